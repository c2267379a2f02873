"""The public API: every command's JSON is the library result's ``to_dict()``, the result protocol
(round trips through dicts and files, frames, statuses), anchors as pose ids, and misuse raising
``PosecrbError`` subclasses that name the argument."""
from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

import posecrb
from posecrb.core.status import Status
from posecrb.io import write_g2o

from ..helpers import make_random_graph, run_cli

VOLATILE = ("times", "runs", "path", "saved")   # timings (and their run counts), absolute paths differ


def _stable(d):
    """``d`` without the keys that differ between two runs of the same call."""
    if isinstance(d, dict):
        return {k: _stable(v) for k, v in d.items() if k not in VOLATILE}
    if isinstance(d, list):
        return [_stable(v) for v in d]
    return d


def _shifted(graph, offset):
    """The same graph with every pose id increased by ``offset``."""
    return dataclasses.replace(graph, ids=graph.ids + offset)


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def shifted_file(request, tmp_path_factory):
    """A connected random graph whose ids start at 100 (with gaps), written through the writer."""
    g = _shifted(make_random_graph(np.random.default_rng(5 + request.param), n=14, extra=10, dim=request.param), 100)
    path = tmp_path_factory.mktemp("api") / f"shifted{request.param}d.g2o"
    write_g2o(g, path)
    return path


def _cli_json(argv, capsys):
    code, out, err = run_cli([*argv, "--format", "json"], capsys)
    assert code == 0, err
    return json.loads(out)


# Every command with a library call, with the same arguments on both sides (CLI flags, keywords).
CASES = [
    ("solve", [], {}),
    ("solve", ["--anchor", "{a}", "--rmax", "6"], {"anchor": "{a}", "rmax": 6}),
    ("bounds", ["--repeat", "1"], {}),
    ("bounds", ["--estimate", "none", "--anchor", "{a}", "--repeat", "1"], {"estimate": None, "anchor": "{a}"}),
    ("bounds", ["--estimate", "vertices", "--fim-variant", "eq64", "--repeat", "1"],
     {"estimate": "vertices", "fim_variant": "eq64"}),
    ("fim", [], {}),
    ("fim", ["--anchor", "{a}", "--rotation-weight", "table2"], {"anchor": "{a}", "rotation_weight": "table2"}),
    ("fim", ["--model", "sed", "--frame", "body"], {"model": "sed", "frame": "body"}),
    ("fim", ["--model", "sed", "--anchor", "{a}", "--estimate", "vertices"],
     {"model": "sed", "anchor": "{a}", "estimate": "vertices"}),
    ("crlb", ["--poses", "all"], {"poses": "all"}),
    ("crlb", ["--anchor", "{a}", "--poses", "{a},{b}"], {"anchor": "{a}", "poses": ["{a}", "{b}"]}),
    ("crlb", ["--model", "sed", "--anchor", "{a}", "--anchor", "{b}", "--poses", "{b}"],
     {"model": "sed", "anchor": ["{a}", "{b}"], "poses": ["{b}"]}),
    ("crlb", ["--model", "sed", "--quotient", "--frame", "body"], {"model": "sed", "quotient": True, "frame": "body"}),
    ("select", ["--budget", "3"], {"budget": 3}),
    ("select", ["--budget", "40%", "--method", "relax", "--seed", "3", "--anchor", "{a}"],
     {"budget": 0.4, "method": "relax", "seed": 3, "anchor": "{a}"}),
    ("select", ["--budget", "3", "--gains", "lazy-exact"], {"budget": 3, "gains": "lazy-exact"}),
    ("select", ["--budget", "3", "--gains", "rounds"], {"budget": 3, "gains": "rounds"}),
    ("select", ["--budget", "2", "--objective", "fim", "--certify", "--estimate", "vertices"],
     {"budget": 2, "objective": "fim", "certify": True, "estimate": "vertices"}),
    ("timeline", [], {}),
    ("timeline", ["--estimate", "none", "--every", "3", "--from", "4", "--to", "12"],
     {"estimate": None, "every": 3, "start": 4, "stop": 12}),
    ("timeline", ["--estimate", "vertices", "--fim-variant", "eq64", "--rotation-weight", "table2"],
     {"estimate": "vertices", "fim_variant": "eq64", "rotation_weight": "table2"}),
]


def _fill(value, ids):
    if isinstance(value, str) and value.startswith("{"):
        return int(value.format(a=ids[3], b=ids[7]))
    if isinstance(value, list):
        return [_fill(v, ids) for v in value]
    return value


@pytest.mark.parametrize("command, flags, keywords", CASES, ids=[f"{c[0]}-{k}" for k, c in enumerate(CASES)])
def test_cli_json_is_the_library_results_dict(shifted_file, command, flags, keywords, capsys):
    ids = posecrb.load(shifted_file).ids.tolist()
    argv = [command, str(shifted_file), *(f.format(a=ids[3], b=ids[7]) for f in flags)]
    cli = _cli_json(argv, capsys)
    lib = getattr(posecrb, command)(str(shifted_file), **{k: _fill(v, ids) for k, v in keywords.items()})
    d = lib.to_dict()
    assert json.loads(json.dumps(d, allow_nan=False)) == d          # JSON-serialisable as it is
    assert _stable(d) == _stable(cli)
    assert set(d) == set(cli) and set(d["times"]) == set(cli["times"])
    assert set(d.get("runs", {})) == set(cli.get("runs", {}))
    if "anchor" in keywords:                                         # anchors are pose ids, never indices
        want = _fill(keywords["anchor"], ids)
        assert (d.get("anchors") or [d["anchor"]]) == (want if isinstance(want, list) else [want])


def test_a_graph_object_gives_the_same_result_as_its_file(shifted_file):
    graph = posecrb.load(shifted_file)
    assert _stable(posecrb.fim(graph).to_dict()) == _stable(posecrb.fim(str(shifted_file)).to_dict())
    assert "parse" not in posecrb.fim(graph).times and "parse" in posecrb.fim(shifted_file).times


# ---- the protocol ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def results(shifted_file):
    f = str(shifted_file)
    return {"solve": posecrb.solve(f), "bounds": posecrb.bounds(f), "fim": posecrb.fim(f, model="sed"),
            "crlb": posecrb.crlb(f, poses="all"), "select": posecrb.select(f, budget=2, certify=True)}


# (to_dict, from_dict, save and load of every result type: tests/library/test_protocol.py)


def test_a_saved_fim_is_a_scipy_sparse_file_with_its_index_map(results, tmp_path):
    res = results["fim"]
    path = res.save(tmp_path / "f.npz")
    m = sp.load_npz(path)
    assert m.shape == (res.size, res.size) and (m != res.matrix).nnz == 0
    with np.load(path) as z:
        assert z["row_pose_id"].tolist() == np.asarray(res.row_ids).tolist()
        assert str(z["frame"]) == res.frame and z["anchor_ids"].tolist() == res.anchors


def test_loading_a_file_of_another_result_type_is_a_parse_error(results, tmp_path):
    path = results["bounds"].save(tmp_path / "b")
    with pytest.raises(posecrb.ParseError, match="not a FimResult"):
        posecrb.FimResult.load(path)
    (tmp_path / "junk.npz").write_bytes(b"not a zip file")
    with pytest.raises(posecrb.ParseError):
        posecrb.SolveResult.load(tmp_path / "junk.npz")


def test_frames(results):
    sol = results["solve"]
    frame = sol.to_frame()
    assert frame["id"].tolist() == sol.ids.tolist() and len(frame) == sol.poses
    if sol.dim == 3:       # unit quaternions with qw >= 0
        q = frame[["qx", "qy", "qz", "qw"]].to_numpy()
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-12)
        assert (q[:, 3] >= 0).all()
    else:                  # theta reproduces the rotation
        th = frame["theta"].to_numpy()
        np.testing.assert_allclose(np.stack([np.cos(th), np.sin(th)], 1), sol.rot[:, :, 0], rtol=0, atol=1e-12)
    crlb = results["crlb"]
    pf = crlb.to_frame()
    assert pf["id"].tolist() == sorted(crlb.per_pose) and len(pf) == crlb.poses
    for _, row in pf.iterrows():
        block = crlb.per_pose[int(row["id"])]
        np.testing.assert_array_equal(row[[f"var_{c}" for c in crlb.coordinates]].to_numpy(float), np.diag(block))
    sel = results["select"]
    sf = sel.to_frame()
    assert sf[["id_i", "id_j", "edge"]].to_numpy().tolist() == sel.selected.tolist()
    assert sorted(sf["step"]) == list(range(1, sel.budget + 1))       # greedy: the order of the picks
    one = results["bounds"].to_frame()
    assert len(one) == 1 and one.loc[0, "lb"] == results["bounds"].lb and one.loc[0, "ordering.lb"]


def test_crlb_frame_without_blocks_says_how_to_ask_for_them(shifted_file):
    with pytest.raises(posecrb.UsageError, match="poses='all'"):
        posecrb.crlb(shifted_file).to_frame()


def test_statuses_travel_through_the_dict():
    """A number that is unavailable is None with its ``<key>_status`` (as ``posecrb.core.status.put``);
    the status comes back from the dict and decides ``status``."""
    d = {"dataset": "g", "path": None, "sha256": None, "dim": 3, "poses": 4, "edges": 5, "components": 1,
         "anchor": 7, "rotation_weight": "eq59", "lb": 1.0, "ub": None,
         "ub_status": {"status": "unavailable", "reason": "breaks down", "hint": "use ub_lambda"},
         "ub_lambda": 2.0, "lambda_inf": 3.0, "lambda_min_rot": 0.5,
         "lambda_min_rot_status": {"status": "warning", "reason": "wide interval"},
         "lambda_min_rot_lower": 0.4, "gap_bound": 9.0, "t_opt_graph": 1.0, "t_opt_approx": 2.0, "total_degree": 8,
         "times": {"lb": 0.1}, "runs": {"lb": 1}, "ordering": {"requested": "auto", "lb": "amd"}}
    res = posecrb.BoundsResult.from_dict(d)
    assert res.ub is None and res.bounds.ub_status == Status.unavailable("breaks down", "use ub_lambda")
    assert res.to_dict() == d and res.fim is None
    assert res.status.state == "unavailable" and set(res.statuses()) == {"ub", "lambda_min(L_w)", "Lemma 4 gap bound"}
    assert "status" not in res.to_dict()                             # no estimate: nothing uncertified
    unc = dict(d, fim_logdet=5.0, trace_fim=6.0, fim_variant="consistent",
               estimate={"source": "solve", "certified": False, "objective": 1.0}, status="uncertified")
    out = posecrb.BoundsResult.from_dict(unc).to_dict()
    assert out == unc and list(out)[-2:] == ["status", "ordering"]
    # the derived key must agree with what it is derived from
    with pytest.raises(posecrb.ArgumentError, match="key 'status' of a BoundsResult is None, which contradicts"):
        posecrb.BoundsResult.from_dict({k: v for k, v in unc.items() if k != "status"})


def test_from_dict_names_a_missing_key():
    with pytest.raises(posecrb.ArgumentError, match="lacks the key 'objective'"):
        posecrb.SolveResult.from_dict({"dataset": "x", "dim": 2, "poses": 3, "edges": 3, "anchor": 0})
    with pytest.raises(posecrb.ArgumentError, match="not a mapping"):
        posecrb.SolveResult.from_dict([1, 2])


def test_an_uncertified_solve_is_a_warning_status(results):
    d = dict(results["solve"].to_dict(), certified=False, reason="not certified: lambda_min = -1 at rmax")
    res = posecrb.SolveResult.from_dict(d)
    assert res.status.state == "warning" and "NOT certified" in res.status.reason and res.to_dict() == d
    assert results["solve"].status.ok


# ---- estimates -----------------------------------------------------------------------------
def test_a_solve_result_or_an_estimate_is_an_estimate(shifted_file):
    sol = posecrb.solve(shifted_file)
    by_name = posecrb.fim(shifted_file)
    by_result = posecrb.fim(shifted_file, estimate=sol)
    assert by_result.logdet == by_name.logdet and by_result.estimate.to_dict() == by_name.estimate.to_dict()
    assert "solve" not in by_result.times               # this call did not run the solver
    given = posecrb.Estimate(sol.rot, sol.trans)
    assert posecrb.crlb(shifted_file, estimate=given).trace_crlb == posecrb.crlb(shifted_file).trace_crlb
    assert posecrb.crlb(shifted_file, estimate=given).estimate.to_dict() == {"source": "given", "certified": None,
                                                                              "objective": None}
    b = posecrb.bounds(shifted_file, estimate=sol)
    assert b.fim_logdet == by_name.logdet


def test_an_estimate_of_another_graph_or_without_poses_is_refused(shifted_file, tmp_path):
    other = make_random_graph(np.random.default_rng(99), n=6, extra=2, dim=posecrb.load(shifted_file).dim)
    path = tmp_path / "other.g2o"
    write_g2o(other, path)
    sol = posecrb.solve(path)
    with pytest.raises(posecrb.ArgumentError, match="another graph"):
        posecrb.fim(shifted_file, estimate=sol)
    with pytest.raises(posecrb.ArgumentError, match="carries no poses"):
        posecrb.fim(path, estimate=posecrb.SolveResult.from_dict(sol.to_dict()))
    with pytest.raises(posecrb.ArgumentError, match="do not match the graph"):
        posecrb.fim(shifted_file, estimate=posecrb.Estimate(sol.rot, sol.trans))
    with pytest.raises(posecrb.ArgumentError, match="estimate=42 is not 'solve'"):
        posecrb.crlb(shifted_file, estimate=42)


# ---- misuse ----------------------------------------------------------------------------------
@pytest.mark.parametrize("call, kwargs, message", [
    ("crlb", {"anchor": 5}, "anchor=5 is not a pose id of {name} (ids 1"),
    ("crlb", {"anchor": -1}, "anchor=-1 is not a pose id of {name}"),
    ("fim", {"anchor": 100.5}, "anchor=100.5 is not a pose id or a sequence of pose ids"),
    ("bounds", {"anchor": 1.0}, "anchor=1.0 is not a pose id"),
    ("solve", {"anchor": True}, "anchor=True is not a pose id"),
    ("crlb", {"anchor": ["{a}", "{b}"]}, "anchor=[{a}, {b}] is several anchors; the paper model takes one"),
    ("crlb", {"poses": ["{a}", 5]}, "poses=5 is not a pose id of {name}"),
    ("crlb", {"poses": "1-x"}, "poses='1-x' is text: pass True (or 'all') or a sequence of pose ids"),
    ("crlb", {"quotient": True}, "quotient=True applies to the sed model"),
    ("fim", {"model": "sed", "fim_variant": "eq64"}, "fim_variant='eq64' applies to the paper model"),
    ("fim", {"frame": "body"}, "frame='body' applies to the sed model"),
    ("fim", {"model": "thesis"}, "model='thesis' is not one of 'paper', 'sed'"),
    ("bounds", {"repeat": 0}, "repeat=0 is not in 1..1000"),
    ("bounds", {"ordering": "best"}, "ordering='best' is not one of"),
    ("select", {"budget": 2, "tol": math.nan}, "tol=nan is not a finite number"),
    ("select", {"budget": 2, "tol": 2.0}, "tol=2.0 is not in (0, 1]"),
    ("select", {"budget": 2, "max_iter": 0}, "max_iter=0 is not in 1..100000"),
    ("select", {"budget": 2, "seed": -1}, "seed=-1 is not in 0.."),
    ("select", {"budget": 2.5}, "budget=2.5 is not a fraction of the candidates in (0, 1]"),
    ("select", {"budget": "20%"}, "budget='20%' is text: pass a number of edges K (an int) or a fraction"),
    ("select", {"budget": 0}, "budget=0 is not a number of edges >= 1"),
    ("select", {"budget": 2, "gains": "fast"},
     "gains='fast' is not one of 'auto', 'exact', 'rounds', 'lazy', 'lazy-exact', 'jl'"),
    ("select", {"budget": 2, "exact": True}, "exact=True: is no longer a keyword of select(): use gains="),
    ("solve", {"certificate_tol": math.inf}, "certificate_tol=inf is not a finite number"),
    ("solve", {"rmax": 1}, "rmax=1 is not in 2..100"),
    ("solve", {"init": "random"}, "init='random' is not one of"),
])
def test_misuse_raises_an_argument_error_in_python_terms(shifted_file, call, kwargs, message):
    ids = posecrb.load(shifted_file).ids.tolist()
    fill = {"a": ids[0], "b": ids[1]}
    kwargs = {k: [x.format(**fill) if isinstance(x, str) else x for x in v] if isinstance(v, list) else v
              for k, v in kwargs.items()}
    kwargs = {k: [int(x) for x in v] if k in ("anchor", "poses") and isinstance(v, list) else v
              for k, v in kwargs.items()}
    with pytest.raises(posecrb.ArgumentError) as info:
        getattr(posecrb, call)(str(shifted_file), **kwargs)
    assert message.format(name=shifted_file.name, **fill) in str(info.value)
    assert isinstance(info.value, posecrb.UsageError) and isinstance(info.value, ValueError)
    assert "--" not in str(info.value)                 # no command-line flag quoted to a Python caller


def test_sources_that_are_not_paths_or_names(tmp_path):
    data = b"EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000\n"
    with pytest.raises(posecrb.ArgumentError, match=r"source=b'EDGE_SE2 0 1 1 0 0 100 0\.\.\.' is bytes"):
        posecrb.load(data)
    with pytest.raises(posecrb.ArgumentError, match="source=3 is not a pose graph"):
        posecrb.bounds(3)
    with pytest.raises(posecrb.ArgumentError, match="text=3 is not a file's content"):
        posecrb.parse(3)
    with pytest.raises(posecrb.DatasetNotFound):
        posecrb.load("no-such-dataset-anywhere", data_dir=tmp_path)
    g = posecrb.parse(data + b"EDGE_SE2 1 2 1 0 0 100 0 0 100 0 1000\n")
    assert g.ids.tolist() == [0, 1, 2] and posecrb.parse(data.decode()).m == 1
    from posecrb.io import parse_text

    with pytest.raises(posecrb.UsageError, match="parse_bytes"):
        parse_text(data)


def test_a_name_resolves_as_on_the_command_line(shifted_file):
    g = posecrb.load(shifted_file.stem, data_dir=shifted_file.parent)
    assert g.path == str(shifted_file) and g.ids[0] > 100


def test_the_command_line_names_its_flags(shifted_file, capsys):
    code, _, err = run_cli(["crlb", str(shifted_file), "--anchor", "5"], capsys)
    assert code == 2 and f"usage error: --anchor 5 is not a pose id of {shifted_file.name}" in err
    code, _, err = run_cli(["crlb", str(shifted_file), "--quotient"], capsys)
    assert code == 2 and "usage error: --quotient applies to the sed model" in err
    code, _, err = run_cli(["solve", str(shifted_file), "--out", str(shifted_file)], capsys)
    assert code == 2 and f"--out {shifted_file} is the input file" in err


def test_argument_error_messages():
    e = posecrb.ArgumentError("max_iter", 0, "is not in 1..100000")
    assert str(e) == "max_iter=0 is not in 1..100000" and e.cli_message() == "--max-iter 0 is not in 1..100000"
    e = posecrb.ArgumentError("save", "x.npz", "directory d does not exist", sep=": ")
    assert str(e) == "save='x.npz': directory d does not exist"
    assert e.cli_message() == "--save x.npz: directory d does not exist"
    assert posecrb.ArgumentError("source", b"ab", "is bytes").cli_message() == "FILE b'ab' is bytes"


# ---- the package's namespace ------------------------------------------------------------------
def test_every_public_name_resolves_and_is_documented():
    for name in posecrb.__all__:
        obj = getattr(posecrb, name)
        if name != "__version__":
            doc = obj.__doc__ or ""
            assert "Examples" in doc and ">>>" in doc, name
    assert set(posecrb.__all__) <= set(dir(posecrb))
    with pytest.raises(AttributeError):
        posecrb.not_a_name  # noqa: B018


def test_importing_posecrb_loads_no_numerics():
    code = ("import sys, posecrb; posecrb.ArgumentError; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'scipy', 'pandas', 'numba')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
