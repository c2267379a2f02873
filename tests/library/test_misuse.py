"""The library's misuse suite: every public function with hostile arguments (wrong types, huge
integers, NUL bytes, numpy scalars and arrays, values out of range) and every public result type with
hostile ``from_dict`` and ``load`` payloads. Every failure is a ``PosecrbError`` subclass, never a raw
Python error, and what the command line refuses the library refuses too."""
from __future__ import annotations

import io
import json
import math
import shutil
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import posecrb
from posecrb.core.errors import UsageError
from posecrb.core.result import Result
from posecrb.io import write_g2o

from ..helpers import PUBLIC_RESULT_TYPES as RESULT_TYPES
from ..helpers import random_pose_graph

DATA = Path(__file__).resolve().parents[1] / "data" / "cli_json"
HUGE = 10 ** 5000          # Python refuses to print it: 'Exceeds the limit (4300 digits)'


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    d = tmp_path_factory.mktemp("misuse")
    shutil.copy(DATA / "g2d.g2o", d)
    return posecrb.load(d / "g2d.g2o")


# Values every parameter meets: of another type, out of any range, or hostile to the machinery.
HOSTILE = [object(), b"bytes", bytearray(b"x"), [], {}, (1, 2), {1}, 1.5, True, np.True_, -1, HUGE, -HUGE,
           math.nan, math.inf, "", "x\0y", "no such thing", np.array(1), np.array([1.0, 2.0]), np.float64(1.5),
           np.int64(-3), 1j, range(3)]

# Per public function: keywords that work, and the parameters to try.
BASE = {
    "load": ({}, ["source", "data_dir", "quaternions"]),
    "parse": ({}, ["text"]),
    "solve": ({}, ["source", "r0", "rmax", "init", "anchor", "certificate_tol", "sesync_compat", "data_dir",
                   "max_iterations", "seed", "verbose"]),
    "bounds": ({"estimate": "vertices"}, ["source", "anchor", "repeat", "rotation_weight", "estimate", "fim_variant",
                                          "ordering", "data_dir"]),
    "fim": ({"estimate": "vertices"}, ["source", "model", "estimate", "anchor", "rotation_weight", "fim_variant",
                                       "frame", "ordering", "data_dir"]),
    "crlb": ({"estimate": "vertices"}, ["source", "model", "quotient", "anchor", "poses", "estimate",
                                        "rotation_weight", "fim_variant", "frame", "ordering", "data_dir"]),
    "select": ({"budget": 2}, ["source", "budget", "objective", "method", "fixed", "certify", "max_iter", "tol",
                               "gains", "estimate", "seed", "anchor", "data_dir"]),
    "timeline": ({"estimate": "vertices"}, ["source", "estimate", "every", "start", "stop", "rotation_weight",
                                            "fim_variant", "data_dir"]),
    "verify": ({"estimate": str(DATA / "g2d.g2o"), "solve": False},
               ["source", "estimate", "estimate_format", "tum_ids", "truth", "solve", "certificate_tol", "anchor",
                "data_dir"]),
}
# What the command line refuses must be refused here too: per parameter kind, values never accepted.
REFUSED = {
    "int": [True, np.True_, 1.5, math.nan, math.inf, "3", b"3", np.array([1.0, 2.0]), 1j, HUGE, -HUGE, object()],
    "float": [True, math.nan, math.inf, -math.inf, "0.1", b"1", object(), 1j],
    "path": [b"bytes", "", "x\0y", object(), 3],
    "choice": [object(), 3, "", "x\0y", b"auto", True],
    "flag": [1, 0, "yes", None, object(), math.nan],
    "poses": [1.5, math.nan, "0,5", "0-3", b"1", object(), [1.5], [True], [HUGE], [-1]],
}
KIND = {"r0": "int", "rmax": "int", "anchor": "int", "repeat": "int", "max_iterations": "int", "seed": "int",
        "max_iter": "int", "every": "int", "start": "int", "stop": "int", "budget": "int", "poses": "poses",
        "certificate_tol": "float", "tol": "float", "source": "path", "data_dir": "path", "text": "path",
        "fixed": "path", "estimate": "path", "quaternions": "choice", "init": "choice", "rotation_weight": "choice",
        "fim_variant": "choice", "ordering": "choice", "model": "choice", "frame": "choice", "objective": "choice",
        "method": "choice", "gains": "choice", "sesync_compat": "flag", "quotient": "flag", "certify": "flag",
        "verbose": "flag", "estimate_format": "choice", "tum_ids": "choice", "truth": "path", "solve": "flag"}


def _call(name, graph, parameter, value):
    keywords, _ = BASE[name]
    keywords = dict(keywords)
    first = {"load": "source", "parse": "text"}.get(name)
    source = {"load": graph.path, "parse": Path(graph.path).read_text()}.get(name, graph)
    if parameter in ("source", "text"):
        source = value
    else:
        keywords[parameter] = value
    if name in ("load", "parse"):
        return getattr(posecrb, name)(**{first: source}, **keywords)
    return getattr(posecrb, name)(source, **keywords)


CASES = [(name, p) for name, (_, params) in BASE.items() for p in params]


@pytest.mark.parametrize("name, parameter", CASES, ids=[f"{n}-{p}" for n, p in CASES])
def test_hostile_arguments_give_posecrb_errors_and_the_command_lines_refusals(name, parameter, graph, tmp_path,
                                                                              monkeypatch):
    monkeypatch.chdir(tmp_path)                   # a relative name resolves nowhere
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    refused = REFUSED[KIND[parameter]]
    for value in HOSTILE + refused:
        try:
            _call(name, graph, parameter, value)
        except posecrb.PosecrbError as exc:
            str(exc)                                        # its message can be shown
            if isinstance(exc, posecrb.ArgumentError):
                exc.cli_message()
            continue
        except Exception as exc:
            pytest.fail(f"{name}({parameter}={value!r:.60}) raised {type(exc).__name__}: {exc}")
        assert not any(value is r for r in refused), f"{name}({parameter}={value!r:.60}) was accepted"


@pytest.mark.parametrize("name", RESULT_TYPES)
def test_hostile_from_dict_payloads_are_argument_errors(results, name):
    """Each key dropped, each value replaced by one of another type, statuses tampered with, keys
    added: an ArgumentError, or (a value the type admits) a result that gives the dict back."""
    cls = type(results[name])
    d = results[name].to_dict()
    payloads = [{k: v for k, v in d.items() if k != key} for key in d]
    payloads += [{**d, key: bad} for key in d for bad in ("zzz", [], {}, None, 1.5, True, -1, {"status": "bogus"})]
    payloads += [{**d, "extra": 1}, [], "x", None, 3]
    for key in d:
        if key.endswith("_status") or key == "gain_status":
            payloads += [{**d, key: {"status": "warning"}}, {**d, key: {"status": "ok", "reason": "x"}},
                         {**d, key: "warning"}, {**d, key: {"status": "warning", "reason": "x", "extra": 1}}]
    accepted = 0
    for payload in payloads:
        try:
            back = cls.from_dict(payload)
        except posecrb.ArgumentError:
            continue
        except Exception as exc:
            pytest.fail(f"{name}.from_dict raised {type(exc).__name__}: {exc} on {payload!r:.200}")
        assert back.to_dict() == payload, f"{name}.from_dict accepted {payload!r:.200} silently"
        accepted += 1
    assert accepted < len(payloads) / 2


def test_wrongly_typed_values_are_not_accepted_silently(results):
    """`lb="zzz"` was accepted by BoundsResult.from_dict, a tampered status raised InternalError."""
    d = results["BoundsResult"].to_dict()
    for bad in ({**d, "lb": "zzz"}, {**d, "poses": 3.5}, {**d, "ordering": "amd"}, {**d, "times": {"lb": "x"}},
                {**d, "ub_status": {"status": "sure", "reason": "x"}}, {**d, "estimate": {"source": 3}}):
        with pytest.raises(posecrb.ArgumentError, match="of a (BoundsResult|GraphBounds|Estimate)"):
            posecrb.BoundsResult.from_dict(bad)
    with pytest.raises(posecrb.ArgumentError, match="lacks the key 'lb'"):
        posecrb.BoundsResult.from_dict({k: v for k, v in d.items() if k != "lb"})


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


@pytest.mark.parametrize("name", RESULT_TYPES)
def test_hostile_load_payloads_are_parse_errors(results, name, tmp_path):
    cls = type(results[name])
    good = Path(results[name].save(tmp_path / "good"))
    d = results[name].to_dict()
    files = {
        "empty.npz": b"", "text.npz": b"EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n", "truncated.npz": good.read_bytes()[:100],
        "array.npy": b"", "other.npz": _npz(result=np.array("{}"), result_type=np.array("Nothing")),
        "garbage.npz": _npz(result=np.array("{not json"), result_type=np.array(name)),
        "tampered.npz": _npz(result=np.array(json.dumps({**d, "zz": 1})), result_type=np.array(name)),
        "list.npz": _npz(result=np.array("[1, 2]"), result_type=np.array(name)),
        "pickle.npz": _npz(result=np.array([object()], dtype=object), result_type=np.array(name)),
    }
    buf = io.BytesIO()
    np.save(buf, np.arange(3))
    files["array.npy"] = buf.getvalue()
    with zipfile.ZipFile(tmp_path / "zip.npz", "w") as z:
        z.writestr("result.npy", b"not an array")
    for file_name, content in files.items():
        (tmp_path / file_name).write_bytes(content)
    for path in [*(tmp_path / f for f in files), tmp_path / "zip.npz", tmp_path / "missing.npz", tmp_path]:
        with pytest.raises(posecrb.ParseError):
            cls.load(path)
    for bad in ("", "x\0y.npz", None, 3, b"good.npz"):
        with pytest.raises(posecrb.ArgumentError):
            cls.load(bad)
    for bad in ("", "x\0y", None, 3, tmp_path / "no-such-dir" / "r"):
        with pytest.raises(posecrb.ArgumentError):
            results[name].save(bad)
    assert cls.load(good).to_dict() == d
    assert issubclass(cls, Result)


def test_numpy_anchor_negative_seed_and_nan_iterations(graph):
    """`anchor=np.array(1)`, `solve(seed=-1)` and `max_iterations=nan` raised raw errors."""
    assert posecrb.fim(graph, anchor=np.array(1), estimate="vertices").anchors == [1]
    assert posecrb.crlb(graph, anchor=np.array([1]), estimate="vertices").anchors == [1]
    for keywords, says in (({"seed": -1}, "seed=-1 is not in 0.."), ({"max_iterations": math.nan}, "is not an integer"),
                           ({"max_iterations": 0}, "max_iterations=0 is not in 1.."),
                           ({"precond_max_cond": math.inf}, "is not a finite number"),
                           ({"seed": np.int64(-3)}, "seed=np.int64(-3) is not in 0..")):
        with pytest.raises(posecrb.ArgumentError) as info:
            posecrb.solve(graph, **keywords)
        assert says in str(info.value)


def test_library_select_errors_name_the_keyword_and_take_numpy_numbers(graph):
    """Library `select` errors said `--budget`, and `select` rejected `np.int64` budgets."""
    assert posecrb.select(graph, budget=np.int64(2)).budget == 2
    half = posecrb.select(graph, budget=np.float64(0.5))
    assert half.budget == half.candidates // 2 and half.budget_spec == "50%"
    for budget, says in ((10 ** 6, "budget=1000000 exceeds the"), (0.001, "budget=0.001 of"),
                         (2.0, "budget=2.0 is not"), (-1, "budget=-1 is not a number of edges >= 1")):
        with pytest.raises(posecrb.ArgumentError) as info:
            posecrb.select(graph, budget=budget)
        assert says in str(info.value) and "--" not in str(info.value)


def test_write_g2o_rotations_without_translations_is_a_usage_error(tmp_path):
    """Found by static type checking: it once crashed with a raw TypeError."""
    graph, rot, _ = random_pose_graph(5, 2, np.random.default_rng(0))
    bare = replace(graph, vertex_rot=None, vertex_trans=None)
    with pytest.raises(UsageError, match="together"):
        write_g2o(bare, tmp_path / "out.g2o", rot=rot)
    assert not (tmp_path / "out.g2o").exists()
    # both given, or neither: written (the latter without vertices)
    write_g2o(bare, tmp_path / "both.g2o", rot=rot, trans=np.zeros((5, 2)))
    assert (tmp_path / "both.g2o").read_text().count("VERTEX_SE2") == 5
    write_g2o(bare, tmp_path / "none.g2o")
    assert "VERTEX_SE2" not in (tmp_path / "none.g2o").read_text()
