"""The Riemannian staircase (SE-Sync, Rosen et al., IJRR 2019, Algorithm 1): local optimisation at
rank r, certification, negative-curvature escape to rank r + 1.

``solve`` starts from rotations padded with zero columns, which stay zero, and computes on the
nonzero columns only (its "width"): an escape from width w goes to width w + 1, which is the
staircase's rank r + 1 once the padding is used up. At each level the trust region
(trust_region.py) minimises the relaxation (relaxed.py) with the preconditioners the policy picks
(policy.py); the level's end point is tested by the dual certificate (certificate.py), and where it
is a saddle the eigenvector of ``S = Q - Lambda`` for its negative eigenvalue gives the
second-order descent direction ``[0 | v]`` in a new column.
"""
from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import NotPositiveDefinite
from .certificate import Certificate, verify
from .policy import PreconditionerPolicy
from .relaxed import RelaxedProblem, State
from .rounding import Rounding, round_point
from .stiefel import lift, retract
from .trust_region import TROptions, trust_region

log = logging.getLogger("posecrb")


@contextmanager
def timed_phase(times: dict[str, float], phase: str) -> Iterator[None]:
    """Add the seconds of the ``with`` block to ``times[phase]`` (also when it raises)."""
    t0 = time.perf_counter()
    try:
        yield
    finally:
        times[phase] = times.get(phase, 0.0) + time.perf_counter() - t0


@dataclass
class StaircaseOutcome:
    """Where the staircase stopped: the last level's point and certificate (None where the
    verification failed), why, and every level left at a saddle, rounded before it was left."""

    state: State
    certificate: Certificate | None
    reason: str
    level: int
    rank: int
    iterations: int
    hessian_vector_products: int
    saddle_roundings: list[Rounding] = field(default_factory=list)


def run_staircase(relaxed: RelaxedProblem, policy: PreconditionerPolicy, Z: np.ndarray, *, r0: int, rmax: int,
                  certificate_tol: float, rng: np.random.Generator, options: TROptions,
                  times: dict[str, float]) -> StaircaseOutcome:
    """Climb from the point ``Z`` (n, d, w), w <= r0, until a level's point is certified, the
    width reaches ``rmax`` or the verification fails; the phases' seconds go into ``times``
    (``optimize``, ``verify``, ``round``)."""
    problem = relaxed.problem
    iterations = hvps = 0
    state: State | None = None
    cert: Certificate | None = None
    roundings: list[Rounding] = []
    r, level = r0, 1
    while True:
        with timed_phase(times, "optimize"):
            res = trust_region(relaxed, Z, options, state=state, preconditioner=policy)
        state = res.state
        iterations += res.iterations
        hvps += res.hvps
        log.info("staircase level %d, r=%d%s: f=%.12g after %d TR iterations (%s), %d HVPs", level, r,
                 _width_note(state.Z, r), state.f, res.iterations, res.status, hvps)
        try:
            with timed_phase(times, "verify"):
                # An adaptive factor at this point with a shift <= eta already decides the test.
                cert = verify(problem, state.lam, certificate_tol, rng,
                              factor=policy.certificate_factor(state, certificate_tol))
        except NotPositiveDefinite as exc:
            return StaircaseOutcome(state, None, f"verification failed: {exc}", level, r, iterations, hvps, roundings)
        log.info("staircase level %d, r=%d: lambda_min(Q - Lambda) = %.3e (%s)", level, r, cert.lambda_min,
                 "certified" if cert.certified else "saddle")
        if cert.certified:
            reason = f"lambda_min(Q - Lambda) = {cert.lambda_min:.3e} >= -{certificate_tol:g} at rank {r}"
            return StaircaseOutcome(state, cert, reason, level, r, iterations, hvps, roundings)
        if state.Z.shape[2] >= rmax:
            reason = (f"not certified: lambda_min(Q - Lambda) = {cert.lambda_min:.3e} < -{certificate_tol:g} "
                      f"at the maximum rank rmax = {rmax}")
            return StaircaseOutcome(state, cert, reason, level, r, iterations, hvps, roundings)
        # Round this level's point before leaving it: where the relaxation is not exact, the next
        # levels' roundings can be worse than this one (the first level, started from rotations,
        # never leaves SO(d)^n: its point is a local optimum of F itself).
        with timed_phase(times, "round"):
            roundings.append(round_point(problem, state.Z, level, r))
        policy.after_escape(cert)
        with timed_phase(times, "optimize"):
            state = escape(relaxed, state, cert)
        Z = state.Z
        r = max(r0, Z.shape[2])
        level += 1


def _width_note(Z: np.ndarray, r: int) -> str:
    width = int(Z.shape[2])
    return "" if width == r else f" (a rank-{width} point: its other columns stay zero)"


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


def escape(relaxed: RelaxedProblem, state: State, cert: Certificate) -> State:
    """Second-order descent from a saddle of width r along [0 | v] at width r + 1: backtracking from
    a = sqrt(n), each next trial at the minimiser of a quartic model of the path
    (:func:`_next_escape_step`), until f decreases by a quarter of the quadratic model's lam a^2.
    The model's step takes fewer trials than halving from so long a first step
    (docs/decisions/solver-preconditioners.md)."""
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
        cand = relaxed.evaluate(retract(Zp, alpha * direction))
        # Along the direction, f ~ f0 + lambda_min alpha^2; ask for a quarter of that decrease.
        if cand.f < f0 + 0.25 * lam * alpha * alpha:
            return cand
        if cand.f < f0 and (best is None or cand.f < best.f):
            best = cand
        alpha = _next_escape_step(alpha, cand.f, f0, lam)
    if best is not None:
        return best
    return relaxed.evaluate(retract(Zp, 1e-6 * direction))
