"""A candidate preconditioner for the solver's first staircase level: the exact inverse Hessian on the tangent space.

At the first level the solver's point is n orthogonal d x d blocks Z_i (rotations, transposed).
Its tangent vectors are V_i = Omega_i Z_i with Omega_i skew: V = E theta, theta holding the
k = d(d-1)/2 coordinates of every Omega_i in the basis G_a of so(d). The Riemannian Hessian is
2 Proj(S V) with S = Q - Lambda, so on the tangent space its inverse is

    P r = E (2 E^T (S + s I) E)^{-1} E^T r,

exact for s = 0 (a Newton step: truncated CG ends after one or two products). Q is dense, but
E^T (S + s I) E is the Schur complement of a sparse matrix that keeps the translations, one copy
per column of Z (r = d copies), as M_red does for Q - Lambda + s I:

    K = [[L(W^tau) (x) I_r,   (V_red (x) I_r) E],
         [E^T (V_red (x) I_r)^T,   E^T ((C - Lambda) (x) I_r) E + s E^T E]],

(n-1) r + n k rows. The solver's preconditioner is instead P (Q - Lambda + s I)^{-1} P with the
tangent projection P, through M_red ((n-1) + n d rows), whose inverse is not the Hessian's on
the tangent space: truncated CG takes 11-44 products per trust-region iteration even at the
optimum.

For each file this runs the first level (trust region from the chordal initialisation, at width d)
twice with the same options: with the solver's own model (``RelaxedModel``, as ``posecrb solve``
builds it) and with K refactored at every accepted iterate at the solver's adaptive shift
s = 1e-10 x (Gershgorin bound of Q). Where that factorization fails (S + s I not positive definite
on the tangent space, away from the optimum) K is refactored without Lambda at the shift delta of
the solver's Lambda-free (Q + delta I)^{-1}, which never fails.

It prints the Hessian-vector products, iterations and factorizations (failed ones in brackets) of
both, the objectives' relative difference, the entries of K's and M_red's factors, the time of one
numeric factorization of each (CHOLMOD, analysis reused, median of --repeat), and an estimate of
the first level's time with K: factorizations x K's time + products x the measured cost of a
product and a solve. K is assembled with scipy's sparse products here (slow, not timed); the
estimate assumes an assembly into a fixed pattern, as M_red's.

Usage: python benchmarks/tangent_precond.py [--repeat K] [--data-dir DIR] [NAME|FILE ...]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
from _common import data_dir, print_header, suite_files


def _so_basis(d: int) -> np.ndarray:
    """(k, d, d) basis of so(d), each of Frobenius norm sqrt 2."""
    if d == 2:
        return np.array([[[0.0, -1.0], [1.0, 0.0]]])
    G = np.zeros((3, 3, 3))
    for a, (i, j) in enumerate(((2, 1), (0, 2), (1, 0))):
        G[a, i, j], G[a, j, i] = 1.0, -1.0
    return G


def _median_time(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _tangent_model(problem, base, shift, fallback_shift):
    import scipy.sparse as sp
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

    from posecrb.solver.staircase import RelaxedModel
    from posecrb.solver.stiefel import gram_eigh, remove_vertical

    class TangentModel(RelaxedModel):
        """RelaxedModel whose preconditioner is E (2 E^T (S + s I) E)^{-1} E^T at every accepted iterate."""

        def __init__(self) -> None:
            super().__init__(problem, base, None)
            d = problem.d
            ident = sp.identity(d, format="csr")
            self.Cbig = sp.kron(problem.C, ident, format="csr")
            self.Vbig = sp.kron(problem.Vred, ident, format="csr")
            self.Lbig = sp.kron(problem.Lred, ident, format="csc")
            self.G = _so_basis(d)
            self.tangent_factor = None
            self.factored_at = None
            self.failed = 0
            self.last_K = None

        def _E(self, Z):
            n, d, r = Z.shape
            k = self.G.shape[0]
            GZ = np.einsum("aij,njc->naic", self.G, Z)
            rows = (np.arange(n)[:, None, None, None] * d * r + np.arange(d)[None, None, :, None] * r
                    + np.arange(r)[None, None, None, :])
            cols = (np.arange(n)[:, None] * k + np.arange(k)[None, :])[:, :, None, None]
            return sp.csc_matrix((GZ.ravel(), (np.broadcast_to(rows, GZ.shape).ravel(),
                                               np.broadcast_to(cols, GZ.shape).ravel())),
                                 shape=(n * d * r, n * k))

        def matrix(self, state, s, with_lambda=True):
            E = self._E(state.Z)
            lam = sp.kron(sp.block_diag(list(state.lam), format="csr"), sp.identity(problem.d), format="csr")
            D = (E.T @ (((self.Cbig - lam) if with_lambda else self.Cbig) @ E)).tocsc() + s * (E.T @ E)
            B = (self.Vbig @ E).tocsc()
            return E, sp.bmat([[self.Lbig, B], [B.T, D]], format="csc")

        def prepare(self, state, last_hvps=None, converging=False):
            if self.factored_at is state.Z:
                return
            self.factored_at = state.Z
            order = "metis" if problem.n >= 50_000 else "amd"
            for with_lambda, s in ((True, shift), (False, fallback_shift)):
                E, K = self.matrix(state, s, with_lambda)
                self.factorizations += 1
                try:
                    self.tangent_factor = (cholesky(K, ordering_method=order), E)
                    self.last_K = K
                    return
                except CholmodNotPositiveDefiniteError:
                    self.failed += 1
            self.tangent_factor = None

        def precondition(self, state, R):
            if self.tangent_factor is None:
                return super().precondition(state, R)
            factor, E = self.tangent_factor
            n, d, r = R.shape
            ntr = self.Lbig.shape[0]
            b = np.zeros(ntr + E.shape[1])
            b[ntr:] = E.T @ R.ravel()
            eta = (E @ factor(b)[ntr:]).reshape(n, d, r) * 0.5
            if self._gram is None or self._gram[0] is not state.Z:
                self._gram = (state.Z, gram_eigh(state.Z))
            return remove_vertical(state.Z, eta, self._gram[1])

    return TangentModel()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--repeat", type=int, default=5, help="timed factorizations per figure (median) [default: 5]")
    args = ap.parse_args()
    from sksparse.cholmod import analyze
    from threadpoolctl import threadpool_limits

    from posecrb.io import load
    from posecrb.linalg.cholesky import solve_tail
    from posecrb.solver.chordal import chordal_rotations
    from posecrb.solver.problem import Problem
    from posecrb.solver.solve import SolverOptions
    from posecrb.solver.staircase import RelaxedModel
    from posecrb.solver.trust_region import TROptions, trust_region

    files = suite_files(data_dir(args.data_dir), args.names)
    if not files:
        ap.error("no dataset files: name them, or set $POSECRB_DATA / --data-dir")
    print_header("first staircase level: the solver's preconditioner against the tangent space's exact inverse",
                 threads=1)
    print(f"\n{'dataset':24s} {'d':>1s} {'poses':>6s} | {'solver: HVPs':>12s} {'it':>3s} {'fact':>4s} "
          f"{'level 1 s':>9s} | {'tangent: HVPs':>13s} {'it':>3s} {'fact':>7s} {'est. s':>7s} | {'F rel diff':>10s} | "
          f"{'nnz(L) M_red':>12s} {'K':>11s} {'factor M_red':>12s} {'K':>8s}")
    defaults = SolverOptions()
    with threadpool_limits(1):
        for path in files:
            graph = load(path, quaternions="raw")
            problem = Problem.from_graph(graph)
            Z0 = np.ascontiguousarray(np.swapaxes(chordal_rotations(problem), 1, 2))
            gersh = problem.gershgorin_max()
            base = problem.factor_full(None, gersh / defaults.precond_max_cond, name="preconditioner M_red(delta)")
            opts = TROptions()
            solver_model = RelaxedModel(problem, base, defaults.adaptive_precond * gersh,
                                        refactor_hvps=defaults.refactor_hvps)
            t0 = time.perf_counter()
            ours = trust_region(solver_model, Z0, opts)
            level1 = time.perf_counter() - t0
            tangent = _tangent_model(problem, base, defaults.adaptive_precond * gersh,
                                     gersh / defaults.precond_max_cond)
            theirs = trust_region(tangent, Z0, opts)
            # cost of one numeric factorization of each matrix, the analysis reused
            K = tangent.last_K if tangent.last_K is not None else tangent.matrix(theirs.state, 1e-3 * gersh)[1]
            order = "metis" if problem.n >= 50_000 else "amd"
            k_symbolic = analyze(K, ordering_method=order)
            k_time = _median_time(lambda: k_symbolic.cholesky(K, beta=1e-3 * gersh), args.repeat)
            k_nnz = k_symbolic.cholesky(K, beta=1e-3 * gersh).L().nnz
            m_time = _median_time(lambda: problem.factor_full(None, 1e-3 * gersh, name="M_red"), args.repeat)
            m_factor = problem.factor_full(None, 1e-3 * gersh, name="M_red")
            Zf = theirs.state.Z.reshape(-1, theirs.state.Z.shape[2])
            step = _median_time(lambda: (problem.Q_product(Zf), solve_tail(m_factor, problem.n - 1, Zf)),
                                args.repeat)
            m_nnz = m_factor.L().nnz
            estimate = tangent.factorizations * k_time + theirs.hvps * step
            rel = (theirs.state.f - ours.state.f) / abs(ours.state.f)
            print(f"{graph.name[:24]:24s} {graph.dim:1d} {graph.n:6d} | {ours.hvps:12d} {ours.iterations:3d} "
                  f"{solver_model.factorizations:4d} {level1:9.3f} | {theirs.hvps:13d} {theirs.iterations:3d} "
                  f"{tangent.factorizations:3d} ({tangent.failed:1d}) {estimate:7.3f} | {rel:+10.1e} | "
                  f"{m_nnz:12,d} {k_nnz:11,d} {m_time * 1e3:10.1f}ms {k_time * 1e3:6.1f}ms", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
