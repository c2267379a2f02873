"""Is an estimate the global optimum? The certificate at the estimate, the basin, and the tolerances
its file's digits set (docs/design.md#verify).

The objective is the maximum-likelihood objective that ``posecrb solve`` minimises (SE-Sync's
``F(R, t) = sum kappa ||R_j - R_i R~||_F^2 + tau ||t_j - t_i - R_i t~||^2``). For rotations R the
dual certificate ``S = Q - Lambda(R)``, ``Lambda = SymBlockDiag(Q R^T R)``, bounds the optimum from
below whatever R is (weak duality of SE-Sync's relaxation: ``F_opt >= F*(R) + n d min(0,
lambda_min(S))``, with ``F*(R) = min_t F(R, t)``); a successful Cholesky of ``S + s I`` proves
``lambda_min(S) > -s``, hence ``F_opt >= F*(R) - n d s``. R is then globally optimal when it is also
a critical point, i.e. when nothing is left to gain locally.

"Nothing left to gain" is measured in units of F, like ``solve``'s own stopping test: the Newton
decrement ``g^T (2 (S + s I))^{-1} g / 2`` (the decrease a Newton step on the rotations would bring,
to second order), and the translations' excess ``F(R, t) - F*(R)``. Both are compared with the
larger of the solver's decrement tolerance (``DECREMENT_RTOL`` of F) and ``ROUNDING_MARGIN`` times
the excess that writing the poses with the estimate's digits causes by itself. At an optimum X*
rounded to its digits, ``X* + delta``, both are about ``delta^T H delta / 2`` (H the Hessian of F);
its expectation over rounding errors uniform within half a quantum of every written number is
estimated from central second differences ``F(X + delta) + F(X - delta) - 2 F(X) = delta^T H delta``
(exact for the translations, F being quadratic in them, and to third order for the rotations), over
``ROUNDING_SAMPLES`` seeded draws. A sum of that many independent terms concentrates at its mean,
so a small margin covers the spread. Where Gershgorin's rigorous ``2 G |delta|^2`` is already below
the solver's tolerance (poses given in memory, files of 17 digits on most graphs), no draw is made.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import NotPositiveDefinite
from ..lie.so import so3_exp
from ..solver.certificate import DualCertificate, lagrange_multipliers, rows_of, verify
from ..solver.problem import Problem
from ..solver.refine import relaxed_gradient
from ..solver.rounding import recover_translations, se_objective
from ..solver.trust_region import CONVERGING_REL_DECREASE

# How converged solve's own estimates are: its trust region stops at a Newton decrement of 1e-11 F,
# or, once an iterate is certified, after a step that lowered F by at most this fraction
# (posecrb.solver.trust_region.CONVERGING_REL_DECREASE), so the decrement left at its estimate is
# below it. An estimate with no more than this left to gain is as converged as solve's.
DECREMENT_RTOL = CONVERGING_REL_DECREASE
# The rounding excess: draws of rounding errors, and the margin over their mean excess.
ROUNDING_SAMPLES = 4
ROUNDING_MARGIN = 4.0
# The smallest shift tried for the lower bound n d s, below the certifying one, as a fraction of
# the certificate's scale (Gershgorin's bound on lambda_max(Q)): a few hundred ulps of it.
TIGHTER_SHIFT = 1e-13


@dataclass(frozen=True)
class Precision:
    """How precisely the estimate was written: the largest quantum (unit of the last written digit)
    of each pose's rotation numbers and of its translation numbers; zeros for poses given as
    float64 arrays, whose own rounding (an ulp) stands for it."""

    rotation_quantum: np.ndarray
    translation_quantum: np.ndarray

    @staticmethod
    def exact(n: int) -> Precision:
        return Precision(np.zeros(n), np.zeros(n))

    def squared_rounding(self, dim: int, trans: np.ndarray) -> float:
        """``|delta|^2`` of the largest rounding errors: half a quantum on each of the d^2 rotation and
        d translation numbers of every pose, at least double precision's rounding of each value."""
        eps = np.finfo(float).eps
        rot = np.maximum(self.rotation_quantum / 2.0, eps)
        tr = np.maximum(self.translation_quantum / 2.0, eps * (1.0 + np.abs(trans).max(axis=1)))
        return float(dim * dim * np.dot(rot, rot) + dim * np.dot(tr, tr))

    def excess(self, problem: Problem, rot: np.ndarray, trans: np.ndarray, objective: float) -> float:
        """The expected increase of F that rounding the poses to these digits causes at an optimum
        (module docstring), from ``ROUNDING_SAMPLES`` central second differences. Rotation errors
        are drawn as rotations about random axes of angle up to one quantum per axis (a quaternion's
        component off by u turns it by about 2u, a matrix entry or an angle by u); every number is at
        least double precision's rounding of its value."""
        eps = np.finfo(float).eps
        n, d = trans.shape
        u_rot = np.maximum(self.rotation_quantum, eps)
        u_tr = np.maximum(self.translation_quantum, eps * (1.0 + np.abs(trans).max(axis=1)))
        rng = np.random.default_rng(0)
        total = 0.0
        for _ in range(ROUNDING_SAMPLES):
            dt = (rng.uniform(-0.5, 0.5, (n, d)) * u_tr[:, None])
            if d == 2:
                w = rng.uniform(-1.0, 1.0, n) * u_rot
                c, s = np.cos(w), np.sin(w)
                turn = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
            else:
                turn = so3_exp(rng.uniform(-1.0, 1.0, (n, 3)) * u_rot[:, None])
            plus = se_objective(problem, rot @ turn, trans + dt)
            minus = se_objective(problem, rot @ np.swapaxes(turn, 1, 2), trans - dt)
            total += max(plus + minus - 2.0 * objective, 0.0) / 2.0
        return total / ROUNDING_SAMPLES


@dataclass(frozen=True)
class Judgement:
    """The certificate at an estimate and what it proves.

    ``objective`` F at the estimate as given; ``objective_optimal_translations`` ``F*(R)``;
    ``translation_excess`` their difference; ``gradient_norm`` the relative norm of the relaxed
    problem's Riemannian gradient (0 at a critical point, at most 1); ``decrement`` the Newton
    decrement (NaN when the certificate failed, which leaves no factor to compute it with);
    ``tolerance`` the excess of F that the solver's tolerance and the estimate's digits allow;
    ``critical`` whether decrement and translation excess are within it; ``certificate`` the dual
    certificate at the tolerance ``certificate_tol``; ``lower_bound`` ``F*(R) - n d s`` for the
    smallest proven shift s (None when no shift was proven); ``certified`` critical and certified:
    the estimate is proven globally optimal, within ``objective - lower_bound``."""

    objective: float
    objective_optimal_translations: float
    translation_excess: float
    gradient_norm: float
    decrement: float
    tolerance: float
    critical: bool
    certificate: DualCertificate
    proven_shift: float | None
    lower_bound: float | None

    @property
    def certified(self) -> bool:
        return self.critical and self.certificate.certified


def judge(problem: Problem, rot: np.ndarray, trans: np.ndarray, precision: Precision, *,
          certificate_tol: float = 1e-3) -> Judgement:
    """The certificate at the estimate (``rot`` (n, d, d), ``trans`` (n, d)) and what it proves."""
    d = problem.d
    nd = problem.n * d
    objective = se_objective(problem, rot, trans)
    best_trans = recover_translations(problem, rot)
    relaxed = se_objective(problem, rot, best_trans)
    excess = max(objective - relaxed, 0.0)
    grad = relaxed_gradient(problem, rot)
    solver_level = DECREMENT_RTOL * max(abs(objective), 1.0)
    rigorous = 2.0 * problem.gershgorin_max() * precision.squared_rounding(d, trans)
    tolerance = solver_level if rigorous <= solver_level else \
        max(solver_level, ROUNDING_MARGIN * precision.excess(problem, rot, trans, objective))
    cert = _certificate(problem, rot, certificate_tol)
    decrement = math.nan
    shift = cert.certificate.proven_shift
    if cert.certified and shift is not None and cert.certificate.proven_factor is not None:
        # The Newton decrement with (S + s I)^{-1}: the inverse Hessian of the relaxed problem up to
        # the shift, on the tangent directions the gradient lies in (S Z = Q Z - Lambda Z = g / 2).
        factor = cert.certificate.proven_factor[0]
        g = rows_of(grad.gradient).reshape(nd, d)
        decrement = 0.25 * float(np.sum(g * problem.schur_solve(factor, g)))
        if shift > TIGHTER_SHIFT * problem.gershgorin_max():
            shift = _smallest_proven_shift(problem, cert, shift)
    critical = (decrement <= tolerance) and excess <= tolerance
    lower = None if shift is None else relaxed - nd * shift
    return Judgement(objective, relaxed, excess, grad.relative_norm, decrement, tolerance, bool(critical), cert,
                     shift, lower)


def _certificate(problem: Problem, rot: np.ndarray, tol: float) -> DualCertificate:
    """``solve``'s certificate test at ``rot``, tried first at the smallest shift ``TIGHTER_SHIFT``:
    at an optimum (``lambda_min(S)`` zero to rounding) that one Cholesky both decides the test and
    proves the tight bound; elsewhere the test runs at ``tol`` as ``solve``'s does."""
    lam = lagrange_multipliers(problem, rot)
    small = TIGHTER_SHIFT * problem.gershgorin_max()
    first = None
    if small <= tol:
        try:
            first = (problem.factor_full(lam, small, name="certificate matrix Q - Lambda + s I"), small)
        except NotPositiveDefinite:
            first = None
    return DualCertificate(lam, verify(problem, lam, tol, np.random.default_rng(0), factor=first), float(tol))


def _smallest_proven_shift(problem: Problem, cert: DualCertificate, shift: float) -> float:
    """A shift below ``shift`` at which ``Q - Lambda + s I`` still factors, for a tighter bound
    ``n d s``: one Cholesky at twice the magnitude of Lanczos' estimate of lambda_min (at least
    ``TIGHTER_SHIFT`` of the certificate's scale); ``shift`` itself where it fails or is no larger."""
    s = max(2.0 * max(-cert.lambda_min, 0.0), TIGHTER_SHIFT * problem.gershgorin_max())
    if s >= shift:
        return shift
    try:
        problem.factor_full(cert.lam, s, name="certificate matrix Q - Lambda + s I")
    except NotPositiveDefinite:
        return shift
    return s


__all__ = ["DECREMENT_RTOL", "ROUNDING_MARGIN", "ROUNDING_SAMPLES", "Judgement", "Precision", "judge"]
