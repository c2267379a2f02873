"""The tangent system's per-pose kernels against the contractions they replace, file by file.

``posecrb.solver.tangent`` builds the columns ``G_a Z_i`` of E by copying signed rows of each block
(every generator G_a has one +-1 per row), and the k x k blocks ``tr((G_a Z_i)^T C_ij (G_b Z_j))``
of K from ``Z_i Z_j^T`` and four entries of C_ij per pair of generators, in the component-major
layout (block index last). This times both (gathers and layout changes included), at a seeded
random point of the first level's width d and of the width d + 1 after an escape, against the einsum
contractions written here as the reference (median of --repeat calls after a warm-up; every BLAS at
one thread), and prints the largest difference relative to the largest entry: 0 for the columns
of E (the same digits), rounding for the blocks of K. ``matrix`` is one whole assembly of K with
Lambda at width d, as the solver makes it at every factorization of K.

--solve DIR instead runs ``solve(load(FILE, quaternions="raw"))`` of the posecrb package in the
checkout DIR (e.g. ``git worktree add /tmp/before COMMIT``, or ``.`` for this one) under cProfile
with the process's CPU time, in a fresh interpreter per file, every BLAS at one thread, and prints
the CPU seconds of the tangent system's kernels (``matrix``, ``tangent_blocks``, ``gauge_modes``,
``diagonal_mean``; a call made inside another of them counted once) against the whole solve's.

Usage: python benchmarks/tangent_kernels.py [--repeat K] [--solve DIR] [--data-dir DIR] [NAME|FILE ...]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from _common import child_env, data_dir, median_time, print_header, suite_files

KERNELS = ("matrix", "tangent_blocks", "gauge_modes", "diagonal_mean")
SOLVE_CHILD = """
import cProfile, json, pstats, sys, time
sys.path.insert(0, sys.argv[1])
from posecrb.io import load
from posecrb.solver import solve
graph = load(sys.argv[2], quaternions="raw")
prof = cProfile.Profile(time.process_time)
prof.enable()
res = solve(graph)
prof.disable()
stats = pstats.Stats(prof).stats
kernels = set(sys.argv[3].split(","))
def is_kernel(key):
    return key[0].endswith("tangent.py") and key[2] in kernels
seconds = 0.0
for key, (_, _, _, cum, callers) in stats.items():
    if is_kernel(key):
        seconds += cum - sum(c[3] for caller, c in callers.items() if is_kernel(caller))
total = sum(v[2] for v in stats.values())
print(json.dumps({"kernels": seconds, "total": total, "objective": res.objective}))
"""


def solve_share(checkout: Path, files: list[Path]) -> int:
    """--solve: the kernels' CPU seconds within whole solves of ``checkout``'s posecrb."""
    print_header(f"CPU seconds of the tangent system's kernels within solve, checkout {checkout}", threads=1)
    print(f"\n{'dataset':32s} {'kernels s':>9s} {'solve s':>8s} {'share':>6s} {'objective':>18s}")
    env = child_env(1)
    env.pop("PYTHONPATH", None)     # the child puts the checkout first
    for path in files:
        argv = [sys.executable, "-c", SOLVE_CHILD, str(checkout.resolve()), str(path), ",".join(KERNELS)]
        proc = subprocess.run(argv, env=env, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            print(f"{path.stem:32s} failed: {proc.stderr.strip().splitlines()[-1:]}")
            continue
        out = json.loads(proc.stdout)
        print(f"{path.stem:32s} {out['kernels']:9.3f} {out['total']:8.2f} {out['kernels'] / out['total']:6.1%} "
              f"{out['objective']:18.12g}", flush=True)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--repeat", type=int, default=7, help="timed calls per kernel (median) [default: 7]")
    ap.add_argument("--solve", type=Path, default=None, metavar="DIR",
                    help="profile whole solves of the checkout DIR instead (module docstring)")
    args = ap.parse_args()
    files = suite_files(data_dir(args.data_dir), args.names)
    if not files:
        ap.error("no dataset files: name them, or set $POSECRB_DATA / --data-dir")
    if args.solve is not None:
        return solve_share(args.solve, files)
    from threadpoolctl import threadpool_limits

    from posecrb.io import load
    from posecrb.solver.problem import Problem
    from posecrb.solver.staircase import RelaxedModel
    from posecrb.solver.stiefel import from_components, random_point, to_components
    from posecrb.solver.tangent import TangentSystem, generator_traces

    print_header("the tangent system's kernels against einsum contractions (ms per call)", threads=1)
    print(f"\n{'dataset':32s} {'d':>1s} {'width':>5s} {'poses':>7s} | {'E einsum':>8s} {'E rows':>7s} "
          f"{'diff':>7s} | {'K blocks einsum':>15s} {'entries':>8s} {'diff':>7s} | {'matrix':>7s}")
    rng = np.random.default_rng(0)
    with threadpool_limits(1):
        for path in files:
            problem = Problem.from_graph(load(path, quaternions="raw"))
            system = TangentSystem.build(problem)
            n, d = problem.n, problem.d
            for width in (d, d + 1):
                Z = random_point(n, d, width, rng)
                G = system.basis
                ref_e = np.einsum("axy,nyc->naxc", G, Z)
                e_einsum = median_time(lambda: np.einsum("axy,nyc->naxc", G, Z), args.repeat)
                e_rows = median_time(lambda: system.tangent_blocks(Z), args.repeat)
                diff_e = np.abs(system.tangent_blocks(Z) - ref_e).max() / np.abs(ref_e).max()
                blocks_c = from_components(system.c_blocks)      # (nc, d, d)

                def contraction():
                    return np.einsum("naxc,nxy,nbyc->nab", ref_e[system.c_row], blocks_c, ref_e[system.c_col])

                def products():
                    Zt = to_components(Z)
                    left, right = Zt[:, :, system.c_row], Zt[:, :, system.c_col]
                    return from_components(generator_traces(system.entries, left, right, system.c_blocks))

                ref_k = contraction()
                k_einsum = median_time(contraction, args.repeat)
                k_products = median_time(products, args.repeat)
                diff_k = np.abs(products() - ref_k).max() / np.abs(ref_k).max()
                assembly = "-"
                if width == d:     # K exists at the first level's width only
                    lam = RelaxedModel(problem).evaluate(Z).lam
                    assembly = f"{1e3 * median_time(lambda: system.matrix(Z, lam, 1e-3), args.repeat):.2f}"
                print(f"{path.stem:32s} {d:1d} {width:5d} {n:7d} | {1e3 * e_einsum:8.2f} {1e3 * e_rows:7.2f} "
                      f"{diff_e:7.0e} | {1e3 * k_einsum:15.2f} {1e3 * k_products:8.2f} {diff_k:7.0e} | "
                      f"{assembly:>7s}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
