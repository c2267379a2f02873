"""The rank-d relaxation at given rotations: its Riemannian gradient, and a local refinement from them.

For estimates computed by another program. At rank d the relaxation ``min tr(Q R^T R)`` over
``St(d, d)^n`` is the maximum-likelihood problem with the translations eliminated
(SE-Sync, Rosen et al. IJRR 2019, section 4): its critical points are the critical points of
``F*(R) = min_t F(R, t)`` on ``SO(d)^n``, and its value is ``F*``. :func:`relaxed_gradient` says how
far given rotations are from one; :func:`refine` moves them to one with ``solve``'s trust region
and preconditioners at that rank, without climbing the staircase; the certificate of the
result is posecrb.solver.certificate.dual_certificate.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .certificate import rows_of
from .options import Preconditioner, PreconditionerSettings
from .policy import build_policy
from .problem import Problem
from .relaxed import RelaxedProblem, State
from .rounding import recover_translations
from .stiefel import inner
from .trust_region import TROptions, trust_region


@dataclass(frozen=True)
class RelaxedGradient:
    """The Riemannian gradient of the rank-d relaxation at rotations R (n, d, d).

    ``gradient`` is in the rotations' layout (block i: the derivative with respect to R_i,
    ``2 (Q Z - Lambda Z)_i^T`` with ``Z_i = R_i^T``); ``norm`` its Frobenius norm;
    ``relative_norm`` that norm over the Euclidean gradient's ``||2 Q Z||_F``, of which the
    Riemannian gradient is the tangent part: 0 at a critical point, at most 1, and unchanged when
    every information matrix is scaled (0 where the Euclidean gradient is 0, i.e. F = 0).
    """

    gradient: np.ndarray
    norm: float
    relative_norm: float


def _gradient_of(state: State) -> RelaxedGradient:
    norm = math.sqrt(inner(state.grad, state.grad))
    euclidean = 2.0 * math.sqrt(inner(state.QZ, state.QZ))
    relative = norm / euclidean if euclidean > 0.0 else 0.0
    return RelaxedGradient(np.ascontiguousarray(np.swapaxes(state.grad, 1, 2)), norm, relative)


def relaxed_gradient(problem: Problem, rot: np.ndarray) -> RelaxedGradient:
    """The Riemannian gradient of ``tr(Q R^T R)`` on ``St(d, d)^n`` at rotations ``rot`` (n, d, d)."""
    return _gradient_of(RelaxedProblem(problem).evaluate(rows_of(rot)))


@dataclass(frozen=True)
class Refinement:
    """Where :func:`refine` ended: rotations (n, d, d) and their optimal translations (n, d),
    pose 0 at the origin; ``objective`` ``F*(R)``, SE-Sync's objective with those translations;
    the gradient there; the trust region's iterations, Hessian-vector products, why it stopped
    (``status``) and the preconditioners' applications."""

    rot: np.ndarray
    trans: np.ndarray
    objective: float
    gradient: RelaxedGradient
    iterations: int
    hessian_vector_products: int
    status: str
    preconditioner_solves: dict[str, int] = field(default_factory=dict)


def refine(problem: Problem, rot: np.ndarray, *, max_iterations: int = 500, preconditioner: Preconditioner = "auto",
           settings: PreconditionerSettings | None = None,
           trust_region_options: Mapping[str, Any] | None = None) -> Refinement:
    """Minimise the rank-d relaxation from rotations ``rot`` (n, d, d) to a critical point.

    The Riemannian trust region of ``solve``'s first staircase level, with the same
    preconditioners (``preconditioner``, ``settings``: as in SolverOptions) and stopping tests
    (``trust_region_options``: other TROptions fields), but no certificate and no escape: where
    the end point is a saddle it stays there (dual_certificate tells). Steps along the tangent
    space of ``St(d, d)^n`` keep each block's determinant, so rotations stay rotations.
    """
    opts = TROptions(max_iterations=max_iterations, **dict(trust_region_options or {}))
    policy = build_policy(problem, preconditioner, settings or PreconditionerSettings(), certificate_tol=None)
    res = trust_region(RelaxedProblem(problem), rows_of(rot), opts, preconditioner=policy)
    end = np.ascontiguousarray(np.swapaxes(res.state.Z, 1, 2))
    return Refinement(end, recover_translations(problem, end), float(res.state.f), _gradient_of(res.state),
                      res.iterations, res.hvps, res.status, policy.solves())
