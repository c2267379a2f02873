"""The preconditioners of the trust region's truncated CG, one class each (docs/design.md#solver).

Each has a ``name`` (its key in ``SolveResult.preconditioner_solves``), ``prepare(state)`` (its
factor at a point; False where that factorization does not exist) and ``apply(state, R)`` (the
preconditioned residual, on the tangent space up to the vertical directions, which the policy
removes), and counts its applications. Which one applies when is decided by
posecrb.solver.policy alone.

* "schur" / "rotation" (:class:`BasePreconditioner`): SE-Sync's regularised ``(Q + delta I)^{-1}``
  through a factor of ``M_red(delta)``, or the rotation block's ``(C + delta I)^{-1}``.
* "adaptive" (:class:`AdaptivePreconditioner`): ``(Q - Lambda + s I)^{-1}`` through ``M_red``
  refactored at an iterate (or the certificate's factor kept past a saddle).
* "tangent" (:class:`TangentPreconditioner`): the tangent space's exact inverse Hessian at the
  first level (posecrb.solver.tangent).
* "split" (:class:`SplitPreconditioner`): after an escape, K on the first level's directions and
  ``M_red``'s factor on the new column's.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..core.errors import NotPositiveDefinite
from ..linalg.cholesky import Factor
from ..linalg.ordering import threaded_matrix
from .options import check_base_kind
from .problem import Problem, RotationBlockFactor
from .relaxed import State
from .stiefel import project
from .tangent import TangentSystem

log = logging.getLogger("posecrb")

# A point's blocks may lean towards the new column's direction w by at most 60 degrees for the
# split preconditioner: max_i |Z_i w|^2 <= sin^2(60 deg). Past that the padded point's inverse
# Hessian is no model of the Hessian (docs/decisions/solver-preconditioners.md).
SPLIT_MAX_LEAN = 0.75


class PreconditionerOperator(Protocol):
    """What the policy asks of each preconditioner."""

    name: str
    applications: int

    def prepare(self, state: State) -> bool: ...

    def apply(self, state: State, R: np.ndarray) -> np.ndarray: ...


def base_preconditioner_kind(requested: str, dim: int, poses: int) -> str:
    """The base factor ``requested`` (``BASE_PRECONDITIONERS``) stands for on a graph of ``poses``
    poses in dimension ``dim``: ``auto`` is "rotation" on the 3D graphs whose factorizations are
    threaded (``posecrb.linalg.ordering.threaded_matrix``), where its factor takes (3/4)^3 of
    M_red's flops, and "schur" elsewhere, where factorizations are cheap and the products decide
    (docs/decisions/solver-preconditioners.md)."""
    check_base_kind(requested)
    if requested != "auto":
        return requested
    return "rotation" if dim == 3 and threaded_matrix(dim, poses, "solver") else "schur"


def _factor_apply(problem: Problem, factor: Factor | RotationBlockFactor, state: State, R: np.ndarray) -> np.ndarray:
    """``Proj (F^{-1} R) / 2`` for an M_red-type factor F (``(Q - Lambda + s I)`` through M_red, or
    the rotation block's ``(C + s I)``): the Hessian is ``2 Proj S``."""
    n, d, r = R.shape
    W = _solve(problem, factor, R.reshape(n * d, r)).reshape(n, d, r)
    return project(state.Z, W, state.Zt, scale=0.5)


def _solve(problem: Problem, factor: Factor | RotationBlockFactor, W: np.ndarray) -> np.ndarray:
    """``(Q - Lambda + s I)^{-1} W`` through a factor of M_red, or ``(C + s I)^{-1} W`` through the
    rotation block's, for W (dn, k)."""
    if isinstance(factor, RotationBlockFactor):
        return factor.solve(W)
    return problem.schur_solve(factor, W)


class BasePreconditioner:
    """The regularised base factor, built on first use: "schur", ``(Q + delta I)^{-1}`` through a
    factor of ``M_red(delta)`` (SE-Sync's regularised Cholesky, section 4.3); "rotation",
    ``(C + delta I)^{-1}`` through a factor of the rotation block alone."""

    def __init__(self, problem: Problem, delta: float, kind: str) -> None:
        self.problem, self.delta, self.name = problem, delta, kind
        self.factor: Factor | RotationBlockFactor | None = None
        self.applications = 0

    def prepare(self, state: State | None = None) -> bool:
        self.built()
        return True

    def built(self) -> Factor | RotationBlockFactor:
        """The factor, built on the first call."""
        if self.factor is None:
            if self.name == "rotation":
                log.debug("base preconditioner: the rotation block's (C + %.3e I)^-1", self.delta)
                self.factor = self.problem.factor_rotation_block(self.delta, name="preconditioner C + delta I")
            else:
                self.factor = self.problem.factor_full(None, self.delta, name="preconditioner M_red(delta)")
        return self.factor

    def solve(self, W: np.ndarray) -> np.ndarray:
        return _solve(self.problem, self.built(), W)

    def apply(self, state: State, R: np.ndarray) -> np.ndarray:
        self.applications += 1
        return _factor_apply(self.problem, self.built(), state, R)


class AdaptivePreconditioner:
    """``(Q - Lambda + s I)^{-1}`` through a factor of ``M_red(Lambda, s)`` at one point.

    Near a minimiser the Riemannian Hessian is ``2 Proj S`` with ``S = Q - Lambda``, so this is
    close to an exact Newton preconditioner. ``point`` is where it was last factored (or tried);
    ``factor_shift`` the shift of a factor of that point's own ``M_red(Lambda, s)`` (None for the
    certificate's factor at a saddle, :meth:`adopt`, which is never a certificate here)."""

    name = "adaptive"

    def __init__(self, problem: Problem, shift: float) -> None:
        self.problem, self.shift = problem, shift
        self.point: np.ndarray | None = None
        self.factor: Factor | None = None
        self.factor_shift: float | None = None
        self.applications = 0
        self.factorizations = 0

    def prepare(self, state: State, shifts: tuple[float, ...] | None = None) -> bool:
        """Factor at ``state``'s point at the first of ``shifts`` (default: s) where
        ``M_red(Lambda, shift)`` is positive definite; False where none is."""
        self.point, self.factor, self.factor_shift = state.Z, None, None
        for shift in (self.shift,) if shifts is None else shifts:
            self.factorizations += 1
            try:
                self.factor = self.problem.factor_full(state.lam, shift, name="preconditioner M_red(Lambda, s)")
            except NotPositiveDefinite:
                continue
            self.factor_shift = shift
            log.debug("preconditioner: (Q - Lambda + %.3e I)^-1", shift)
            return True
        return False

    def adopt(self, state: State, factor: Factor, sigma: float) -> None:
        """Take ``factor`` of ``Q - Lambda + sigma I`` at a saddle for ``state``'s point."""
        self.point, self.factor, self.factor_shift = state.Z, factor, None
        log.debug("preconditioner: the saddle's (Q - Lambda + %.3e I)^-1", sigma)

    def forget(self) -> None:
        """Refactor at the next prepared point, whichever."""
        self.point = None

    def tried_at(self, state: State) -> bool:
        return self.point is state.Z

    def certificate_factor(self, state: State, tol: float) -> tuple[Factor, float] | None:
        """(factor, s) when this preconditioner was factored at ``state``'s point as
        ``M_red(Lambda, s)`` with ``0 <= s <= tol``: that successful Cholesky proves
        ``lambda_min(Q - Lambda) > -s >= -tol``, the certificate test of
        posecrb.solver.certificate.verify (the same matrix, a smaller or equal shift). Else None."""
        s = self.factor_shift
        if self.point is state.Z and self.factor is not None and s is not None and 0.0 <= s <= tol:
            return self.factor, s
        return None

    def solve(self, W: np.ndarray) -> np.ndarray:
        assert self.factor is not None
        return self.problem.schur_solve(self.factor, W)

    def apply(self, state: State, R: np.ndarray) -> np.ndarray:
        assert self.factor is not None
        self.applications += 1
        return _factor_apply(self.problem, self.factor, state, R)


class TangentPreconditioner:
    """The tangent space's exact inverse Hessian at the first level, ``E (2 E^T (S + s I) E)^{-1} E^T``
    through a factor of K (posecrb.solver.tangent), whose system is built on first use.

    Where ``S + s I`` is not positive definite on the tangent space (away from a minimiser) K is
    factored without Lambda at the base shift delta, i.e. ``(Q + delta I)`` restricted to the
    tangent space (``exact`` False)."""

    name = "tangent"

    def __init__(self, problem: Problem, shift: float, fallback_shift: float,
                 system: TangentSystem | None = None) -> None:
        self.problem, self.shift, self.fallback_shift, self.system = problem, shift, fallback_shift, system
        self.point: np.ndarray | None = None
        self.factor: Factor | None = None
        self.exact = False          # the factor is K with Lambda, not the Lambda-free fallback
        self.applications = 0
        self.factorizations = 0

    def build(self) -> TangentSystem:
        if self.system is None:
            self.system = TangentSystem.build(self.problem)
        return self.system

    def prepare(self, state: State) -> bool:
        """Factor K at ``state``'s point: with Lambda at s, else without at delta; False where both fail."""
        system = self.build()
        attempts = ((state.lam, self.shift, "(S + s I)"), (None, self.fallback_shift, "(Q + delta I)"))
        for lam, shift, label in attempts:
            self.factorizations += 1
            try:
                factor = system.factor(state.Z, lam, shift, name="tangent preconditioner K")
            except NotPositiveDefinite:
                continue
            self.point, self.factor, self.exact = state.Z, factor, lam is not None
            log.debug("preconditioner: the tangent space's inverse of %s", label)
            return True
        self.point = self.factor = None
        return False

    def carry_to(self, state: State) -> None:
        """Keep the last point's factor for ``state``'s point (E is rebuilt at the new point, so the
        preconditioner stays on its tangent space)."""
        self.point = state.Z

    def at(self, state: State) -> bool:
        return self.factor is not None and self.point is state.Z

    def exact_at(self, state: State) -> bool:
        """Whether the preconditioner at ``state`` is the inverse Hessian on the tangent space."""
        return self.at(state) and self.exact

    def apply(self, state: State, R: np.ndarray) -> np.ndarray:
        assert self.system is not None and self.factor is not None
        self.applications += 1
        # E maps into the tangent space: no projection needed
        return self.system.apply(self.factor, state.Z, R)


@dataclass(frozen=True)
class _SplitParts:
    normal: np.ndarray        # (n, r, 1) the new column's direction w projected off each block's rows
    gauge: np.ndarray         # (n k, k) K's near-null coordinates (TangentSystem.gauge_modes)
    gauge_scale: float        # the Hessian's scale put on them (TangentSystem.diagonal_mean)


class SplitPreconditioner:
    """After the escape from the first level: K's factor on the in-plane directions and an M_red-type
    factor on the new column's.

    The point is ``[Z1 | 0]`` plus a small new column. At ``[Z1 | 0]`` exactly, every tangent vector
    is ``Omega_i Z_i + b_i w^T`` (w the new column's unit vector), the two kinds are orthogonal and
    the Hessian does not couple them: on the first it is the first level's, whose inverse the last
    factor of K is; on the second it is ``2 (Q - Lambda)`` acting on b. So ``P = E (2 K_schur)^{-1}
    E^T + N (2 (Q - Lambda + sigma I))^{-1} N^T`` is the inverse Hessian there and stays close to it
    while the new column is small (docs/design.md#solver). w is the Gram matrix's eigenvector of the
    smallest eigenvalue, projected off each block's rows (N).
    """

    name = "split"

    def __init__(self, problem: Problem, tangent: TangentPreconditioner) -> None:
        self.problem, self.tangent = problem, tangent
        self.applications = 0
        self._parts: tuple[np.ndarray, _SplitParts | None] | None = None   # cached per point
        self._gauge: tuple[Factor, np.ndarray] | None = None               # (K's factor, its gauge modes)
        self._column: BasePreconditioner | AdaptivePreconditioner | None = None

    def possible(self, state: State) -> bool:
        """Whether ``state`` is at width d + 1 with the first level's factor of K with Lambda at hand."""
        return (state.Z.shape[2] == self.problem.d + 1 and self.tangent.factor is not None
                and self.tangent.exact)

    def frame(self, state: State) -> tuple[np.ndarray, np.ndarray] | None:
        """(w, Z w) at ``state``, or None where the split does not apply (:meth:`possible`, or a
        block leaning more than ``SPLIT_MAX_LEAN`` towards w)."""
        if not self.possible(state):
            return None
        w = state.gram[1][:, :1]                    # (r, 1): the new column's direction
        Zw = state.Z @ w                            # (n, d, 1)
        if float(np.max(np.einsum("nds,nds->n", Zw, Zw))) > SPLIT_MAX_LEAN:
            return None
        return w, Zw

    def prepare(self, state: State, column: BasePreconditioner | AdaptivePreconditioner | None = None) -> bool:
        """Whether the split applies at ``state`` (its data cached per point), with ``column``'s
        factor for the new column."""
        self._column = column
        if self._parts is None or self._parts[0] is not state.Z:
            self._parts = (state.Z, self._compute_parts(state))
        return self._parts[1] is not None

    def _compute_parts(self, state: State) -> _SplitParts | None:
        frame = self.frame(state)
        system, factor = self.tangent.system, self.tangent.factor
        if frame is None or system is None or factor is None or self.tangent.point is None:
            return None
        w, Zw = frame
        scale = system.diagonal_mean(state.Z, state.lam)
        if scale <= 0:
            return None
        # K's gauge modes depend on its factor only, which the level after the escape keeps
        if self._gauge is None or self._gauge[0] is not factor:
            self._gauge = (factor, system.gauge_modes(self.tangent.point[:, :, :self.problem.d]))
        return _SplitParts(normal=w[None] - np.einsum("ndr,nds->nrs", state.Z, Zw), gauge=self._gauge[1],
                           gauge_scale=scale)

    def apply(self, state: State, R: np.ndarray) -> np.ndarray:
        """``P R``: the in-plane part through K's factor, the new column's through the column
        factor with one right-hand side."""
        parts = self._parts[1] if self._parts is not None and self._parts[0] is state.Z else None
        system, factor, column = self.tangent.system, self.tangent.factor, self._column
        assert parts is not None and system is not None and factor is not None and column is not None
        self.applications += 1
        n, d, _ = state.Z.shape
        inplane = system.apply(factor, state.Z, R, gauge=(parts.gauge, parts.gauge_scale))
        b = np.einsum("ndr,nr->nd", R, parts.normal[:, :, 0])
        x = column.solve(b.reshape(n * d, 1)).reshape(n, d)
        return inplane + 0.5 * x[:, :, None] * parts.normal[:, None, :, 0]
