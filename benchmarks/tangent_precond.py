"""The solver's first staircase level with each of its two preconditioners, file by file.

``posecrb solve`` preconditions the first level (trust region from the chordal initialisation, at
width d) of a 2D graph with the exact inverse of the Riemannian Hessian on the tangent space
(``posecrb.solver.tangent``: a factor of the sparse matrix K whose Schur complement is
``E^T (S + s I) E``), and of a 3D graph with ``Proj (Q - Lambda + s I)^{-1} Proj`` through M_red
(``SolverOptions.tangent_precond``). This runs the first level both ways for every file, the two
alternating round by round (median of --repeat rounds after a warm-up; every BLAS at one thread):

* M_red: the base factor (Q + delta I)^{-1} built first, refactored as (Q - Lambda + s I)^{-1}
  after a truncated-CG run of more than 30 products (the solver's 3D path);
* K: ``TangentSystem.build`` (pattern and analysis) first, K refactored at accepted iterates, and
  the Newton-decrement stop at ``TROptions.exact_decrement_tol`` where K is factored at the
  iterate itself (the solver's 2D path).

It prints for each the Hessian-vector products, iterations, factorizations and the time (set-up
included), the objectives' relative difference, and the entries of one factor of M_red and of K.

Usage: python benchmarks/tangent_precond.py [--repeat K] [--data-dir DIR] [NAME|FILE ...]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
from _common import data_dir, print_header, suite_files


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--repeat", type=int, default=3, help="timed rounds per file (median) [default: 3]")
    args = ap.parse_args()
    from threadpoolctl import threadpool_limits

    from posecrb.io import load
    from posecrb.solver.chordal import chordal_rotations
    from posecrb.solver.problem import Problem
    from posecrb.solver.solve import SolverOptions
    from posecrb.solver.staircase import RelaxedModel
    from posecrb.solver.tangent import TangentSystem
    from posecrb.solver.trust_region import TROptions, trust_region

    files = suite_files(data_dir(args.data_dir), args.names)
    if not files:
        ap.error("no dataset files: name them, or set $POSECRB_DATA / --data-dir")
    print_header("the solver's first staircase level: M_red's preconditioner against the tangent space's (K)",
                 threads=1)
    print(f"\n{'dataset':24s} {'d':>1s} {'poses':>6s} | {'M_red: HVPs':>11s} {'it':>3s} {'fact':>4s} {'s':>7s} | "
          f"{'K: HVPs':>7s} {'it':>3s} {'fact':>4s} {'s':>7s} | {'F rel diff':>10s} | {'nnz(L) M_red':>12s} {'K':>11s}")
    defaults = SolverOptions()
    opts = TROptions()
    with threadpool_limits(1):
        for path in files:
            graph = load(path, quaternions="raw")
            problem = Problem.from_graph(graph)
            Z0 = np.ascontiguousarray(np.swapaxes(chordal_rotations(problem), 1, 2))
            gersh = problem.gershgorin_max()
            delta, shift = gersh / defaults.precond_max_cond, defaults.adaptive_precond * gersh
            problem.factor_full(None, delta, name="warm-up: M_red's pattern and analysis")

            def schur():
                base = problem.factor_full(None, delta, name="preconditioner M_red(delta)")
                model = RelaxedModel(problem, base, shift, refactor_hvps=defaults.refactor_hvps)
                return model, trust_region(model, Z0, opts)

            def tangent():
                model = RelaxedModel(problem, None, shift, refactor_hvps=defaults.refactor_hvps,
                                     tangent=TangentSystem.build(problem), tangent_fallback_shift=delta,
                                     base_factory=lambda: problem.factor_full(None, delta, name="base"))
                return model, trust_region(model, Z0, opts)

            runs: dict[str, list] = {"M_red": [], "K": []}
            for k in range(args.repeat + 1):
                for name, fn in (("M_red", schur), ("K", tangent)) if k % 2 == 0 else (("K", tangent),
                                                                                      ("M_red", schur)):
                    t0 = time.perf_counter()
                    model, res = fn()
                    if k:
                        runs[name].append((time.perf_counter() - t0, model, res))
            (_, m_model, m_res), (_, k_model, k_res) = runs["M_red"][0], runs["K"][0]
            m_time = statistics.median(t for t, _, _ in runs["M_red"])
            k_time = statistics.median(t for t, _, _ in runs["K"])
            m_nnz = problem.factor_full(None, delta, name="M_red").L().nnz
            system = TangentSystem.build(problem)
            k_nnz = system.factor(k_res.state.Z, None, delta, name="K").L().nnz
            rel = (k_res.state.f - m_res.state.f) / abs(m_res.state.f)
            print(f"{graph.name[:24]:24s} {graph.dim:1d} {graph.n:6d} | {m_res.hvps:11d} {m_res.iterations:3d} "
                  f"{m_model.factorizations + 1:4d} {m_time:7.3f} | {k_res.hvps:7d} {k_res.iterations:3d} "
                  f"{k_model.factorizations:4d} {k_time:7.3f} | {rel:+10.1e} | {m_nnz:12,d} {k_nnz:11,d}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
