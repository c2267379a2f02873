"""Every command's JSON keeps its keys and its computed values across the library's redesign.

``tests/data/cli_json/expected_*.json`` holds each command's ``--format json`` output on the
small graphs of that folder as an earlier release printed it. Today's output must have exactly
the same keys, at every level, and the same values, except timings (which change from run to
run). A deliberate change of a key or a value regenerates the file and goes into the changelog.

Tolerances: the graphs have 16 and 27 poses with well-conditioned Laplacians and FIMs (condition
numbers below 1e4), so log-dets, traces and bounds agree to about 1e-12 relative whatever the
order of the floating-point operations. Quantities downstream of the iterative solver move with
its stopping point; the certified estimate is unique and the Riemannian gradient at it is below
1e-9 relative, so they agree to well within 1e-7 relative. Certificate values that are zero in
exact arithmetic (``lambda_min``, ``duality_gap``) are compared absolutely, against the
eigensolver's tolerance (1e-6 of the certificate's scale, here below 1).
"""
from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import pytest

from posecrb.cli import main

DATA = Path(__file__).resolve().parent.parent / "data" / "cli_json"
EXPECTED = json.loads(next(DATA.glob("expected_*.json")).read_text())
CASES = EXPECTED["cases"]

TIMING_KEYS = {"times", "runs", "created", "elapsed_seconds", "build_ratio"}   # build_ratio: of two times
# Keys added since the stored outputs, as "parent.key" (list positions left out), each listed in
# CHANGELOG.md: the output may have them after the stored keys of that object; nothing else may
# be added, renamed or dropped.
#   logdet_accuracy.tier, .condition_kind: which tier of posecrb.linalg.accuracy bounded the
#   log-det's rounding error, and whether its condition number is exact or an upper bound.
ADDED_KEYS = frozenset({"logdet_accuracy.tier", "logdet_accuracy.condition_kind"})
_LIST_POSITION = re.compile(r"\[\d+\]")
NEAR_ZERO_KEYS = {"lambda_min", "duality_gap"}
RTOL, ATOL, ATOL_NEAR_ZERO = 1e-7, 1e-9, 1e-6
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def _is_timing(key: str) -> bool:
    return key in TIMING_KEYS or key.endswith(("_time", "_seconds")) or key.startswith("time_")


def _close(a: float, b: float, key: str) -> bool:
    atol = ATOL_NEAR_ZERO if key in NEAR_ZERO_KEYS else ATOL
    return math.isclose(a, b, rel_tol=RTOL, abs_tol=atol)


def differences(expected, actual, where: str = "", key: str = "") -> list[str]:
    """Where ``actual`` differs from ``expected``: keys at every level, values beyond the tolerances."""
    if isinstance(expected, dict):
        if not isinstance(actual, dict):
            return [f"{where}: a {type(actual).__name__}, expected an object"]
        out = []
        parent = _LIST_POSITION.sub("", where).rsplit(".", 1)[-1]
        keys = list(actual)
        while keys and keys[-1] not in expected and f"{parent}.{keys[-1]}" in ADDED_KEYS:
            keys.pop()
        if list(expected) != keys:
            out.append(f"{where}: keys {list(actual)} != expected {list(expected)}")
        for k in expected:
            if k in actual and not _is_timing(k):
                out += differences(expected[k], actual[k], f"{where}.{k}", k)
        return out
    if isinstance(expected, list):
        if not isinstance(actual, list) or len(actual) != len(expected):
            return [f"{where}: {actual!r:.200} != expected {expected!r:.200}"]
        return [d for i, (e, a) in enumerate(zip(expected, actual)) for d in differences(e, a, f"{where}[{i}]", key)]
    if isinstance(expected, bool) or expected is None or isinstance(expected, int) and not isinstance(actual, float):
        return [] if expected == actual and type(expected) is type(actual) else [f"{where}: {actual!r} != {expected!r}"]
    if isinstance(expected, (int, float)):
        ok = isinstance(actual, (int, float)) and not isinstance(actual, bool) and _close(expected, actual, key)
        return [] if ok else [f"{where}: {actual!r} != {expected!r}"]
    if isinstance(expected, str) and isinstance(actual, str):
        # text with numbers in it (a solver's reason): the words exactly, the printed numbers to their digits
        if NUMBER.sub("#", expected) != NUMBER.sub("#", actual):
            return [f"{where}: {actual!r} != {expected!r}"]
        for e, a in zip(NUMBER.findall(expected), NUMBER.findall(actual)):
            if not math.isclose(float(e), float(a), rel_tol=1e-3, abs_tol=ATOL_NEAR_ZERO):
                return [f"{where}: {actual!r} != {expected!r}"]
        return []
    return [] if expected == actual else [f"{where}: {actual!r} != {expected!r}"]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A copy of the graphs (the JSON shows paths relative to the working directory)."""
    d = tmp_path_factory.mktemp("cli_json")
    for f in DATA.glob("*.g2o"):
        shutil.copy(f, d)
    return d


@pytest.mark.parametrize("name", sorted(CASES))
def test_command_json_is_unchanged(name, workdir, monkeypatch, capsys):
    case = CASES[name]
    monkeypatch.chdir(workdir)
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    code = main(["-q", *case["argv"], "--format", "json"])
    out = capsys.readouterr().out
    assert code == case["exit"]
    assert differences(case["json"], json.loads(out), name) == []


def test_the_comparison_sees_a_changed_key_and_a_changed_value():
    """The comparison is not vacuous: a renamed key, a value off by 1e-6 relative and a changed word fail."""
    expected = {"lb": 300.0, "times": {"a": 1.0}, "reason": "lambda_min = -2.0e-13 at rank 3"}
    assert differences(expected, {**expected, "times": {"a": 5.0}}) == []
    assert differences(expected, {"lb": 300.0, "times": {}, "why": "x"})
    assert differences(expected, {**expected, "lb": 300.0003})
    assert differences(expected, {**expected, "reason": "lambda_min = -2.0e-13 at rank 4"})
    assert differences(expected, {**expected, "reason": "lambda_min = -2.0e-13 on rank 3"})


def test_only_the_listed_keys_may_be_added_and_only_last():
    """``ADDED_KEYS`` admits exactly its keys, under their parent, after the stored ones; any other
    added key, a listed key under another parent, a listed key in place of a stored one, or a
    listed key before a stored one still fails."""
    stored = {"logdet": 1.0, "logdet_accuracy": {"condition": 2.0, "error_bound": 3e-12}}
    now = {**stored, "logdet_accuracy": {**stored["logdet_accuracy"], "tier": "lambda_min",
                                         "condition_kind": "upper bound"}}
    assert differences(stored, now, "fim") == []
    assert differences({"rows": [stored]}, {"rows": [now]}, "tables") == []
    assert differences(stored, {**now, "tier": "lambda_min"}, "fim")
    assert differences({"accuracy": {"condition": 2.0}}, {"accuracy": {"condition": 2.0, "tier": "x"}}, "crlb")
    assert differences(stored, {**stored, "logdet_accuracy": {"condition": 2.0, "tier": "x"}}, "fim")
    assert differences(stored, {**stored, "logdet_accuracy": {"tier": "x", **stored["logdet_accuracy"]}}, "fim")
