"""``posecrb verify`` from the command line: every estimate format gives the same verdict and values,
bad estimate files are clear errors naming the file (and line), the JSON is the result's to_dict."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import posecrb
from posecrb.cli import main
from posecrb.io import write_g2o
from posecrb.verification.result import VerifyResult

from ..helpers import ring, run_cli


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A 3D ring with chords, its file, and solve's optimum."""
    d = tmp_path_factory.mktemp("verify")
    g = ring(20, 3, closures=4)
    path = d / "ring.g2o"
    write_g2o(g, str(path))
    graph = posecrb.load(path)
    return d, graph, posecrb.solve(graph)


def _write(path, rows):
    path.write_text("\n".join(rows) + "\n")
    return str(path)


def _formats(d, graph, sol) -> dict[str, str]:
    """solve's optimum in each estimate format, 17 significant digits (written here, independently of
    posecrb's writers but g2o's)."""
    f = "{:.17g}".format
    q = Rotation.from_matrix(sol.rot).as_quat()
    g2o = d / "opt.g2o"
    write_g2o(graph, str(g2o), sol.rot, sol.trans)
    ceres = [f"{i} " + " ".join(map(f, [*t, *qq])) for i, t, qq in zip(graph.ids, sol.trans, q)]
    tum = [" ".join(map(f, [1000.0 + 0.5 * k, *t, *qq])) for k, (t, qq) in enumerate(zip(sol.trans, q))]
    kitti = [" ".join(map(f, np.hstack([r, t[:, None]]).ravel())) for r, t in zip(sol.rot, sol.trans)]
    return {"g2o": str(g2o), "ceres": _write(d / "opt.ceres", ceres), "tum": _write(d / "opt.tum", ["# t x y z"] + tum),
            "kitti": _write(d / "opt.kitti", kitti)}


def test_every_format_gives_the_same_verdict_and_values(case, capsys):
    d, graph, sol = case
    got = {}
    for fmt, path in _formats(d, graph, sol).items():
        code, out, _ = run_cli(["verify", graph.path, "--estimate", path, "--format", "json"], capsys)
        assert code == 0
        got[fmt] = json.loads(out)
        assert got[fmt]["estimate"]["format"] == fmt and got[fmt]["verdict"] == "certified-optimal"
    ref = got["g2o"]
    for r in got.values():
        # 17 digits identify the doubles; the quaternion and matrix conversions move the poses by a few ulps
        assert r["objective"] == pytest.approx(ref["objective"], rel=1e-9)
        assert r["suboptimality"] == pytest.approx(ref["suboptimality"], abs=1e-9 * ref["objective"])
        assert r["ate_trans"] == pytest.approx(ref["ate_trans"], abs=1e-9)


def test_the_json_is_the_result(case, capsys, tmp_path):
    d, graph, sol = case
    path = _formats(d, graph, sol)["tum"]
    code, out, _ = run_cli(["verify", graph.path, "--estimate", path, "--format", "json"], capsys)
    assert code == 0
    shown = json.loads(out)
    res = posecrb.verify(graph.path, path)
    mine = res.to_dict()
    assert shown.keys() == mine.keys()
    assert {k: v for k, v in shown.items() if k != "times"} == {k: v for k, v in mine.items() if k != "times"}
    assert VerifyResult.from_dict(shown).to_dict() == shown
    for fmt in ("table", "csv", "markdown"):
        code, out, _ = run_cli(["verify", graph.path, "--estimate", path, "--format", fmt], capsys)
        assert code == 0 and "certified-optimal" in out
    assert run_cli(["verify", graph.path, "--estimate", path, "--format", "table"], capsys)[1].index("verdict") < \
        run_cli(["verify", graph.path, "--estimate", path, "--format", "table"], capsys)[1].index("F at the estimate")


def test_the_graph_file_is_its_own_estimate(case, capsys):
    _, graph, _ = case
    code, out, _ = run_cli(["verify", graph.path, "--estimate", graph.path, "--format", "json"], capsys)
    r = json.loads(out)
    assert code == 0 and r["estimate"]["format"] == "g2o" and r["verdict"] in ("global-basin", "certified-optimal")


def test_no_solve_leaves_the_optimums_keys_null_with_a_status(case, capsys):
    d, graph, sol = case
    path = _formats(d, graph, sol)["kitti"]
    code, out, err = run_cli(["verify", graph.path, "--estimate", path, "--no-solve", "--format", "json"], capsys)
    r = json.loads(out)
    assert code == 0 and r["verdict"] == "certified-optimal"
    for key in ("optimum_objective", "suboptimality", "refined_objective", "ate_trans", "mahalanobis"):
        assert r[key] is None and r[f"{key}_status"]["status"] == "unavailable" and "--no-solve" in \
            r[f"{key}_status"]["reason"]
    assert "warning" not in err


def test_require(case, capsys):
    d, graph, sol = case
    path = _formats(d, graph, sol)["g2o"]
    assert run_cli(["verify", graph.path, "--estimate", path, "--require", "certified-optimal"], capsys)[0] == 0
    moved = sol.trans.copy()
    moved[3] += 0.5
    off = d / "off.g2o"
    write_g2o(graph, str(off), sol.rot, moved)
    code, _, err = run_cli(["verify", graph.path, "--estimate", str(off), "--require", "certified-optimal"], capsys)
    assert code == 1 and "weaker than --require certified-optimal" in err
    assert run_cli(["verify", graph.path, "--estimate", str(off), "--require", "global-basin"], capsys)[0] == 0


def _bad_files(d, graph, sol):
    q = Rotation.from_matrix(sol.rot).as_quat()
    ceres = [f"{i} " + " ".join(f"{x:.17g}" for x in [*t, *qq]) for i, t, qq in zip(graph.ids, sol.trans, q)]
    tum = [" ".join(f"{x:.17g}" for x in [1.5 + k, *t, *qq]) for k, (t, qq) in enumerate(zip(sol.trans, q))]
    nan = list(ceres)
    nan[4] = nan[4].rsplit(" ", 1)[0] + " nan"
    skew = list(ceres)
    skew[2] = " ".join(skew[2].split()[:4] + ["0", "0", "0", "3.5"])
    return {
        "missing id": (ceres[:-1], f"has {len(ceres) - 1} rows for the graph's {len(ceres)} poses: its first column "
                                   f"is not the graph's ids (id {graph.ids[-1]} is missing)"),
        "extra id": (ceres + [f"{graph.ids.max() + 7} 0 0 0 0 0 0 1"], f"(id {graph.ids.max() + 7} is not a pose"),
        "wrong dimension": ([f"{i} 0 0 0" for i in graph.ids], ":1: Ceres 2D rows are 2D poses; the graph is 3D"),
        "nan": (nan, ":5: pose: 'nan' is not a number"),
        "not a rotation": (skew, ":3: quaternion of norm 3.5"),
        "empty": ([""], "is empty"),
        "TUM one short": (tum[:-1], f"has {len(tum) - 1} TUM row(s) for the graph's {len(tum)} poses"),
    }


@pytest.mark.parametrize("name", ["missing id", "extra id", "wrong dimension", "nan", "not a rotation", "empty",
                                  "TUM one short"])
def test_bad_estimates_are_clear_errors(case, capsys, name):
    d, graph, sol = case
    rows, words = _bad_files(d, graph, sol)[name]
    path = _write(d / f"bad {name}.txt", rows)
    code, out, err = run_cli(["verify", graph.path, "--estimate", path], capsys)
    assert code == 1 and out == ""
    assert err.startswith(f"posecrb: error: {path}") and words in err, err
    assert "Traceback" not in err


def test_ceres_ids_missing_or_extra_name_the_id(case, capsys):
    d, graph, sol = case
    rows, _ = _bad_files(d, graph, sol)["missing id"]
    path = _write(d / "short.ceres", rows)
    code, _, err = run_cli(["verify", graph.path, "--estimate", path, "--estimate-format", "ceres"], capsys)
    assert code == 1 and f"{path}: lacks 1 pose(s) of the graph, e.g. id {graph.ids[-1]}" in err
    rows, _ = _bad_files(d, graph, sol)["extra id"]
    path = _write(d / "long.ceres", rows)
    code, _, err = run_cli(["verify", graph.path, "--estimate", path, "--estimate-format", "ceres"], capsys)
    assert code == 1 and f"{path}:{len(rows)}: has 1 pose(s) the graph does not have, e.g. id {graph.ids.max() + 7}" \
        in err


def test_truth_gives_the_errors_against_it_and_the_nees(tmp_path, capsys):
    g = ring(20, 2, closures=4, noise=0.02, seed=4)
    path = tmp_path / "noisy.g2o"
    write_g2o(g, str(path))                      # the vertices are the truth
    sol = posecrb.solve(str(path))
    est = tmp_path / "opt.g2o"
    write_g2o(g, str(est), sol.rot, sol.trans)
    code, out, _ = run_cli(["verify", str(path), "--estimate", str(est), "--truth", str(path), "--format", "json"],
                           capsys)
    t = json.loads(out)["truth"]
    assert code == 0 and t["source"]["path"] == str(path)
    assert t["estimate"]["ate_trans"] == pytest.approx(t["optimum"]["ate_trans"], rel=1e-9)
    assert t["estimate"]["ate_trans"] > 0 and t["nees"] > 0 and t["nees_dof"] == 3 * 19


def test_main_entry_point_maps_a_missing_estimate_to_usage(capsys):
    assert main(["verify", "intel"]) == 2
