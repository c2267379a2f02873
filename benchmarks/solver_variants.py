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
  no-split      split_precond=False: after an escape from the first level, M_red's preconditioner
                instead of the split one (K's factor in-plane, M_red's on the new column)
  schur-base    base_precond="schur": SE-Sync's base preconditioner (Q + delta I)^-1, a factor of M_red(delta)
  rotation-base base_precond="rotation": the rotation block's (C + delta I)^-1 (d rows per pose, no
                translations), the default on 3D graphs of at least 10,000 poses
  r0=5          start the staircase at rank 5 (SE-Sync's default) instead of d + 1
  no-precond    precondition=False (the unpreconditioned trust region, for scale)
  no-cert-stop  certified_rel_decrease=None: never stop a level early when the preconditioner's
                factorization at an accepted iterate already certifies it
  dec=1e-9      decrement_tol=1e-9 (default 1e-11): stop at a 100x larger Newton decrement
  dec=1e-10     decrement_tol=1e-10
BLAS is single-threaded (the solver limits it itself).

With --kernels, instead of solving, times the kernels behind the solver's implementation choices
per dataset (thread CPU time, the best of --repeat rounds x 5, robust to other load on the machine):
the M_red factorization and a solve with d + 1 right-hand sides for CHOLMOD's simplicial and
supernodal kinds next to the kind the solver picks (posecrb.solver.problem.factor_mode, with its
fill measure (d + 1) sum c^2 / sum c), the product C Z through scipy's CSR and CSC kernels, and
the nearest rotations of the chordal blocks by batched SVD (lie.so.so_project) and by
solver.stiefel.nearest_rotations. Usage:
  python benchmarks/solver_variants.py [--repeat K] [--variants base,fixed-precond,r0=5] [--sesync-compat] [NAME ...]
  python benchmarks/solver_variants.py --kernels [--repeat K] [NAME ...]
"""
from __future__ import annotations

import argparse
import logging
import math
import statistics
import sys
import time

from _common import data_dir, print_header, suite_files

VARIANTS = {
    "base": {},
    "fixed-precond": {"adaptive_precond": None},
    "every-iterate": {"refactor_hvps": None},
    "refactor>5": {"refactor_hvps": 5},
    "refactor>10": {"refactor_hvps": 10},
    "refactor>60": {"refactor_hvps": 60},
    "r0=5": {"r0": 5},
    "theta=1": {"theta": 1.0},
    "no-precond": {"precondition": False},
    "no-split": {"split_precond": False},
    "schur-base": {"base_precond": "schur"},
    "rotation-base": {"base_precond": "rotation"},
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
    ap.add_argument("--kernels", action="store_true", help="time the solver's kernel choices instead")
    args = ap.parse_args(argv)
    files = suite_files(data_dir(args.data_dir), args.names or DEFAULT_NAMES)
    if not files:
        ap.error("no data directory: give --data-dir or set POSECRB_DATA")
    if args.kernels:
        return kernels(files, args.repeat)
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    from posecrb import load
    from posecrb.solver import solve

    variants = [v for v in args.variants.split(",") if v]
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        ap.error(f"unknown variants {sorted(unknown)}; choose from {sorted(VARIANTS)}")
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


def _best_cpu(fn, rounds: int) -> float:
    """Best thread CPU time of ``fn`` over ``rounds`` x 5 calls (after one warm-up), in ms."""
    fn()
    best = math.inf
    for _ in range(5 * max(rounds, 1)):
        t0 = time.thread_time()
        fn()
        best = min(best, time.thread_time() - t0)
    return 1e3 * best


def kernels(files, rounds: int) -> int:
    import numpy as np
    from threadpoolctl import threadpool_limits

    from posecrb import load
    from posecrb.lie.so import so_project
    from posecrb.linalg.cholesky import SymbolicCholesky
    from posecrb.solver.chordal import chordal_rotations
    from posecrb.solver.problem import Problem
    from posecrb.solver.stiefel import nearest_rotations

    print_header("posecrb.solver kernel choices (thread CPU time, ms)", 1,
                 [f"best of {5 * rounds} calls after one warm-up; BLAS single-threaded as in the solver"])
    print(f"{'dataset':24s} {'fill':>6s} {'picked':>10s} {'simpl fac':>9s} {'solve':>6s} {'super fac':>9s} "
          f"{'solve':>6s} {'C@Z csr':>7s} {'csc':>6s} {'SVD rot':>7s} {'nearest':>7s}")
    with threadpool_limits(1, user_api="blas"):
        for path in files:
            if not path.is_file():
                print(f"{path.stem:24s} missing: {path}")
                continue
            p = Problem.from_graph(load(path))
            d = p.d
            M = p.full_matrix(None, p.gershgorin_max() / 1e6)
            rhs = np.asfortranarray(np.random.default_rng(0).standard_normal((M.shape[0], d + 1)))
            cells = []
            for mode in ("simplicial", "supernodal"):
                sym = SymbolicCholesky(M, mode=mode)
                f = sym.factor(M)
                cells += [_best_cpu(lambda: sym.factor(M), rounds), _best_cpu(lambda: f.solve_A(rhs), rounds)]
            Z = np.random.default_rng(1).standard_normal((p.n * d, d + 1))
            C_csc = p.C.tocsc()
            cells += [_best_cpu(lambda: p.C @ Z, rounds), _best_cpu(lambda: C_csc @ Z, rounds)]
            noise = 0.1 * np.random.default_rng(2).standard_normal((p.n, d, d))
            blocks = np.swapaxes(chordal_rotations(p), 1, 2) + noise
            cells += [_best_cpu(lambda: so_project(blocks), rounds),
                      _best_cpu(lambda: nearest_rotations(blocks), rounds)]
            print(f"{path.stem:24s} {(d + 1) * p.pose_fill():6.0f} {p.factor_mode(d + 1):>10s} "
                  + " ".join(f"{c:{w}.2f}" for c, w in zip(cells, (9, 6, 9, 6, 7, 6, 7, 7), strict=True)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
