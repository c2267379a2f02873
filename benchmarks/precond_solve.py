"""The solver's preconditioner solve on one file: what it costs against the memory bound, and a candidate.

Builds the solver's data (``Problem.from_graph``) and its first preconditioner, the factor of
M_red(delta) that ``posecrb solve`` builds at the start (the pose-level nested dissection on large
graphs, CHOLMOD's supernodal kind above the fill switch), then times with every BLAS at one thread
(as inside the solver), median of --repeat calls after a warm-up:

* ``solve_tail`` (posecrb.linalg.cholesky) with k = 1, 3 and 8 right-hand sides: the rotation rows
  of M_red^{-1} [0; W], one call per truncated-CG step; once with CHOLMOD's BLAS at one thread and
  once on every core (what ``posecrb.linalg.threads.solve_threads`` gives the solves of large
  graphs when no other process keeps a core busy), the two calls alternating;
* the memory bound: the factor's values read twice (forward and backward substitution) at the rate
  one core streams an array of the same size here (``numpy.add.reduce``, median of --repeat);
* a candidate kept outside the package: a supernodal forward/backward substitution compiled with
  numba over the factor's CSC form (scikit-sparse's ``L()``, which converts CHOLMOD's factor in
  place to a simplicial one with the supernodes' pattern), loops vectorised by LLVM, columns in
  blocks of four; and CHOLMOD's own solve on that converted factor. Its result is checked against
  CHOLMOD's (the largest difference relative to the solution's largest entry is printed).

Usage: python benchmarks/precond_solve.py [--repeat K] FILE
(FILE: a path, e.g. the 2D grid of 100,489 poses from ``python benchmarks/grids.py 2 100000``.)
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
from _common import print_header


def _compiled_substitution():
    """The candidate's kernels, compiled on first use. Indices are unsigned (numba's wrap-around
    test for negative indices keeps LLVM from vectorising the loops), columns go in blocks of four
    (four axpys or dot products share one pass over the work vector), and only the dot products of
    the backward substitution may be reassociated (fastmath), so that they vectorise too."""
    from numba import njit, uint64

    flags = {"nogil": True, "boundscheck": False, "error_model": "numpy"}
    reassoc = {**flags, "fastmath": {"reassoc", "nsz"}}

    @njit(**flags)
    def axpy4(val, q0, q1, q2, q3, u, lo, hi, y0, y1, y2, y3):  # pragma: no cover - compiled
        for i in range(uint64(lo), uint64(hi)):
            u[i] -= (val[uint64(q0) + i] * y0 + val[uint64(q1) + i] * y1 + val[uint64(q2) + i] * y2
                     + val[uint64(q3) + i] * y3)

    @njit(**flags)
    def axpy1(val, q0, u, lo, hi, y0):  # pragma: no cover - compiled
        for i in range(uint64(lo), uint64(hi)):
            u[i] -= val[uint64(q0) + i] * y0

    @njit(**reassoc)
    def dot4(val, q0, q1, q2, q3, u, lo, hi):  # pragma: no cover - compiled
        s0 = s1 = s2 = s3 = 0.0
        for i in range(uint64(lo), uint64(hi)):
            ui = u[i]
            s0 += val[uint64(q0) + i] * ui
            s1 += val[uint64(q1) + i] * ui
            s2 += val[uint64(q2) + i] * ui
            s3 += val[uint64(q3) + i] * ui
        return s0, s1, s2, s3

    @njit(**reassoc)
    def dot1(val, q0, u, lo, hi):  # pragma: no cover - compiled
        s0 = 0.0
        for i in range(uint64(lo), uint64(hi)):
            s0 += val[uint64(q0) + i] * u[i]
        return s0

    @njit(**flags)
    def load(U, X, indptr, indices, bounds, s, gather):  # pragma: no cover - compiled
        """Supernode s's work rows from X: its own columns, and below them zeros (forward) or the
        rows it reads (``gather``, backward). Returns (first column, columns, rows, first entry)."""
        j0, w = bounds[s], bounds[s + 1] - bounds[s]
        p0, m = uint64(indptr[j0]), indptr[j0 + 1] - indptr[j0]
        for a in range(X.shape[0]):
            for i in range(uint64(w)):
                U[a, i] = X[a, uint64(j0) + i]
            for i in range(uint64(w), uint64(m)):
                U[a, i] = X[a, uint64(indices[p0 + i])] if gather else 0.0
        return j0, w, m, p0

    @njit(**flags)
    def substitute(indptr, indices, val, bounds, X):  # pragma: no cover - compiled
        """X (k, N) <- L^{-T} L^{-1} X for a lower CSC factor whose supernodes start at ``bounds``;
        val[indptr[j] - c + i] is L[rows[i], j] for column j = j0 + c of a supernode of rows ``rows``."""
        k = X.shape[0]
        nsup = bounds.shape[0] - 1
        maxm = 0
        for s in range(nsup):
            maxm = max(maxm, indptr[bounds[s] + 1] - indptr[bounds[s]])
        U = np.empty((k, maxm))
        for s in range(nsup):                           # forward: L y = b
            j0, w, m, p0 = load(U, X, indptr, indices, bounds, s, False)
            c = 0
            while c + 4 <= w:
                q0, q1 = indptr[j0 + c] - c, indptr[j0 + c + 1] - c - 1
                q2, q3 = indptr[j0 + c + 2] - c - 2, indptr[j0 + c + 3] - c - 3
                for a in range(k):
                    u = U[a]
                    y0 = u[c] / val[q0 + c]
                    u[c + 1] -= val[q0 + c + 1] * y0
                    u[c + 2] -= val[q0 + c + 2] * y0
                    u[c + 3] -= val[q0 + c + 3] * y0
                    y1 = u[c + 1] / val[q1 + c + 1]
                    u[c + 2] -= val[q1 + c + 2] * y1
                    u[c + 3] -= val[q1 + c + 3] * y1
                    y2 = u[c + 2] / val[q2 + c + 2]
                    u[c + 3] -= val[q2 + c + 3] * y2
                    y3 = u[c + 3] / val[q3 + c + 3]
                    u[c], u[c + 1], u[c + 2], u[c + 3] = y0, y1, y2, y3
                    axpy4(val, q0, q1, q2, q3, u, c + 4, m, y0, y1, y2, y3)
                c += 4
            while c < w:
                q0 = indptr[j0 + c] - c
                for a in range(k):
                    u = U[a]
                    u[c] = u[c] / val[q0 + c]
                    axpy1(val, q0, u, c + 1, m, u[c])
                c += 1
            for a in range(k):
                for i in range(uint64(w)):
                    X[a, uint64(j0) + i] = U[a, i]
                for i in range(uint64(w), uint64(m)):
                    X[a, uint64(indices[p0 + i])] += U[a, i]
        for s in range(nsup - 1, -1, -1):               # backward: L^T x = y
            j0, w, m, p0 = load(U, X, indptr, indices, bounds, s, True)
            c = w
            while c >= 4:
                q0, q1 = indptr[j0 + c - 4] - (c - 4), indptr[j0 + c - 3] - (c - 3)
                q2, q3 = indptr[j0 + c - 2] - (c - 2), indptr[j0 + c - 1] - (c - 1)
                for a in range(k):
                    u = U[a]
                    s0, s1, s2, s3 = dot4(val, q0, q1, q2, q3, u, c, m)
                    x3 = (u[c - 1] - s3) / val[q3 + c - 1]
                    x2 = (u[c - 2] - s2 - val[q2 + c - 1] * x3) / val[q2 + c - 2]
                    x1 = (u[c - 3] - s1 - val[q1 + c - 1] * x3 - val[q1 + c - 2] * x2) / val[q1 + c - 3]
                    x0 = (u[c - 4] - s0 - val[q0 + c - 1] * x3 - val[q0 + c - 2] * x2
                          - val[q0 + c - 3] * x1) / val[q0 + c - 4]
                    u[c - 1], u[c - 2], u[c - 3], u[c - 4] = x3, x2, x1, x0
                c -= 4
            while c >= 1:
                q0 = indptr[j0 + c - 1] - (c - 1)
                for a in range(k):
                    u = U[a]
                    u[c - 1] = (u[c - 1] - dot1(val, q0, u, c, m)) / val[q0 + c - 1]
                c -= 1
            for a in range(k):
                for i in range(uint64(w)):
                    X[a, uint64(j0) + i] = U[a, i]

    return substitute


def _median(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _median_pair(fa, fb, repeat: int) -> tuple[float, float]:
    """Medians of ``fa`` and ``fb``, called alternately ``repeat`` times each after a warm-up."""
    fa(), fb()
    ta, tb = [], []
    for _ in range(repeat):
        for fn, times in ((fa, ta), (fb, tb)):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
    return statistics.median(ta), statistics.median(tb)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file")
    ap.add_argument("--repeat", type=int, default=9, help="timed calls per figure (median) [default: 9]")
    args = ap.parse_args()
    from threadpoolctl import threadpool_limits

    from posecrb.io import load
    from posecrb.linalg.cholesky import PermutedFactor, solve_tail
    from posecrb.linalg.selinv import supernode_bounds
    from posecrb.linalg.threads import cholmod_blas, cholmod_threads
    from posecrb.solver.problem import Problem
    from posecrb.solver.solve import SolverOptions

    print_header("preconditioner solve: CHOLMOD against the memory bound and a compiled candidate", threads=1)
    graph = load(args.file)
    problem = Problem.from_graph(graph)
    delta = problem.gershgorin_max() / SolverOptions().precond_max_cond
    factor = problem.factor_full(None, delta, name="preconditioner M_red(delta)")
    first = problem.n - 1
    rng = np.random.default_rng(0)
    W = rng.standard_normal((problem.n * problem.d, 8))
    print(f"\n== {graph.name}: {graph.n} poses, {graph.m} edges, M_red {first + problem.n * problem.d} rows, "
          f"CHOLMOD kind {problem.factor_mode(problem.d + 1)}")
    cores = cholmod_threads()      # CHOLMOD's BLAS threads as the solver finds them (its solve_threads count)
    with threadpool_limits(1):
        blas = cholmod_blas()

        def on_every_core(k: int) -> np.ndarray:
            with blas.limit(limits=cores):
                return solve_tail(factor, first, W[:, :k])

        pairs = {k: _median_pair(lambda k=k: solve_tail(factor, first, W[:, :k]), lambda k=k: on_every_core(k),
                                 args.repeat) for k in (1, 3, 8)}
        cholmod = {k: one for k, (one, _) in pairs.items()}
        cholmod_all = {k: every for k, (_, every) in pairs.items()}
        reference = solve_tail(factor, first, W[:, :3])
        inner = factor._inner if isinstance(factor, PermutedFactor) else factor
        lower = inner.L()                       # converts CHOLMOD's factor in place (see above)
        nbytes = lower.data.nbytes
        stream = np.random.default_rng(1).standard_normal(lower.data.size)
        rate = nbytes / _median(lambda: np.add.reduce(stream), args.repeat)
        converted = _median(lambda: solve_tail(factor, first, W[:, :3]), args.repeat)
        bounds = supernode_bounds(lower.indptr, lower.indices)
        indptr = lower.indptr.astype(np.int64)
        perm = factor.P()
        position = np.empty_like(perm)
        position[perm] = np.arange(perm.size)
        rows = position[first:]
        substitute = _compiled_substitution()

        def candidate(k: int) -> np.ndarray:
            X = np.zeros((k, perm.size))
            X[:, rows] = W[:, :k].T
            substitute(indptr, lower.indices, lower.data, bounds, X)
            return X[:, rows].T

        compiled = {k: _median(lambda k=k: candidate(k), args.repeat) for k in (1, 3)}
        diff = float(np.max(np.abs(candidate(3) - reference)) / np.max(np.abs(reference)))
    print(f"factor: {lower.nnz:,} entries ({nbytes / 1e6:.0f} MB of values), {bounds.size - 1:,} supernodes")
    print(f"one core streams {rate / 1e9:.1f} GB/s here: two passes over the values take "
          f"{2 * nbytes / rate * 1e3:.1f} ms (the memory bound of a solve)")
    print(f"{'solve':58s} {'k=1':>8s} {'k=3':>8s} {'k=8':>8s}")
    print(f"{'CHOLMOD supernodal (solve_tail, what the solver does)':58s} "
          + " ".join(f"{cholmod[k] * 1e3:6.1f}ms" for k in (1, 3, 8)))
    print(f"{f'the same, CHOLMOD BLAS on {cores} threads (solve_threads)':58s} "
          + " ".join(f"{cholmod_all[k] * 1e3:6.1f}ms" for k in (1, 3, 8)))
    print(f"{'CHOLMOD on the converted simplicial factor':58s} {'':>8s} {converted * 1e3:6.1f}ms")
    print(f"{'compiled supernodal substitution (numba, candidate)':58s} "
          + " ".join(f"{compiled[k] * 1e3:6.1f}ms" for k in (1, 3)))
    print(f"candidate against CHOLMOD: largest difference {diff:.1e} of the solution's largest entry")
    return 0


if __name__ == "__main__":
    sys.exit(main())
