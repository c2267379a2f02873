"""Whole-process time: `posecrb crlb --model sed --frame body --poses all` vs gtsam.Marginals.

For each NAME (default: sphere2500) the certified estimate is computed once and written, with
the file's edges, to a temporary g2o file; then, median of REPEAT runs after a warm-up, each a
fresh Python process reading that same file and producing every per-pose covariance block:
  posecrb   python -m posecrb crlb EST --model sed --frame body --estimate vertices --poses all
            --format json (parse, FIM, factorization, selected inversion, JSON of all blocks)
  gtsam     gtsam.readG2o, a constrained prior on the first pose (the same gauge), Marginals,
            marginalCovariance of every other pose, blocks saved with numpy
and the largest relative (Frobenius) difference of the two sets of blocks. Needs gtsam
(pip install 'posecrb[gtsam]'); prints a note and exits 0 without it.
Usage: python benchmarks/gtsam_marginals.py [--repeat K] [NAME ...]
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import logging
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _common import median_time

from posecrb import load
from posecrb.datasets import search as datasets
from posecrb.io import write_g2o
from posecrb.solver.estimate import get_estimate

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


def main() -> None:
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=["sphere2500"])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    if importlib.util.find_spec("gtsam") is None:
        print("gtsam is not installed (pip install 'posecrb[gtsam]'): nothing to compare")
        return
    print(f"{'dataset':16s} {'n':>6s} {'posecrb s':>9s} {'gtsam s':>8s} {'ratio':>6s}  max rel diff")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.names:
            g = load(datasets.resolve(name))
            est = get_estimate(g, "solve")
            path = Path(tmp) / f"{g.name}_est.g2o"
            write_g2o(g, path, est.rot, est.trans)
            out_p, out_g = Path(tmp) / "posecrb.json", Path(tmp) / "gtsam.npz"
            cmd_p = [sys.executable, "-m", "posecrb", "crlb", str(path), "--model", "sed", "--frame", "body",
                     "--estimate", "vertices", "--poses", "all", "--format", "json"]
            cmd_g = [sys.executable, "-c", GTSAM_SCRIPT, str(path), str(g.dim), str(out_g)]

            def run_posecrb():
                with open(out_p, "w") as fh:
                    subprocess.run(cmd_p, check=True, stdout=fh)

            t_p = median_time(run_posecrb, args.repeat)
            t_g = median_time(lambda: subprocess.run(cmd_g, check=True), args.repeat)
            ours = json.loads(out_p.read_text())["per_pose"]
            with np.load(out_g) as z:
                diff = max(np.linalg.norm(b - np.array(ours[str(int(i))])) / np.linalg.norm(b)
                           for i, b in zip(z["ids"], z["blocks"]))
            print(f"{g.name:16s} {g.n:6d} {t_p:9.2f} {t_g:8.2f} {t_p / t_g:6.2f}  {diff:.1e}", flush=True)


if __name__ == "__main__":
    main()
