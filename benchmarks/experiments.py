"""Benchmark: the full CSAIL CRLB sweep (Fig. 6: 20 levels x 100 trials) with a 2-process pool,
plus the per-trial cost (perturb + certified solve + errors) measured serially.

Target: the full sweep in at most 10 minutes with --jobs 2. Prints figures; asserts nothing.
Usage: python benchmarks/experiments.py [--levels 1:20] [--trials 100] [--jobs 2] [--data-dir DIR]
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    from posecrb.core.errors import DatasetNotFound
    from posecrb.datasets import search as datasets
    from posecrb.experiments.crlb_sweep import _crlb_trial, crlb_sweep, parse_levels
    from posecrb.io import load
    from posecrb.sim.montecarlo import make_tasks
    from posecrb.solver import solve
    from posecrb.solver.rounding import anchor_estimate

    ap = argparse.ArgumentParser()
    ap.add_argument("--dataset", default="CSAIL")
    ap.add_argument("--levels", default="1:20")
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--data-dir", default=None)
    args = ap.parse_args()
    try:
        graph = load(datasets.resolve(args.dataset, args.data_dir))
    except DatasetNotFound as exc:
        print(f"skipped: {exc}")
        return
    kcs = parse_levels(args.levels)
    res = solve(graph)
    rot, trans = anchor_estimate(res.rot, res.trans, 0)
    ctx = {"graph": graph, "rot": rot, "trans": trans, "anchor": 0, "kc": 20.0, "scale": "both",
           "tau": None, "kappa": None, "solver_options": {}}
    times = []
    for task in make_tasks(0, 7, [(1,)]):
        t0 = time.perf_counter()
        _crlb_trial(ctx, task)
        times.append(time.perf_counter() - t0)
    per_trial = float(np.median(times[1:]))
    print(f"{graph.name}: {graph.n} poses, {graph.m} edges; one trial (perturb + solve + errors): "
          f"median {per_trial * 1e3:.1f} ms over {len(times) - 1} runs")
    t0 = time.perf_counter()
    sweep = crlb_sweep(graph, kcs, args.trials, 0, executor="local" if args.jobs > 1 else "serial",
                       jobs=args.jobs, truth=(res.rot, res.trans))
    wall = time.perf_counter() - t0
    n = len(kcs) * args.trials
    print(f"full sweep: {len(kcs)} levels x {args.trials} trials = {n} solves, --jobs {args.jobs}: "
          f"{wall:.1f} s wall ({wall / n * 1e3:.1f} ms per trial), target <= 600 s")
    last = sweep.levels[-1]
    print(f"k_c = {last.kc:g}: MSE/CRLB = {last.ratio:.4f} (+- {last.mse_stderr / last.mse_bound:.4f})")


if __name__ == "__main__":
    main()
