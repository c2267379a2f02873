"""The staircase level after the first escape with each of its two preconditioners, graph by graph.

After an escape from the first staircase level (width d + 1), ``posecrb solve`` preconditions with
the split preconditioner (``SolverOptions.split_precond``, docs/design.md#solver: the first level's
factor of K on the in-plane directions, the saddle's factor of M_red on the new column's) while the
new column is small, and with ``Proj (Q - Lambda + s I)^{-1} Proj`` through M_red otherwise. This
solves every graph both ways (``split_precond=True`` and ``False``, alternating; every BLAS at one
thread) and prints, for the graphs whose first level ends at a saddle, the Hessian-vector products
of the level after the escape (from the solver's own log records), of the whole solve, the number of
levels, the time and the relaxation values' relative difference; then the sums.

The graphs are noisy 2D grids made in memory (``posecrb.sim.generators.grid``, the noise model of
``benchmarks/grids.py``: tau = 1/sigma^2, kappa = 1/(2 sigma^2), seeds 0..K-1), and any FILE given.

--set MODULE.NAME=VALUE (repeatable) sets a module constant first (VALUE a Python literal), e.g.
``--set posecrb.solver.staircase.TANGENT_REFACTOR_HVPS=0``.

Usage: python benchmarks/split_precond.py [--sides 16,24,32] [--sigmas 0.3,0.4,0.5,0.7] [--seeds 6]
           [--set MODULE.NAME=VALUE] [FILE ...]
"""
from __future__ import annotations

import argparse
import ast
import importlib
import logging
import sys
import time

import numpy as np
from _common import print_header


class _LevelProducts(logging.Handler):
    """Collects each staircase level's cumulative product count from the solver's log records."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.levels: dict[int, int] = {}

    def emit(self, record: logging.LogRecord) -> None:
        if record.msg.startswith("staircase level") and "HVPs" in record.msg and isinstance(record.args, tuple):
            self.levels[int(record.args[0])] = int(record.args[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*")
    ap.add_argument("--sides", default="16,24,32", help="grid sides (poses = side^2) [default: 16,24,32]")
    ap.add_argument("--sigmas", default="0.3,0.4,0.5,0.7", help="noise levels [default: 0.3,0.4,0.5,0.7]")
    ap.add_argument("--seeds", type=int, default=6, help="seeds 0..K-1 per side and noise [default: 6]")
    ap.add_argument("--set", action="append", default=[], metavar="MODULE.NAME=VALUE",
                    help="set a module constant before solving (repeatable)")
    args = ap.parse_args()
    for setting in args.set:
        target, _, value = setting.partition("=")
        module, _, name = target.rpartition(".")
        mod = importlib.import_module(module)
        if not hasattr(mod, name):
            ap.error(f"{module} has no {name}")
        setattr(mod, name, ast.literal_eval(value))
    from threadpoolctl import threadpool_limits

    from posecrb.io import load
    from posecrb.sim.generators import grid
    from posecrb.solver.solve import solve

    handler = _LevelProducts()
    logger = logging.getLogger("posecrb")
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False

    graphs = []
    for side in (int(x) for x in args.sides.split(",") if x):
        for sigma in (float(x) for x in args.sigmas.split(",") if x):
            for seed in range(args.seeds):
                graphs.append((f"grid {side}x{side}, noise {sigma:g}, seed {seed}",
                               lambda side=side, sigma=sigma, seed=seed: grid(
                                   2, side, tau=1.0 / sigma ** 2, kappa=1.0 / (2.0 * sigma ** 2), noise=True,
                                   rng=np.random.default_rng(seed))))
    graphs += [(path, lambda path=path: load(path)) for path in args.files]
    print_header("the level after the first escape: the split preconditioner against M_red's", threads=1,
                 extra=[f"set: {', '.join(args.set)}"] if args.set else [])
    print(f"\n{'graph':34s} | {'level 2 HVPs':>13s} | {'all HVPs':>12s} | {'levels':>6s} | {'s':>13s} | "
          "rel. value diff")
    sums = np.zeros(6)
    escaping = 0
    with threadpool_limits(1):
        for name, make in graphs:
            graph = make()
            rows = []
            for split in (False, True):
                handler.levels.clear()
                t0 = time.perf_counter()
                res = solve(graph, split_precond=split)
                wall = time.perf_counter() - t0
                levels = dict(handler.levels)
                rows.append((levels, res, wall))
            if 2 not in rows[0][0] or 2 not in rows[1][0]:
                continue
            escaping += 1
            second = [lv[2] - lv[1] for lv, _, _ in rows]
            total = [res.hessian_vector_products for _, res, _ in rows]
            walls = [w for _, _, w in rows]
            diff = (rows[1][1].relaxation_value - rows[0][1].relaxation_value) / abs(rows[0][1].relaxation_value)
            sums += [*second, *total, *walls]
            print(f"{name:34s} | {second[0]:5d} -> {second[1]:5d} | {total[0]:5d} -> {total[1]:5d} | "
                  f"{max(rows[0][0])} -> {max(rows[1][0])} | {walls[0]:5.3f} -> {walls[1]:5.3f} | {diff:+.1e}")
    if escaping:
        print(f"{'sum over ' + str(escaping) + ' escaping graphs':34s} | {sums[0]:5.0f} -> {sums[1]:5.0f} | "
              f"{sums[2]:5.0f} -> {sums[3]:5.0f} |        | {sums[4]:5.2f} -> {sums[5]:5.2f} | "
              f"level 2 ratio {sums[1] / sums[0]:.3f}")
    print(f"{len(graphs) - escaping} of {len(graphs)} graphs certified at the first level (not shown)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
