"""posecrb.solver.solve with option variants, in-process, per dataset: where the solver's time goes.

For every dataset (default: the mid-size and large SE-Sync files) runs ``load`` once and then
``solve(graph, **variant)`` for each variant, alternating variant by variant, one warm-up round,
then the median of --repeat rounds; prints total and phase times, trust-region iterations,
Hessian-vector products, rank, certificate and the objective's relative difference to the
baseline variant. Variants (keyword arguments of posecrb.solver.solve):
  base          the defaults
  fixed-precond adaptive_precond=None: the regularised factor (Q + delta I)^-1 built once, as
                SE-Sync's RegularizedCholesky, never (Q - Lambda + s I)^-1
  every-iterate refactor_hvps=None: (Q - Lambda + s I)^-1 refactored at every accepted iterate
                (the default refactors only after a truncated CG run of more than 30 products)
  refactor>K    refactor_hvps=K
  theta=1       truncated CG stops at ||r|| <= ||r0|| min(kappa, ||r0||^1) (Manopt; default exponent 0.5)
  r0=5          start the staircase at rank 5 (SE-Sync's default) instead of d + 1
  no-precond    precondition=False (the unpreconditioned trust region, for scale)
  no-cert-stop  certified_rel_decrease=None: never stop a level early when the preconditioner's
                factorization at an accepted iterate already certifies it
  dec=1e-9      decrement_tol=1e-9 (default 1e-11): stop at a 100x larger Newton decrement
  dec=1e-10     decrement_tol=1e-10
BLAS is single-threaded (the solver limits it itself). Usage:
  python benchmarks/solver_variants.py [--repeat K] [--variants base,fixed-precond,r0=5] [--sesync-compat] [NAME ...]
"""
from __future__ import annotations

import argparse
import logging
import statistics
import sys
import time

from _common import data_dir, print_header, suite_files

VARIANTS = {
    "base": {},
    "fixed-precond": {"adaptive_precond": None},
    "every-iterate": {"refactor_hvps": None},
    "refactor>10": {"refactor_hvps": 10},
    "refactor>60": {"refactor_hvps": 60},
    "r0=5": {"r0": 5},
    "theta=1": {"theta": 1.0},
    "no-precond": {"precondition": False},
    "no-cert-stop": {"certified_rel_decrease": None},
    "dec=1e-9": {"decrement_tol": 1e-9},
    "dec=1e-10": {"decrement_tol": 1e-10},
}
DEFAULT_NAMES = ["city10000", "ais2klinik", "parking-garage", "sphere2500", "sphere_bignoise_vertex3",
                 "torus3D", "cubicle"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--variants", default="base,fixed-precond,r0=5")
    ap.add_argument("--sesync-compat", action="store_true", help="read 3D quaternions as SE-Sync does")
    args = ap.parse_args(argv)
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    from posecrb import load
    from posecrb.solver import solve

    variants = [v for v in args.variants.split(",") if v]
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        ap.error(f"unknown variants {sorted(unknown)}; choose from {sorted(VARIANTS)}")
    files = suite_files(data_dir(args.data_dir), args.names or DEFAULT_NAMES)
    print_header("posecrb.solver.solve option variants (in-process)", None,
                 [f"median of {args.repeat} alternating rounds after one warm-up round; times in seconds"])
    print(f"{'dataset':24s} {'variant':14s} {'total':>7s} {'init':>6s} {'optim':>7s} {'verify':>6s} {'its':>4s} "
          f"{'HVPs':>5s} {'rank':>4s} {'cert':>4s} {'objective':>18s} {'rel to base':>11s}")
    for path in files:
        if not path.is_file():
            print(f"{path.stem:24s} missing: {path}")
            continue
        g = load(path, quaternions="raw" if args.sesync_compat else "normalize")
        runs: dict[str, list] = {v: [] for v in variants}
        for k in range(args.repeat + 1):
            for v in (variants if k % 2 == 0 else variants[::-1]):
                t0 = time.perf_counter()
                res = solve(g, **VARIANTS[v])
                wall = time.perf_counter() - t0
                if k:
                    runs[v].append((wall, res))
        base_obj = None
        for v in variants:
            ordered = sorted(runs[v], key=lambda x: x[0])
            wall, res = ordered[(len(ordered) - 1) // 2]
            wall = statistics.median(x[0] for x in runs[v])
            base_obj = res.objective if base_obj is None else base_obj
            t = res.times
            print(f"{g.name:24s} {v:14s} {wall:7.3f} {t['init']:6.3f} {t['optimize']:7.3f} {t['verify']:6.3f} "
                  f"{res.iterations:4d} {res.hessian_vector_products:5d} {res.rank:4d} "
                  f"{'yes' if res.certified else 'NO':>4s} {res.objective:18.10f} "
                  f"{(res.objective - base_obj) / abs(base_obj):11.1e}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
