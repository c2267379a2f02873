"""Riemannian staircase: local optimisation at rank r, certification, negative-curvature escape.

SE-Sync (Rosen et al., IJRR 2019), Algorithm 1 and section 4.2-4.3:
at a first-order critical point Y of the rank-r relaxation, ``Lambda = SymBlockDiag(Q Y^T Y)``
and ``S = Q - Lambda``. If ``S >= 0`` (within tolerance) Y solves the SDP relaxation
globally; otherwise an eigenvector v of S with ``v^T S v < 0`` gives a second-order
descent direction ``[0 | v]`` in a new column. ``solve`` starts from rotations padded with zero
columns, which stay zero, and computes on the nonzero columns only (its "width"): an escape from
width w goes to width w + 1, which is the staircase's rank r + 1 once the padding is used up.

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
"""
from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np

from ..core.errors import InternalError, NotPositiveDefinite, SolverError
from ..linalg.cholesky import Factor
from ..linalg.lanczos import largest_eigenpair
from .problem import Problem, RotationBlockFactor
from .stiefel import (
    gram_eigh,
    hessian_blocks,
    lift,
    project,
    remove_vertical,
    retract,
    sym_block_diag_product,
    to_components,
)
from .tangent import TangentSystem
from .trust_region import State

log = logging.getLogger("posecrb")

# A base preconditioner factor: M_red(delta)'s (its rotation block of the inverse is (Q + delta I)^{-1})
# or the rotation block's own (C + delta I), posecrb.solver.problem.RotationBlockFactor.
BaseFactor: TypeAlias = "Factor | RotationBlockFactor"


# The preconditioners truncated CG can apply, as the solve's result names them: the base factor
# ("schur", SE-Sync's (Q + delta I)^{-1} through M_red(delta), or "rotation", the rotation block's
# (C + delta I)^{-1}), "adaptive" ((Q - Lambda + s I)^{-1} through M_red refactored at an iterate,
# or the certificate's factor kept past a saddle), "tangent" (the tangent space's K,
# posecrb.solver.tangent) and "split" (after an escape: K on the first d columns, M_red's factor on
# the new one).
PRECONDITIONERS = ("schur", "rotation", "adaptive", "tangent", "split")


# The tangent preconditioner's factor is kept for the next iterate while truncated CG needs at most
# this many products with it. Against refactoring at every iterate (0) it trades products for
# factorizations: fewer seconds on city10000 (0.50 -> 0.35 s), more on ais2klinik (0.36 -> 0.46 s,
# 10 -> 41 products), the sum over five 2D files 0.94x, within this machine's noise; the 2D grid of
# 30,276 poses 10.45 -> 9.03 s (benchmarks/solve_checkouts.py, docs/performance.md).
TANGENT_REFACTOR_HVPS = 3


class RelaxedModel:
    """f(Z) = tr(Z^T Q Z) on St(d, r)^n with gradient, Hessian and a Schur-complement preconditioner."""

    def __init__(self, problem: Problem, precond_factor: BaseFactor | None = None, adaptive_shift: float | None = None,
                 refactor_hvps: int | None = 30, tangent: TangentSystem | None = None,
                 tangent_fallback_shift: float = 0.0, base_factory: Callable[[], BaseFactor] | None = None,
                 tangent_factory: Callable[[], TangentSystem] | None = None,
                 tangent_switch_hvps: int | None = None, split_escape: bool = True) -> None:
        self.problem = problem
        # How many times each preconditioner (``PRECONDITIONERS``) has been applied: what the
        # result reports.
        self.preconditioned: Counter[str] = Counter()
        # Builds ``tangent`` at the first level once a truncated-CG run needed more than
        # ``tangent_switch_hvps`` products (where the tangent system's factorizations cost more than
        # the products they save unless there are many).
        self._tangent_factory = tangent_factory
        self.tangent_switch_hvps = tangent_switch_hvps
        # Builds the base factor on first use when ``precond_factor`` is None: with the tangent
        # preconditioner a graph certified at the first level never needs it.
        self._base_factory = base_factory
        # At width d (the first staircase level): the tangent space's exact inverse Hessian
        # (posecrb.solver.tangent), refactored at every accepted iterate; None: not used.
        self.tangent = tangent
        self.tangent_fallback_shift = tangent_fallback_shift
        self._tangent_factor: tuple[np.ndarray, Factor] | None = None   # (Z it applies at, factor)
        self._tangent_exact = False     # that factor is K with Lambda (not the Lambda-free fallback)
        self.base_factor = precond_factor
        self.precond_factor = precond_factor
        self.adaptive_shift = adaptive_shift
        self.refactor_hvps = refactor_hvps
        self.lambda_hint = 0.0      # lambda_min(Q - Lambda) at the last saddle (<= 0), set by the staircase
        # The certificate's factor of Q - Lambda + sigma I at the saddle just left (set by the
        # staircase), reused after the escape where the split preconditioner applies.
        self.saddle_factor: tuple[Factor, float] | None = None
        self._saddle_factor_in_use = False
        self.refactor_next = False  # refactor at the next prepare() whatever the HVP count (after an escape)
        self.hvps = 0
        # At width d + 1 after an escape from the first level: the split preconditioner
        # (``_split_parts``), cached per point.
        self.split_escape = split_escape
        self._split: tuple[np.ndarray, _SplitParts | None] | None = None
        self._gauge: tuple[Factor, np.ndarray] | None = None   # (K's factor, its gauge modes)
        self.factorizations = 0
        self._factored_at: np.ndarray | None = None     # Z of the iterate the adaptive factor was built at
        self.factor_shift: float | None = None          # its shift s (None: not a factor at that point's Lambda)
        self.certificate_tol: float | None = None       # eta, when the trust region may stop once certified
        self._gram: tuple[np.ndarray, tuple[np.ndarray, np.ndarray]] | None = None   # (Z, gram_eigh(Z))
        self._comp: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None   # (Z, Z, Lambda) component-major

    def _components(self, state: State) -> tuple[np.ndarray, np.ndarray]:
        """Z and Lambda of ``state`` in the component-major layout of the block kernels, cached
        per point (tCG applies the Hessian and projection many times at one point)."""
        if self._comp is None or self._comp[0] is not state.Z:
            self._comp = (state.Z, to_components(state.Z), to_components(state.lam))
        return self._comp[1], self._comp[2]

    def project(self, state: State, W: np.ndarray) -> np.ndarray:
        """Tangent projection at ``state``'s point (stiefel.project with the cached layout)."""
        return project(state.Z, W, self._components(state)[0])

    def prepare(self, state: State, last_hvps: int | None = None, converging: bool = False) -> None:
        """Refactor the preconditioner as (Q - Lambda(Y) + s I)^{-1} at the iterate, when it pays.

        Near a minimiser the Riemannian Hessian is 2 Proj S with S = Q - Lambda, so this
        is close to an exact Newton preconditioner. Refactoring costs one sparse Cholesky,
        which on most problems is worth more than the Hessian-vector products it saves, so
        with ``refactor_hvps`` set the current factor (first the Lambda-free (Q + delta I)^{-1},
        SE-Sync's choice) is kept until a truncated-CG run needs more than ``refactor_hvps``
        products (``last_hvps``); ``refactor_hvps=None`` refactors at every accepted iterate.

        Where S + s I is not positive definite (away from a minimiser, typically right after a
        staircase escape) the shift grows past the negative curvature: first to
        ``s + 2 |lambda_hint|`` (the certificate's lambda_min at the saddle just left), then tenfold;
        after an escape (``refactor_next``) the factor is rebuilt at once, since the Lambda-free one
        is poor there;
        the Lambda-free factor is the last resort, because it ignores Lambda, the dominant
        diagonal part of the Hessian, and makes truncated CG take hundreds of steps.

        After an escape the shift s alone is tried only at a ``converging`` iterate (the trust
        region's last step decreased f by at most its ``certified_rel_decrease``): only there can
        that factorization also certify the point, and before it the point is mostly still
        indefinite, so the attempt fails at the full cost of a factorization (2D grid of 100,489
        poses: one failed attempt of 1.5-2 s fewer; of 30,276 poses: 210 -> 181 HVPs; the same optima,
        benchmarks/solve_checkouts.py, docs/performance.md).
        """
        if self.adaptive_shift is None or (self.base_factor is None and self._base_factory is None):
            return
        at_first_level = state.Z.shape[2] == self.problem.d
        if (self.tangent is None and self._tangent_factory is not None and at_first_level
                and last_hvps is not None and self.tangent_switch_hvps is not None
                and last_hvps > self.tangent_switch_hvps):
            log.debug("preconditioner: %d products in the last truncated CG, switching to the tangent space's",
                      last_hvps)
            self.tangent, self._tangent_factory = self._tangent_factory(), None
        if self.tangent is not None and at_first_level:
            self._prepare_tangent(state, last_hvps)
            return
        if self._saddle_factor_in_use and self._split_frame(state, self._gram_of(state)) is None:
            # The split preconditioner no longer applies, and the saddle's factor is a poor
            # (Q - Lambda + s I)^{-1} for M_red's preconditioner here: refactor past the saddle.
            self._saddle_factor_in_use = False
            self.refactor_next = True
            self._factored_at = None
        if self._factored_at is state.Z:
            return
        if (self.refactor_hvps is not None and not self.refactor_next
                and (last_hvps is None or last_hvps <= self.refactor_hvps)):
            return
        s = self.adaptive_shift
        if self.refactor_next and self.saddle_factor is not None:
            fac, sigma = self.saddle_factor
            self.saddle_factor = None
            if self._split_possible(state) and sigma <= s + 20.0 * abs(self.lambda_hint):
                # The split preconditioner inverts Q - Lambda only on the new column's directions,
                # where the saddle's factor (its shift sigma > |lambda_min| past the negative
                # curvature) serves as well as a new one: one factorization fewer (docs/performance.md).
                self.refactor_next = False
                self._factored_at = state.Z
                self.factor_shift = None    # a factor at the saddle, not at this point: never a certificate
                self.precond_factor = fac
                self._saddle_factor_in_use = True
                log.debug("preconditioner: the saddle's (Q - Lambda + %.3e I)^-1", sigma)
                return
        shifts = [s]
        if self.lambda_hint < 0:
            # Right after an escape the iterate is still next to the saddle, where S + s I is
            # indefinite: a factorization at s alone would fail (at full cost), so start past it.
            past_saddle = [s + 2.0 * abs(self.lambda_hint), s + 20.0 * abs(self.lambda_hint)]
            shifts = ([s] if converging and not self.refactor_next else []) + past_saddle
        self.refactor_next = False
        self._saddle_factor_in_use = False
        self._factored_at = state.Z
        self.factor_shift = None
        for shift in shifts:
            self.factorizations += 1
            try:
                self.precond_factor = self.problem.factor_full(state.lam, shift,
                                                               name="preconditioner M_red(Lambda, s)")
            except NotPositiveDefinite:
                continue
            self.factor_shift = shift
            log.debug("preconditioner: (Q - Lambda + %.3e I)^-1", shift)
            return
        self.precond_factor = self._base()
        log.debug("preconditioner: Q - Lambda + s I not PD, using (Q + delta I)^-1")

    def _prepare_tangent(self, state: State, last_hvps: int | None = None) -> None:
        """Factor K (posecrb.solver.tangent) at ``state``'s point, once per point: at the adaptive
        shift s, and where S + s I is not positive definite on the tangent space (away from a
        minimiser) without Lambda at the base preconditioner's shift delta, which is (Q + delta I)
        restricted to the tangent space; where even that fails the base factor preconditions."""
        if self._tangent_factor is not None and self._tangent_factor[0] is state.Z:
            return
        if (self._tangent_factor is not None and last_hvps is not None
                and last_hvps <= TANGENT_REFACTOR_HVPS):
            # The factor of the last point still inverts the Hessian nearly: keep it (E is
            # rebuilt at the new point, so the preconditioner stays on its tangent space).
            self._tangent_factor = (state.Z, self._tangent_factor[1])
            return
        if self.tangent is None or self.adaptive_shift is None:
            raise InternalError("tangent preconditioner not set up")
        attempts = ((state.lam, self.adaptive_shift, "(S + s I)"), (None, self.tangent_fallback_shift, "(Q + delta I)"))
        for lam, shift, label in attempts:
            self.factorizations += 1
            try:
                factor = self.tangent.factor(state.Z, lam, shift, name="tangent preconditioner K")
            except NotPositiveDefinite:
                continue
            self._tangent_factor = (state.Z, factor)
            self._tangent_exact = lam is not None
            log.debug("preconditioner: the tangent space's inverse of %s", label)
            return
        self._tangent_factor = None
        self.precond_factor = self._base()
        log.debug("preconditioner: K not positive definite, using (Q + delta I)^-1")

    def exact_preconditioner(self, state: State) -> bool:
        """Whether the preconditioner at ``state`` is the inverse Hessian on the tangent space: K with
        Lambda, factored at this point or kept from the last one because truncated CG needed at most
        ``TANGENT_REFACTOR_HVPS`` products with it (trust_region's ``exact_decrement_tol``)."""
        return self._tangent_factor is not None and self._tangent_factor[0] is state.Z and self._tangent_exact

    def _base(self) -> BaseFactor | None:
        """The base factor ((Q + delta I)^{-1} through M_red, or the rotation block's (C + delta I)^{-1}),
        built by ``base_factory`` on first use."""
        if self.base_factor is None and self._base_factory is not None:
            self.base_factor = self._base_factory()
            self._base_factory = None
        return self.base_factor

    def certificate_factor(self, state: State, tol: float) -> tuple[Factor, float] | None:
        """(factor, s) when the preconditioner was factored at ``state``'s point as
        M_red(Lambda, s) with 0 <= s <= ``tol``: that successful Cholesky already proves
        ``Q - Lambda + s I > 0``, i.e. lambda_min(Q - Lambda) > -s >= -tol, the certificate
        test of :func:`verify` (the same matrix, a smaller or equal shift). Else None."""
        factor = self.precond_factor
        if (self._factored_at is state.Z and self.factor_shift is not None and factor is not None
                and not isinstance(factor, RotationBlockFactor) and 0.0 <= self.factor_shift <= tol):
            return factor, self.factor_shift
        return None

    def certified(self, state: State) -> bool:
        """Whether ``state`` is already certified by the preconditioner's factorization
        (``certificate_tol`` set by the staircase; see :meth:`certificate_factor`)."""
        return self.certificate_tol is not None and self.certificate_factor(state, self.certificate_tol) is not None

    def evaluate(self, Z: np.ndarray) -> State:
        p = self.problem
        n, d, r = Z.shape
        Zf = Z.reshape(n * d, r)
        QZf, trans = p.Q_product_and_translations(Zf)
        f = p.objective_from_translations(Zf, trans)
        QZ = QZf.reshape(n, d, r)
        lam = sym_block_diag_product(QZ, Z)
        grad = 2.0 * (QZ - lam @ Z)
        return State(Z, f, QZ, lam, grad)

    def hvp(self, state: State, V: np.ndarray) -> np.ndarray:
        """Riemannian Hessian: 2 Proj_Z(Q V - Lambda V) (SE-Sync eq. 46 in this layout)."""
        self.hvps += 1
        n, d, r = V.shape
        QV = self.problem.Q_product(V.reshape(n * d, r)).reshape(n, d, r)
        Zt, lamt = self._components(state)
        return hessian_blocks(Zt, lamt, V, QV)

    def precondition(self, state: State, R: np.ndarray) -> np.ndarray:
        tangent_factor = (self._tangent_factor[1] if self._tangent_factor is not None
                          and self._tangent_factor[0] is state.Z else None)
        if self.precond_factor is None and tangent_factor is None:
            return R
        n, d, r = R.shape
        gram = self._gram_of(state)
        R = remove_vertical(state.Z, R, gram)
        if tangent_factor is not None and self.tangent is not None:
            self.preconditioned["tangent"] += 1
            # E maps into the tangent space: no projection needed, only the gauge removed
            return remove_vertical(state.Z, self.tangent.apply(tangent_factor, state.Z, R), gram)
        if self.precond_factor is None:
            raise InternalError("preconditioner factor missing")
        parts = self._split_parts(state, gram)
        if parts is not None:
            self.preconditioned["split"] += 1
            return remove_vertical(state.Z, self._split_apply(state, R, parts), gram)
        factor = self.precond_factor
        self.preconditioned["adaptive" if factor is not self.base_factor
                            else "rotation" if isinstance(factor, RotationBlockFactor) else "schur"] += 1
        W = self._precond_solve(R.reshape(n * d, r)).reshape(n, d, r)
        return remove_vertical(state.Z, project(state.Z, W, self._components(state)[0], scale=0.5), gram)

    def _precond_solve(self, W: np.ndarray) -> np.ndarray:
        """The preconditioner factor applied to W (dn, k): ``(Q - Lambda + s I)^{-1} W`` through a
        factor of M_red, or ``(C + s I)^{-1} W`` through the rotation block's base factor."""
        factor = self.precond_factor
        if isinstance(factor, RotationBlockFactor):
            return factor.solve(W)
        return self.problem.schur_solve(factor, W)

    def _gram_of(self, state: State) -> tuple[np.ndarray, np.ndarray]:
        """gram_eigh of ``state``'s point, cached: tCG preconditions many vectors at one point."""
        if self._gram is None or self._gram[0] is not state.Z:
            self._gram = (state.Z, gram_eigh(state.Z))
        return self._gram[1]

    def _split_possible(self, state: State) -> bool:
        """Whether ``state`` is at width d + 1 with the first level's factor of K with Lambda at hand."""
        return (self.split_escape and state.Z.shape[2] == self.problem.d + 1 and self.tangent is not None
                and self._tangent_factor is not None and self._tangent_exact)

    def _split_parts(self, state: State, gram: tuple[np.ndarray, np.ndarray]) -> _SplitParts | None:
        """The split preconditioner's data at ``state``'s point, or None where it does not apply.

        After the escape from the first level the point is ``[Z1 | 0]`` plus a small new column.
        At ``[Z1 | 0]`` exactly, every tangent vector is ``Omega_i Z_i + b_i w^T`` (w the new
        column's unit vector), the two kinds are orthogonal and the Hessian does not couple them:
        on the first it is the first level's, whose inverse the last factor of K is; on the
        second it is ``2 (Q - Lambda)`` acting on b. So ``P = E (2 K_schur)^{-1} E^T +
        N (2 (Q - Lambda + sigma I))^{-1} N^T`` is the inverse Hessian there and stays close to it
        while the new column is small (docs/design.md#solver). w is the Gram matrix's eigenvector of
        the smallest eigenvalue, projected off each block's rows (N). Not used (None) where
        :meth:`_split_frame` says so or where the in-plane scale is not positive.
        """
        if self._split is not None and self._split[0] is state.Z:
            return self._split[1]
        parts = None
        frame = self._split_frame(state, gram) if self.precond_factor is not None else None
        if frame is not None and self.tangent is not None and self._tangent_factor is not None:
            w, Zw = frame
            scale = self.tangent.diagonal_mean(state.Z, state.lam)
            if scale > 0:
                # K's gauge modes depend on its factor only, which the level after the escape keeps
                factor = self._tangent_factor[1]
                if self._gauge is None or self._gauge[0] is not factor:
                    self._gauge = (factor, self.tangent.gauge_modes(self._tangent_factor[0][:, :, :self.problem.d]))
                gauge = self._gauge[1]
                parts = _SplitParts(normal=w[None] - np.einsum("ndr,nds->nrs", state.Z, Zw), gauge=gauge,
                                    gauge_scale=scale)
        self._split = (state.Z, parts)
        return parts

    def _split_frame(self, state: State, gram: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
        """(w, Z w) for the split preconditioner at ``state``, or None where it does not apply: not at
        width d + 1 after the first level, or a block turned more than 60 degrees towards w."""
        if not self._split_possible(state):
            return None
        w = gram[1][:, :1]                          # (r, 1): the new column's direction
        Zw = state.Z @ w                            # (n, d, 1)
        if float(np.max(np.einsum("nds,nds->n", Zw, Zw))) > 0.75:
            return None
        return w, Zw

    def _split_apply(self, state: State, R: np.ndarray, parts: _SplitParts) -> np.ndarray:
        """``P R`` of :meth:`_split_parts`: the in-plane part through K's factor, the new column's
        through M_red's factor with one right-hand side."""
        assert self.tangent is not None and self._tangent_factor is not None and self.precond_factor is not None
        Z = state.Z
        n, d, _ = Z.shape
        inplane = self.tangent.apply(self._tangent_factor[1], Z, R, gauge=(parts.gauge, parts.gauge_scale))
        b = np.einsum("ndr,nr->nd", R, parts.normal[:, :, 0])
        x = self._precond_solve(b.reshape(n * d, 1)).reshape(n, d)
        return inplane + 0.5 * x[:, :, None] * parts.normal[:, None, :, 0]


@dataclass(frozen=True)
class _SplitParts:
    normal: np.ndarray        # (n, r, 1) the new column's direction w projected off each block's rows
    gauge: np.ndarray         # (n k, k) K's near-null coordinates (TangentSystem.gauge_modes)
    gauge_scale: float        # the Hessian's scale put on them (TangentSystem.diagonal_mean)


@dataclass
class Certificate:
    certified: bool
    lambda_min: float
    vector: np.ndarray | None      # (n, d) unit eigenvector for lambda_min < -tol
    factorizations: int
    lanczos_solves: int
    # When certified: the shift s <= tol of the successful Cholesky of Q - Lambda + s I, which
    # proves lambda_min > -s (lambda_min itself is a Lanczos estimate).
    proven_shift: float | None = None
    shifted_factor: tuple[Factor, float] | None = None


# Relative residual tolerances of the shift-invert Lanczos runs in verify() (||A x - theta x|| <=
# tol theta). A certified point: the Ritz value is only the reported estimate of lambda_min (the
# factorization is the proof), and its error is second order in the residual (Kato-Temple), so
# 1e-8 keeps it far below the certificate's eta. The last two digits of residual cost the most
# steps (against 1e-10: parking-garage and ais2klinik 10 solves fewer, cubicle 9), for estimates
# that moved by at most 2.2e-12 with eta = 1e-3 (docs/performance.md). A saddle: the eigenvector
# is the escape direction, which backtracking and the next level's trust region refine; with 1e-4
# the escapes reach the same optima (2D grids; MIT and sphere_bignoise from their vertices: to
# 6e-15 relative).
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


def verify(problem: Problem, state: State, tol: float, rng: np.random.Generator,
           estimate_lambda: bool = True, factor: tuple | None = None) -> Certificate:
    """Decide lambda_min(Q - Lambda) >= -tol by sparse Cholesky; return the eigenpair if not.

    ``tol`` must be finite and >= 0 (a NaN made the shift search below loop forever); a
    non-finite certificate matrix is a SolverError, never an endless search. ``factor`` is an
    optional ``(Cholesky factor of M_red(Lambda, s), s)`` at this very point with 0 <= s <= tol
    (RelaxedModel.certificate_factor): it already decides the test, so no factorization is done.
    """
    if not (math.isfinite(tol) and tol >= 0):
        raise SolverError(f"certificate tolerance must be a finite number >= 0, got {float(tol)}")
    n, d = problem.n, problem.d
    dn = n * d
    lam = state.lam
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
        return Certificate(True, lm, None, facs, solves, proven_shift=float(shift))
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
    Sv = problem.Q_product(v[:, None]).ravel() - (lam @ v.reshape(n, d, 1)).ravel()
    rq = float(v @ Sv)
    lm = min(lm, rq) if rq < 0 else lm
    certified = lm >= -tol
    return Certificate(certified, lm, None if certified else v.reshape(n, d), facs, solves,
                       shifted_factor=(fac, float(sigma)))


def _next_escape_step(alpha: float, f: float, f0: float, lam: float) -> float:
    """The escape's next trial step after ``alpha`` gave the value ``f`` without enough decrease.

    Along the retracted path Z(a) = retract([Y | 0] + a [0 | v]) the objective is even in a
    (flipping the sign of the new column is an orthogonal map of R^(r+1) that the retraction and f
    commute with), so f(a) = f0 + lam a^2 + c a^4 + O(a^6). The next step is the minimiser
    sqrt(-lam / (2 c)) of that model through the trial's value, kept within [alpha / 16, alpha / 2];
    where the model has no minimiser (c <= 0, or a non-finite value) it is alpha / 2."""
    c = (f - f0 - lam * alpha * alpha) / alpha ** 4
    if not (c > 0.0 and lam < 0.0 and math.isfinite(c)):
        return 0.5 * alpha
    return min(0.5 * alpha, max(alpha / 16.0, math.sqrt(-lam / (2.0 * c))))


def escape(model: RelaxedModel, state: State, cert: Certificate) -> State:
    """Second-order descent from a saddle of width r along [0 | v] at width r + 1: backtracking from
    a = sqrt(n), each next trial at the minimiser of a quartic model of the path
    (:func:`_next_escape_step`), until f decreases by a quarter of the quadratic model's lam a^2.
    (Halving took 7-8 trials on the 2D grids of 30,276 and 100,489 poses; docs/performance.md.)"""
    Z = state.Z
    n, d, r = Z.shape
    Zp = lift(Z, r + 1)
    direction = np.zeros_like(Zp)
    direction[:, :, r] = cert.vector
    lam = cert.lambda_min
    f0 = state.f
    alpha = math.sqrt(n)
    best = None
    for _ in range(60):
        cand = model.evaluate(retract(Zp, alpha * direction))
        # Along the direction, f ~ f0 + lambda_min alpha^2; ask for a quarter of that decrease.
        if cand.f < f0 + 0.25 * lam * alpha * alpha:
            return cand
        if cand.f < f0 and (best is None or cand.f < best.f):
            best = cand
        alpha = _next_escape_step(alpha, cand.f, f0, lam)
    if best is not None:
        return best
    return model.evaluate(retract(Zp, 1e-6 * direction))
