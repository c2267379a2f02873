"""The library as a user meets it, on the real intel dataset, with nothing but ``import posecrb``:
load by name, solve, bounds / fim / crlb / select at that estimate, the values the command line
prints, an anchor given as a pose id on a copy whose ids do not start at 0, and misuse raising
``PosecrbError`` subclasses. (The command line runs in a subprocess, as a user runs it.)"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest

import posecrb

OFFSET = 1000    # the shifted copy's ids are intel's plus this
pytestmark = pytest.mark.slow   # seven command-line runs in subprocesses


def _cli(*args: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "posecrb", *args, "--format", "json"], capture_output=True,
                         text=True, check=False, timeout=300, env=os.environ.copy())
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def _stable(d):
    """Without what differs between two runs: timings and absolute paths."""
    if isinstance(d, dict):
        return {k: _stable(v) for k, v in d.items() if k not in ("times", "runs", "path", "saved")}
    if isinstance(d, list):
        return [_stable(v) for v in d]
    return d


@pytest.fixture(scope="module")
def intel(shared_datasets):
    return posecrb.load("intel")   # found through $POSECRB_DATA, as the subprocesses find it


@pytest.fixture(scope="module")
def solution(intel):
    return posecrb.solve(intel)


@pytest.fixture(scope="module")
def shifted(intel, tmp_path_factory):
    """intel with every pose id increased by OFFSET, written as text (VERTEX and EDGE lines)."""
    lines = []
    with open(intel.path) as fh:
        for line in fh:
            tok = line.split()
            if tok and tok[0].startswith("VERTEX"):
                tok[1] = str(int(tok[1]) + OFFSET)
            elif tok and tok[0].startswith("EDGE"):
                tok[1], tok[2] = str(int(tok[1]) + OFFSET), str(int(tok[2]) + OFFSET)
            lines.append(" ".join(tok))
    path = tmp_path_factory.mktemp("acceptance") / "shifted.g2o"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_load_by_name_and_solve(intel, solution):
    assert (intel.dim, intel.n, intel.m) == (2, 1728, 2512)
    assert solution.certified and solution.status.ok and solution.anchor == 0
    assert _stable(solution.to_dict()) == _stable(_cli("solve", "intel"))


@pytest.mark.parametrize("command, flags, keywords", [
    ("bounds", ["--repeat", "1"], {}),
    ("fim", [], {}),
    ("fim", ["--model", "sed"], {"model": "sed"}),
    ("crlb", ["--poses", "1,2,500"], {"poses": [1, 2, 500]}),
    ("crlb", ["--model", "sed"], {"model": "sed"}),
    ("select", ["--budget", "5", "--objective", "fim"], {"budget": 5, "objective": "fim"}),
])
def test_results_at_the_estimate_reproduce_the_command_lines_json(intel, solution, command, flags, keywords):
    res = getattr(posecrb, command)(intel, estimate=solution, **keywords)
    cli = _cli(command, "intel", *flags)
    assert _stable(res.to_dict()) == _stable(cli)
    assert type(res).from_dict(cli).to_dict() == cli


def test_crlb_with_a_pose_id_anchor_on_shifted_ids(intel, solution, shifted):
    g = posecrb.load(shifted)
    assert int(g.ids[0]) == OFFSET and g.n == intel.n
    res = posecrb.crlb(shifted, anchor=OFFSET + 17, poses=[OFFSET + 17, OFFSET + 18])
    assert res.anchors == [OFFSET + 17] and sorted(res.per_pose) == [OFFSET + 17, OFFSET + 18]
    assert _stable(res.to_dict()) == _stable(_cli("crlb", str(shifted), "--anchor", str(OFFSET + 17),
                                                  "--poses", f"{OFFSET + 17},{OFFSET + 18}"))
    # the same pose of intel, anchored by its own id: the bound does not depend on how ids are numbered
    same = posecrb.crlb(intel, anchor=17, estimate=solution)
    assert math.isclose(res.trace_crlb, same.trace_crlb, rel_tol=1e-9)
    assert not (res.per_pose[OFFSET + 17] != 0).any()       # the anchor's block is zero
    frame = res.to_frame()
    assert frame["id"].tolist() == [OFFSET + 17, OFFSET + 18] and frame.loc[0, "trace"] == 0.0


def test_misuse_raises_posecrb_errors(intel, shifted):
    cases = [
        (lambda: posecrb.crlb(shifted, anchor=5), "anchor=5 is not a pose id of shifted.g2o"),
        (lambda: posecrb.crlb(intel, anchor=-1), "anchor=-1 is not a pose id of intel.g2o"),
        (lambda: posecrb.fim(intel, anchor=1.5), "anchor=1.5 is not a pose id"),
        (lambda: posecrb.select(intel, budget=5, tol=float("nan")), "tol=nan is not a finite number"),
        (lambda: posecrb.load(b"VERTEX_SE2 0 0 0 0"), "is bytes"),
    ]
    for call, message in cases:
        with pytest.raises(posecrb.PosecrbError) as info:
            call()
        assert isinstance(info.value, posecrb.ArgumentError) and message in str(info.value)
