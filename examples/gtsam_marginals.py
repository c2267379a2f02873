"""Cross-check posecrb's per-pose Cramér–Rao bounds with GTSAM's marginal covariances.

For each dataset: posecrb computes the certified optimum and writes it as a g2o file; GTSAM reads
that file (``gtsam.readG2o``), holds the first pose fixed with a constrained prior (the same gauge
as posecrb's anchor) and computes ``gtsam.Marginals``; posecrb computes the thesis model's CRB
in GTSAM's body-frame coordinates (``crlb --model sed --frame body``) at the same estimate. The
script prints, per dataset, the largest and the median relative (Frobenius) difference of the
per-pose covariance blocks and both anchored traces.

Needs gtsam (``pip install '.[gtsam]'`` in posecrb's clone): without it the script says so and
exits with status 77 (skipped). Needs the real datasets (``$POSECRB_DATA``). Usage::

    python examples/gtsam_marginals.py [NAME ...]      # default: intel tinyGrid3D
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

SKIPPED = 77   # exit status of an example that cannot run here


def posecrb(*args: str) -> str:
    """Stdout of this interpreter's posecrb command line."""
    return subprocess.run([sys.executable, "-m", "posecrb", *args], check=True, capture_output=True,
                          text=True).stdout


def gtsam_marginals(path: Path, dim: int) -> dict[int, np.ndarray]:
    """GTSAM's marginal covariance of every pose but the first, which a constrained prior fixes."""
    import gtsam  # noqa: PLC0415 -- optional: the script exits 77 without it

    is3d = dim == 3
    graph, initial = gtsam.readG2o(str(path), is3d)
    keys = sorted(initial.keys())
    prior, pose = ((gtsam.PriorFactorPose3, initial.atPose3(keys[0])) if is3d else
                   (gtsam.PriorFactorPose2, initial.atPose2(keys[0])))
    graph.add(prior(keys[0], pose, gtsam.noiseModel.Constrained.All(6 if is3d else 3)))
    marginals = gtsam.Marginals(graph, initial)
    return {int(k): marginals.marginalCovariance(k) for k in keys[1:]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", default=["intel", "tinyGrid3D"])
    args = parser.parse_args()
    if importlib.util.find_spec("gtsam") is None:
        print("gtsam is not installed (pip install '.[gtsam]' in posecrb's clone): nothing to compare", file=sys.stderr)
        return SKIPPED

    print(f"{'dataset':12s} {'poses':>6s} {'max rel diff':>12s} {'median':>9s} {'trace posecrb':>14s} "
          f"{'trace GTSAM':>12s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.names:
            estimate = Path(tmp, f"{name}_opt.g2o")
            posecrb("solve", name, "--out", str(estimate), "--format", "json")
            ours = json.loads(posecrb("crlb", str(estimate), "--model", "sed", "--frame", "body",
                                      "--estimate", "vertices", "--poses", "all", "--format", "json"))
            theirs = gtsam_marginals(estimate, ours["dim"])
            blocks = {int(i): np.asarray(b) for i, b in ours["per_pose"].items()}
            diffs = [np.linalg.norm(blocks[i] - c) / np.linalg.norm(c) for i, c in theirs.items()]
            trace_gtsam = sum(np.trace(c) for c in theirs.values())
            print(f"{name:12s} {ours['poses']:6d} {max(diffs):12.1e} {np.median(diffs):9.1e} "
                  f"{ours['trace_crlb']:14.6g} {trace_gtsam:12.6g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
