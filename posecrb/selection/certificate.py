"""The ratio certificate of a selection: upper bounds on the best K-subset's objective value, and
the certified ratio ``(value - base) / (upper_bound - base)`` they give (1 = provably optimal).

Not to be confused with the solver's optimality certificate (``posecrb.solver.staircase``), which
certifies a pose-graph estimate as the global optimum. The bounds here, each valid on its own:

* relaxation bound: Frank-Wolfe's ``min_t f(x_t) + gap_t`` (>= the relaxation's optimum >= the best
  K-subset, f concave; ``posecrb.selection.relaxation``); for lambda_2 also ``R(v) + gap`` at the
  returned set itself (``supergradient_bound``);
* submodular bound (log-det objectives, monotone submodular): ``f(S) + (sum of the K largest
  marginal gains at S)`` for any set S (Minoux), at the returned set (``submodular_bound``) and at
  the greedy's intermediate sets;
* when every candidate is kept, the value itself.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import PosecrbError
from .objectives import FiedlerObjective, LogDetObjective, ObjectiveState
from .relaxation import Relaxation


@dataclass(frozen=True)
class RatioCertificate:
    """Upper bounds on the best K-subset's objective (each valid on its own)."""

    upper_bound: float | None           # the smallest of the bounds below
    relaxation_bound: float | None      # Frank-Wolfe: min_t f(x_t) + gap_t (>= relaxation optimum); for
    #                                     lambda_2 also f + gap at the returned set
    submodular_bound: float | None      # f(S) + sum of the K largest marginal gains at S (log-det only)
    relaxed_value: float | None         # f at the last Frank-Wolfe iterate
    iterations: int = 0
    converged: bool | None = None
    step: str | None = None

    def ratio(self, value: float, base_value: float) -> float | None:
        """(value - base) / (upper_bound - base), clipped to [0, 1]: the fraction of the best
        achievable gain over the fixed edges guaranteed to be reached; None without a bound."""
        if self.upper_bound is None:
            return None
        den = self.upper_bound - base_value
        if den <= 0:
            return 1.0
        return float(min(1.0, max(0.0, (value - base_value) / den)))


def submodular_bound(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int) -> tuple[float, float]:
    """(f(S), f(S) + sum of the K largest exact marginal gains over the candidates not in S)."""
    state = obj.evaluate(x)
    rest = cand[x[cand] == 0.0]
    if rest.size == 0:
        return state.value, state.value
    g = obj.gains(state, rest)
    return state.value, state.value + float(np.sort(g)[::-1][:k].sum())


def supergradient_bound(obj: FiedlerObjective, state: ObjectiveState, cand: np.ndarray, k: int) -> float:
    """``R(v) + max_s g^T (s - x)`` at the evaluated set ``state`` (lambda_2 <= v^T L(S') v for any
    S', linear in S'): its Rayleigh quotient plus the K largest supergradient entries minus the
    selected candidates' ones."""
    g = obj.gradient(state, cand)
    return state.value + float(np.sort(g)[::-1][:k].sum() - g[state.x[cand] == 1.0].sum())


def ratio_certificate(value: float, relax: Relaxation | None, relaxation_bound: float | None,
                      submodular: float | None, every_candidate: bool) -> RatioCertificate:
    """The certificate of a selection of objective ``value`` from its bounds (None where absent);
    ``every_candidate``: the budget keeps every candidate, so ``value`` is the optimum.

    Raises PosecrbError when ``value`` exceeds its own upper bound (a defect, never data)."""
    bounds = [b for b in (relaxation_bound, submodular) if b is not None]
    if every_candidate:
        bounds.append(value)
    upper = min(bounds) if bounds else None
    if upper is not None and value > upper + 1e-9 * max(1.0, abs(upper)):  # pragma: no cover - a bug
        raise PosecrbError(f"internal inconsistency: value {value} above its upper bound {upper}")
    return RatioCertificate(upper_bound=upper, relaxation_bound=relaxation_bound, submodular_bound=submodular,
                            relaxed_value=relax.value if relax else None,
                            iterations=relax.iterations if relax else 0,
                            converged=relax.converged if relax else None, step=relax.step if relax else None)
