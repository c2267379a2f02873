"""Every pose's covariance: ``posecrb crlb --model sed --frame body --poses all`` against GTSAM's
``Marginals``, whole process against whole process (hyperfine).

For each NAME (default sphere2500 and torus3D; --quick the 125-pose 3D grid) the certified estimate
is written once, untimed, with the file's edges (``posecrb solve FILE --out EST.g2o``); then two
programs read that same file and produce every per-pose covariance block:

  posecrb   posecrb crlb EST --model sed --frame body --estimate vertices --poses all --format json
  GTSAM     gtsam.readG2o, a constrained prior on the first pose (the same gauge), Marginals and
            marginalCovariance of every other pose, the blocks saved with numpy

and the check runs give the largest relative (Frobenius) difference of the two sets of blocks.
Needs gtsam in this interpreter (``pip install '.[gtsam]'``); skipped without it.

Usage: python benchmarks/peers/gtsam_marginals.py [--quick] [--runs K] [--warmup K] [--threads T]
       [--out DIR] [NAME ...]
"""
from __future__ import annotations

import importlib.util
import sys
import tempfile
from pathlib import Path

import _peer  # noqa: F401 -- benchmarks/ on sys.path
import harness
import numpy as np
from harness import Command, posecrb_cli
from suite import inputs

GTSAM_SCRIPT = r"""
import sys
import numpy as np
import gtsam
path, is3d, out = sys.argv[1], sys.argv[2] == "3", sys.argv[3]
graph, initial = gtsam.readG2o(path, is3d)
keys = sorted(initial.keys())
prior = gtsam.PriorFactorPose3 if is3d else gtsam.PriorFactorPose2
pose = initial.atPose3(keys[0]) if is3d else initial.atPose2(keys[0])
graph.add(prior(keys[0], pose, gtsam.noiseModel.Constrained.All(6 if is3d else 3)))
marginals = gtsam.Marginals(graph, initial)
np.savez(out, ids=np.array(keys[1:]), blocks=np.stack([marginals.marginalCovariance(k) for k in keys[1:]]))
"""


def largest_difference(posecrb_json: dict, gtsam_npz: Path) -> float:
    """max over poses of ||B_gtsam - B_posecrb||_F / ||B_gtsam||_F."""
    ours = posecrb_json["per_pose"]
    with np.load(gtsam_npz) as z:
        return max(float(np.linalg.norm(b - np.array(ours[str(int(i))])) / np.linalg.norm(b))
                   for i, b in zip(z["ids"], z["blocks"]))


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="datasets or grids [default: sphere2500 torus3D]")
    args = harness.parse(ap, argv)
    absent = "" if importlib.util.find_spec("gtsam") else "gtsam is not installed here (pip install '.[gtsam]')"
    group = harness.start("gtsam", args, absent)
    if group is None:
        return 0
    names = args.names or ([inputs.GRID_3D_SMALL] if args.quick else ["sphere2500", "torus3D"])
    with tempfile.TemporaryDirectory(prefix="posecrb-gtsam-") as tmp:
        for name, file in harness.found("gtsam", names):
            estimate, blocks = Path(tmp) / f"{name}-estimate.g2o", Path(tmp) / f"{name}-gtsam.npz"
            solved = harness.check_run(Command("solve", posecrb_cli("solve", str(file), "--out", str(estimate),
                                                                     "--format", "json")))
            if not solved.ok:
                print(f"gtsam: {name}: the estimate failed: {solved.reason()}", file=sys.stderr)
                continue
            entry = group.compare(name, [
                Command("posecrb", posecrb_cli("crlb", str(estimate), "--model", "sed", "--frame", "body",
                                               "--estimate", "vertices", "--poses", "all", "--format", "json")),
                Command("GTSAM", (sys.executable, "-c", GTSAM_SCRIPT, str(estimate), str(inputs.dimension(name)),
                                  str(blocks)))])
            if entry is None:
                continue
            ours = entry["outputs"]["posecrb"].json()
            entry["checks"].update(poses=ours.get("poses"), dim=ours.get("dim"),
                                   largest_relative_difference=largest_difference(ours, blocks))
    group.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
