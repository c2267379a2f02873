"""The dual certificate: Lambda, ``S = Q - Lambda`` and the test ``lambda_min(S) >= -eta`` by sparse Cholesky.

SE-Sync (Rosen et al., IJRR 2019), section 4.2-4.3: at a first-order critical point Y of the
rank-r relaxation, ``Lambda = SymBlockDiag(Q Y^T Y)`` and ``S = Q - Lambda``; if ``S >= 0``
(within tolerance) Y solves the SDP relaxation globally, otherwise an eigenvector v of S with
``v^T S v < 0`` gives the staircase's escape direction (posecrb.solver.staircase).

Verification uses the sparse identity ``(Q - Lambda + s I)^{-1} = [M_red(s)^{-1}]_{RR}``
(see problem.py): one sparse Cholesky of ``M_red(eta)`` decides ``lambda_min(S) > -eta``
(SE-Sync's first test); its factor also drives a shift-invert Lanczos for the value of
lambda_min. When it fails, increasing shifts locate a PD shift sigma and shift-invert
Lanczos at -sigma returns the negative eigenpair for the escape.

What "certified" means (the tolerance eta, ``certificate_tol``, default 1e-3): posecrb accepts
``lambda_min(Q - Lambda) >= -eta`` on the translation-ELIMINATED certificate. For any feasible
point Z of the SDP (diagonal blocks I_d), ``tr(Q Z) >= f(Y) + n d lambda_min(Q - Lambda)``, so a
certified solve proves ``F* >= f(Y) - n d eta``: an absolute suboptimality bound of at most
``n d eta`` plus the rounding gap (``SolveResult.duality_gap``). The bound is ``n d s`` for the shift
``s <= eta`` of the Cholesky that certified (``Certificate.proven_shift``); ``solve`` warns where it
does not fall below the objective, i.e. where a large tolerance leaves "certified" without content.
SE-Sync's C++ test is looser: it factors ``M - Lambda + eta I`` with eta added to the translation
rows as well. Its Schur complement is ``C - Lambda + eta I - V^T (L(W^tau) + eta I)^{-1} V``, which exceeds
``Q - Lambda + eta I`` by ``V^T [L^{-1} - (L + eta I)^{-1}] V`` -- large where L(W^tau) has small
eigenvalues (big, weakly connected graphs) -- and the dual bound it implies is only
``F* >= f(Y) - eta (n d + sum_i |t_i - t_0|^2)``, with the translations' spread in it. On the
noisy 2D grid of 100,489 poses, SE-Sync's test passes at a rank-3 point where
``lambda_min(Q - Lambda) = -3.7e-3``; there ``n d eta = 201`` but
``eta sum |t_i - t_0|^2 = 6.7e6`` against F ~ 3.0e5, i.e. no bound at all. posecrb keeps the
strict test, escapes into the rank-3 start's zero column there and certifies
``lambda_min = -4e-9`` at rank 3 (the relaxation value lower by 0.015).

:func:`dual_certificate` builds the same certificate from rotations computed elsewhere, with the
same test, so "certified" means the same for an estimate of another program.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import NotPositiveDefinite, SolverError
from ..linalg.cholesky import Factor
from ..linalg.lanczos import largest_eigenpair
from .problem import Problem
from .stiefel import sym_block_diag_product


@dataclass(frozen=True)
class Certificate:
    """The outcome of :func:`verify` at one point."""

    certified: bool
    lambda_min: float
    vector: np.ndarray | None      # (n, d) unit eigenvector for lambda_min < -tol
    factorizations: int
    lanczos_solves: int
    # When certified: the shift s <= tol of the successful Cholesky of Q - Lambda + s I, which
    # proves lambda_min > -s (lambda_min itself is a Lanczos estimate).
    proven_shift: float | None = None
    # When not: the factor of Q - Lambda + sigma I the shift search found, and sigma
    shifted_factor: tuple[Factor, float] | None = None
    # When certified: the factor of Q - Lambda + s I that proved it, and s (for a Newton decrement at
    # the point, posecrb.verification.judge)
    proven_factor: tuple[Factor, float] | None = None


# Relative residual tolerances of the shift-invert Lanczos runs in verify() (||A x - theta x|| <=
# tol theta). A certified point: the Ritz value is only the reported estimate of lambda_min (the
# factorization is the proof), and its error is second order in the residual (Kato-Temple), so
# 1e-8 keeps it far below the certificate's eta while the last digits of residual, which cost the
# most Lanczos steps, are not computed. A saddle: the eigenvector is the escape direction, which
# backtracking and the next level's trust region refine, so a coarse one reaches the same optima
# (docs/decisions/solver-preconditioners.md).
CERTIFIED_LANCZOS_TOL = 1e-8
SADDLE_LANCZOS_TOL = 1e-4


def _largest_inverse_eig(problem: Problem, factor: Factor, dn: int, rng: np.random.Generator, maxiter: int,
                         tol: float, v0: np.ndarray | None = None) -> tuple[float, np.ndarray, int]:
    """Largest eigenpair of (S + s I)^{-1} through the sparse factor of M_red(s) (thick-restart Lanczos,
    at most ``maxiter`` restarts; an unconverged search returns its best Ritz pair, which the callers
    only use as an estimate or check against the exact operator)."""
    def apply_inverse(x: np.ndarray) -> np.ndarray:
        return problem.schur_solve(factor, x.reshape(dn, 1)).ravel()

    if v0 is None:
        v0 = rng.standard_normal(dn)
    ritz = largest_eigenpair(apply_inverse, v0, tol=tol, max_restarts=maxiter)
    return ritz.value, ritz.vector, ritz.matvecs


def verify(problem: Problem, lam: np.ndarray, tol: float, rng: np.random.Generator,
           estimate_lambda: bool = True, factor: tuple[Factor, float] | None = None) -> Certificate:
    """Decide ``lambda_min(Q - Lambda) >= -tol`` by sparse Cholesky; return the eigenpair if not.

    ``lam`` holds Lambda's (n, d, d) blocks. ``tol`` must be finite and >= 0 (a NaN made the
    shift search below loop forever); a non-finite certificate matrix is a SolverError, never an
    endless search. ``factor`` is an optional ``(Cholesky factor of M_red(Lambda, s), s)`` with
    0 <= s <= tol at this very Lambda (the adaptive preconditioner's): it already decides the
    test, so no factorization is done.
    """
    if not (math.isfinite(tol) and tol >= 0):
        raise SolverError(f"certificate tolerance must be a finite number >= 0, got {float(tol)}")
    n, d = problem.n, problem.d
    dn = n * d
    facs = 0
    if factor is not None and 0.0 <= factor[1] <= tol:
        fac, shift = factor
    else:
        shift = tol
        facs = 1
        try:
            fac = problem.factor_full(lam, tol, name="certificate matrix Q - Lambda + eta I")
        except NotPositiveDefinite:
            fac = None
    if fac is not None:
        lm = 0.0
        solves = 0
        if estimate_lambda:
            mu, _, solves = _largest_inverse_eig(problem, fac, dn, rng, maxiter=50, tol=CERTIFIED_LANCZOS_TOL)
            lm = 1.0 / mu - shift if mu > 0 else -shift
            lm = max(lm, -shift)   # the factorization proved lambda_min > -shift >= -tol
        return Certificate(True, lm, None, facs, solves, proven_shift=float(shift), proven_factor=(fac, float(shift)))
    # Not PSD within tol: find a positive-definite shift, then shift-invert at it.
    scale = problem.gershgorin_max() + float(np.max(np.abs(lam)))
    if not math.isfinite(scale):
        raise SolverError("the certificate matrix Q - Lambda has non-finite entries; cannot verify the estimate")
    sigma = max(10.0 * tol, 1e-9 * scale, np.finfo(float).tiny)
    facs = 1
    while True:   # sigma grows 10x per step from >= 1e-9 scale to 4 scale: at most ~11 steps
        try:
            fac = problem.factor_full(lam, sigma, name="shifted certificate matrix")
            facs += 1
            break
        except NotPositiveDefinite:
            facs += 1
            if sigma > 4 * scale:
                raise
            sigma *= 10.0
    mu, v, solves = _largest_inverse_eig(problem, fac, dn, rng, maxiter=300, tol=SADDLE_LANCZOS_TOL)
    lm = 1.0 / mu - sigma
    v = v / np.linalg.norm(v)
    # Rayleigh quotient with the exact operator (guards against an inaccurate Ritz value).
    rq = float(v @ certificate_product(problem, lam, v[:, None]).ravel())
    lm = min(lm, rq) if rq < 0 else lm
    certified = lm >= -tol
    return Certificate(certified, lm, None if certified else v.reshape(n, d), facs, solves,
                       shifted_factor=(fac, float(sigma)))


# ---- the certificate of given rotations ------------------------------------------------------

def rows_of(rot: np.ndarray) -> np.ndarray:
    """The row layout of problem.py for rotations (n, d, d): ``Z_i = R_i^T``."""
    return np.ascontiguousarray(np.swapaxes(np.asarray(rot, dtype=float), 1, 2))


def lagrange_multipliers(problem: Problem, rot: np.ndarray) -> np.ndarray:
    """Lambda(R) = SymBlockDiag(Q R^T R), SE-Sync's Lagrange multiplier, as its (n, d, d) diagonal
    blocks ``sym((Q Z)_i Z_i^T)`` with ``Z_i = R_i^T`` (``R = [R_1 ... R_n]`` is d x dn)."""
    Z = rows_of(rot)
    n, d, r = Z.shape
    QZ = problem.Q_product(Z.reshape(n * d, r)).reshape(n, d, r)
    return sym_block_diag_product(QZ, Z)


def certificate_product(problem: Problem, lam: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``S X = (Q - Lambda) X`` for X (dn, k), Lambda by its (n, d, d) blocks (Q never formed)."""
    n, d = problem.n, problem.d
    k = X.shape[1]
    return problem.Q_product(X) - (lam @ X.reshape(n, d, k)).reshape(n * d, k)


@dataclass(frozen=True)
class DualCertificate:
    """SE-Sync's dual certificate of given rotations: ``Lambda`` (n, d, d) blocks, the test of
    ``S = Q - Lambda`` by :func:`verify` (``certificate``) and the tolerance it used."""

    lam: np.ndarray
    certificate: Certificate
    tol: float

    @property
    def certified(self) -> bool:
        return self.certificate.certified

    @property
    def lambda_min(self) -> float:
        return self.certificate.lambda_min


def dual_certificate(problem: Problem, rot: np.ndarray, tol: float = 1e-3,
                     rng: np.random.Generator | None = None) -> DualCertificate:
    """The certificate of rotations ``rot`` (n, d, d): Lambda(R) and ``lambda_min(Q - Lambda) >= -tol``
    decided by the same :func:`verify` as ``solve``'s.

    The rotations certify global optimality (of the rank-d relaxation, hence of F with optimal
    translations) only where they are a critical point, which the test itself does not check:
    the Riemannian gradient (posecrb.solver.refine.relaxed_gradient) says how close they are.
    ``rng`` seeds the Lanczos start (default seed 0, as ``solve``'s).
    """
    lam = lagrange_multipliers(problem, rot)
    cert = verify(problem, lam, tol, np.random.default_rng(0) if rng is None else rng)
    return DualCertificate(lam, cert, float(tol))
