"""Which preconditioner applies when: the one switching policy of the staircase.

The rules (the measurements behind each threshold: docs/decisions/solver-preconditioners.md):

* First level (width d): the tangent space's inverse Hessian where it is on (2D from the start; 3D
  once a truncated-CG run needed more than ``TANGENT_SWITCH_HVPS`` products), its factor kept for
  the next iterate while truncated CG needs at most ``TANGENT_REFACTOR_HVPS`` products with it;
  where K is not positive definite, the base factor.
* Otherwise the base factor until a truncated-CG run needs more than ``refactor_hvps`` products,
  then ``(Q - Lambda + s I)^{-1}`` refactored at the iterate.
* After an escape (:meth:`PreconditionerPolicy.after_escape`) the factor is rebuilt at once, with
  shifts past the saddle's negative curvature; right after the escape from the first level the
  split preconditioner applies with the saddle's own factor on the new column, until a block
  leans too far towards that column.
* The trust region's exact-decrement stop where the tangent factor is exact; its certified stop
  where the adaptive factor at the point certifies it.
"""
from __future__ import annotations

import logging

import numpy as np

from ..linalg.cholesky import Factor
from .certificate import Certificate
from .options import Preconditioner, PreconditionerSettings
from .preconditioners import (
    AdaptivePreconditioner,
    BasePreconditioner,
    PreconditionerOperator,
    SplitPreconditioner,
    TangentPreconditioner,
    base_preconditioner_kind,
)
from .problem import Problem
from .relaxed import State
from .stiefel import remove_vertical
from .tangent import TangentSystem

log = logging.getLogger("posecrb")

# The names of the preconditioners, in the order of SolveResult.preconditioner_solves.
PRECONDITIONER_NAMES = ("schur", "rotation", "adaptive", "tangent", "split")

# 3D, "auto": the first level switches to the tangent space's preconditioner after a truncated-CG
# run of more than this many products. Its factor of K has half as many rows again as M_red's
# there and costs 2-2.5 times its factorization, which pays only where products are many
# (docs/decisions/solver-preconditioners.md).
TANGENT_SWITCH_HVPS = 20

# The tangent factor is kept for the next iterate while truncated CG needed at most this many
# products with it: it trades products for factorizations, which pays where factorizations are
# expensive (large graphs) and is neutral on small ones (docs/decisions/solver-preconditioners.md).
TANGENT_REFACTOR_HVPS = 3

# Right after an escape the iterate is next to the saddle, where S + s I is indefinite: the shifts
# tried start past its negative curvature lambda (<= 0), at s + 2 |lambda|, then s + 20 |lambda|;
# the saddle's own factor of S + sigma I serves the split preconditioner's new column where
# sigma <= s + 20 |lambda| (docs/decisions/solver-preconditioners.md).
PAST_SADDLE_SHIFTS = (2.0, 20.0)


class PreconditionerPolicy:
    """Decides which preconditioner the trust region applies at a point, and when each is refactored.

    ``apply`` counts on the preconditioner it picks; :meth:`solves` reports the counts. With no
    base preconditioner (``preconditioner="none"``) it applies the identity.
    """

    def __init__(self, problem: Problem, *, base: BasePreconditioner | None = None,
                 adaptive: AdaptivePreconditioner | None = None, tangent: TangentPreconditioner | None = None,
                 tangent_switch_hvps: int | None = None, split: bool = False, refactor_hvps: int | None = 30,
                 certificate_tol: float | None = None) -> None:
        self.problem, self.base, self.adaptive, self.tangent = problem, base, adaptive, tangent
        # None: the tangent preconditioner (if any) is on from the start
        self.tangent_switch_hvps = tangent_switch_hvps
        self.split = SplitPreconditioner(problem, tangent) if split and tangent is not None else None
        self.refactor_hvps = refactor_hvps
        self.certificate_tol = certificate_tol      # eta: the trust region may stop once certified
        # the M_red-type preconditioner in use where the tangent one is not: base or adaptive
        self.current: BasePreconditioner | AdaptivePreconditioner | None = None
        if base is not None and (tangent is None or tangent_switch_hvps is not None):
            base.prepare()
            self.current = base
        self._lambda_hint = 0.0      # lambda_min(Q - Lambda) at the last saddle (<= 0)
        self._refactor_next = False  # refactor at the next prepare() whatever the products (after an escape)
        self._saddle_factor: tuple[Factor, float] | None = None   # (factor, sigma) of the saddle just left
        self._saddle_factor_in_use = False

    # ---- what the trust region calls ----------------------------------------------------------
    def prepare(self, state: State, last_hvps: int | None = None, converging: bool = False) -> None:
        """Refactor what applies at ``state`` where it pays; ``last_hvps``: the products of the
        last truncated-CG run; ``converging``: the trust region's last step decreased f by at most
        its ``certified_rel_decrease`` (only there can a factorization at s alone succeed after an
        escape, and certify the point)."""
        base, adaptive, tangent = self.base, self.adaptive, self.tangent
        if adaptive is None or base is None:
            return
        if tangent is not None and state.Z.shape[2] == self.problem.d and self._tangent_on(tangent, last_hvps):
            self._prepare_tangent(tangent, base, state, last_hvps)
            return
        if self._saddle_factor_in_use and (self.split is None or self.split.frame(state) is None):
            # The split no longer applies, and the saddle's factor is a poor (Q - Lambda + s I)^{-1}
            # here: refactor past the saddle.
            self._saddle_factor_in_use = False
            self._refactor_next = True
            adaptive.forget()
        if adaptive.tried_at(state):
            return
        if (self.refactor_hvps is not None and not self._refactor_next
                and (last_hvps is None or last_hvps <= self.refactor_hvps)):
            return
        if (self._refactor_next and self._saddle_factor is not None
                and self._adopt_saddle_factor(adaptive, self._saddle_factor, state)):
            return
        self._refactor(adaptive, base, state, converging)

    def apply(self, state: State, R: np.ndarray) -> np.ndarray:
        """The preconditioned residual at ``state``, with the vertical directions removed."""
        part = self._pick(state)
        if part is None:
            return R
        gram = state.gram
        return remove_vertical(state.Z, part.apply(state, remove_vertical(state.Z, R, gram)), gram)

    def exact(self, state: State) -> bool:
        """Whether the preconditioner at ``state`` is the inverse Hessian on the tangent space (the
        trust region's ``exact_decrement_tol`` then applies)."""
        return self.tangent is not None and self.tangent.exact_at(state)

    def certified(self, state: State) -> bool:
        """Whether ``state`` is certified by the adaptive factor at its point (:meth:`certificate_factor`)."""
        return self.certificate_tol is not None and self.certificate_factor(state, self.certificate_tol) is not None

    # ---- what the staircase calls --------------------------------------------------------------
    def certificate_factor(self, state: State, tol: float) -> tuple[Factor, float] | None:
        """(factor, s) of ``M_red(Lambda, s)`` at ``state``'s point with ``0 <= s <= tol``, or None."""
        return None if self.adaptive is None else self.adaptive.certificate_factor(state, tol)

    def after_escape(self, cert: Certificate) -> None:
        """The next level starts next to the saddle ``cert`` describes: rebuild the factor there at
        once, shifted past its negative curvature, or take the saddle's own factor."""
        self._lambda_hint = min(cert.lambda_min, 0.0)
        self._refactor_next = True
        self._saddle_factor = cert.shifted_factor

    def solves(self) -> dict[str, int]:
        """How many times each preconditioner was applied, by name (``PRECONDITIONER_NAMES``), where not 0."""
        parts: list[PreconditionerOperator] = [p for p in (self.base, self.adaptive, self.tangent, self.split)
                                               if p is not None]
        counts = {name: sum(p.applications for p in parts if p.name == name) for name in PRECONDITIONER_NAMES}
        return {name: count for name, count in counts.items() if count}

    # ---- the rules ------------------------------------------------------------------------------
    def _pick(self, state: State) -> PreconditionerOperator | None:
        """The preconditioner that applies at ``state``: the tangent one where it is factored there,
        else the split one where it applies, else the base or adaptive factor in use (None: none)."""
        if self.tangent is not None and self.tangent.at(state):
            return self.tangent
        if self.current is None:
            return None
        if self.split is not None and self.split.prepare(state, self.current):
            return self.split
        return self.current

    def _tangent_on(self, tangent: TangentPreconditioner, last_hvps: int | None) -> bool:
        """Whether the tangent preconditioner applies at the first level, switching it on after a
        long truncated-CG run where it waits for one."""
        if self.tangent_switch_hvps is None:
            return True
        if last_hvps is not None and last_hvps > self.tangent_switch_hvps:
            log.debug("preconditioner: %d products in the last truncated CG, switching to the tangent space's",
                      last_hvps)
            self.tangent_switch_hvps = None
            tangent.build()
            return True
        return False

    def _prepare_tangent(self, tangent: TangentPreconditioner, base: BasePreconditioner, state: State,
                         last_hvps: int | None) -> None:
        if tangent.at(state):
            return
        if tangent.factor is not None and last_hvps is not None and last_hvps <= TANGENT_REFACTOR_HVPS:
            tangent.carry_to(state)
            return
        if not tangent.prepare(state):
            base.prepare()
            self.current = base
            log.debug("preconditioner: K not positive definite, using (Q + delta I)^-1")

    def _adopt_saddle_factor(self, adaptive: AdaptivePreconditioner, saddle: tuple[Factor, float],
                             state: State) -> bool:
        """Take the saddle's factor of ``Q - Lambda + sigma I`` for the split's new column: it serves
        there as well as a new factor (its shift is past the negative curvature), one factorization
        fewer. False where the split does not apply or sigma is far past the curvature."""
        factor, sigma = saddle
        self._saddle_factor = None
        if not (self.split is not None and self.split.possible(state)
                and sigma <= adaptive.shift + PAST_SADDLE_SHIFTS[-1] * abs(self._lambda_hint)):
            return False
        self._refactor_next = False
        adaptive.adopt(state, factor, sigma)
        self.current = adaptive
        self._saddle_factor_in_use = True
        return True

    def _refactor(self, adaptive: AdaptivePreconditioner, base: BasePreconditioner, state: State,
                  converging: bool) -> None:
        """Factor ``(Q - Lambda + s I)`` at ``state``; after an escape past the saddle's curvature
        first (s alone only at a converging iterate), the base factor where none is positive definite."""
        s = adaptive.shift
        shifts: tuple[float, ...] = (s,)
        if self._lambda_hint < 0:
            past_saddle = tuple(s + k * abs(self._lambda_hint) for k in PAST_SADDLE_SHIFTS)
            shifts = ((s,) if converging and not self._refactor_next else ()) + past_saddle
        self._refactor_next = False
        self._saddle_factor_in_use = False
        if adaptive.prepare(state, shifts):
            self.current = adaptive
        else:
            base.prepare()
            self.current = base
            log.debug("preconditioner: Q - Lambda + s I not PD, using (Q + delta I)^-1")


def build_policy(problem: Problem, choice: Preconditioner, settings: PreconditionerSettings,
                 certificate_tol: float | None) -> PreconditionerPolicy:
    """The policy of ``SolverOptions.preconditioner`` and its settings for ``problem``: the base
    factor built now unless the tangent preconditioner applies from the start (then on first use:
    a graph certified at the first level never needs it)."""
    if choice == "none":
        return PreconditionerPolicy(problem, certificate_tol=certificate_tol)
    gershgorin = problem.gershgorin_max()
    # delta caps the base factor's condition number near max_condition (SE-Sync's regularised Cholesky)
    delta = gershgorin / settings.max_condition
    base = BasePreconditioner(problem, delta, base_preconditioner_kind(settings.base, problem.d, problem.n))
    if settings.adaptive_shift is None:
        return PreconditionerPolicy(problem, base=base, refactor_hvps=settings.refactor_hvps,
                                    certificate_tol=certificate_tol)
    shift = settings.adaptive_shift * gershgorin
    tangent = None
    switch = None
    if choice == "tangent" or (choice == "auto" and problem.d == 2):
        tangent = TangentPreconditioner(problem, shift, delta, TangentSystem.build(problem))
    elif choice == "auto":
        tangent, switch = TangentPreconditioner(problem, shift, delta), TANGENT_SWITCH_HVPS
    return PreconditionerPolicy(problem, base=base, adaptive=AdaptivePreconditioner(problem, shift),
                                tangent=tangent, tangent_switch_hvps=switch, split=settings.split_after_escape,
                                refactor_hvps=settings.refactor_hvps, certificate_tol=certificate_tol)
