"""The continuous relaxation ``x in [0, 1]^C, sum x = K`` and its rounding to a K-subset.

Both objectives are concave in x, so at any point ``f(x) + max_s grad^T (s - x)`` (the Frank-Wolfe
duality gap added to the value) bounds the relaxation's optimum, hence the best K-subset
(``frank_wolfe``). The relaxed weights are rounded by top-K and by seeded Madow draws
(``madow``: systematic sampling, edge e kept with probability x_e), the best kept
(``round_relaxation``). For fiedler the rounded set is then polished by swaps
(``polish_fiedler``), MAC's relaxation being otherwise the same: the naive start (heaviest edges),
step ``2/(t+2)``, 20 iterations.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .objectives import FiedlerObjective, LogDetObjective, ObjectiveState

# The relaxation is rounded by top-K and by this many seeded Madow draws; the best is kept.
MADOW_DRAWS = 8
# fiedler-relax polishes its rounded set by swaps: at most this many eigensolves, trials among the
# this-many best-ranked additions and removals per round.
POLISH_SOLVES = 60
POLISH_WIDTH = 16


@dataclass(frozen=True)
class Relaxation:
    """A Frank-Wolfe run on the concave relaxation ``x in [0, 1]^C, sum x = K``."""

    weights: np.ndarray        # (c,) last iterate, per candidate
    value: float               # f at the last iterate
    bound: float               # min over iterates of f(x_t) + gap_t: >= the relaxation's optimum
    gap: float                 # duality gap at the last iterate
    iterations: int
    converged: bool
    step: str                  # "backtracking" | "2/(t+2)"
    history: list = field(default_factory=list)   # (iteration, value, bound)


def top_k(scores: np.ndarray, k: int, tiebreak: np.ndarray | None = None) -> np.ndarray:
    """Positions of the k largest scores; ties by ``tiebreak`` (larger first), then position."""
    keys = (np.arange(scores.size),) + ((-tiebreak,) if tiebreak is not None else ()) + (-scores,)
    return np.lexsort(keys)[:k]


def frank_wolfe(obj: LogDetObjective | FiedlerObjective, x_full: np.ndarray, cand: np.ndarray, k: int,
                start: np.ndarray, *, max_iter: int,
                tol: float, base_value: float, step: str = "backtracking") -> Relaxation:
    """Frank-Wolfe ascent on ``f(x)`` over ``{0 <= x <= 1, sum x = K}`` (candidates only).

    The linear maximisation oracle is the indicator of the K largest gradient entries; the
    duality gap ``g^T (s - x)`` added to ``f(x)`` bounds the relaxation's maximum (f concave),
    and the smallest such bound over the iterates is returned. Stops when the gap is below
    ``tol * (bound - base_value)`` (the gain is known to a relative ``tol``) or after
    ``max_iter`` iterations. ``step="backtracking"``: the adaptive step of Pedregosa et al.
    (2020), sufficient increase against a local quadratic model whose curvature is
    doubled on failure; ``"2/(t+2)"``: the classical rule (MAC's).
    """
    x = x_full.copy()
    x[cand] = start
    state = obj.evaluate(x)
    best = math.inf
    lip = None
    hist = []
    gap = math.inf
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        g = obj.gradient(state, cand)
        s = np.zeros(cand.size)
        s[top_k(g, k)] = 1.0
        d = s - x[cand]
        gap = float(np.dot(g, d))
        best = min(best, state.value + max(gap, 0.0))
        hist.append((it, state.value, best))
        if gap <= tol * max(best - base_value, 1e-300):
            converged = True
            break
        dd = float(np.dot(d, d))
        if step == "2/(t+2)":
            gamma = 2.0 / (it + 2.0)
            x[cand] += gamma * d
            state = obj.evaluate(x, v0=state.data) if obj.kind == "fiedler" else obj.evaluate(x)
            continue
        if lip is None:
            lip = gap / dd
        for _ in range(60):
            gamma = min(1.0, gap / (lip * dd))
            trial = x.copy()
            trial[cand] += gamma * d
            new = obj.evaluate(trial)
            if new.value >= state.value + gamma * gap - 0.5 * gamma * gamma * lip * dd - 1e-12 * abs(state.value):
                break
            lip *= 2.0
        x, state = trial, new
        lip *= 0.5
    np.clip(x, 0.0, 1.0, out=x)
    return Relaxation(weights=x[cand].copy(), value=state.value, bound=best, gap=gap, iterations=it,
                      converged=converged, step=step, history=hist)


def heaviest(weights: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Positions of the k largest weights, ties broken at random (seeded): on datasets with one
    noise level for every edge this is a random selection, not the first k in the file."""
    return np.lexsort((rng.permutation(weights.size), -weights))[:k]


def madow(weights: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Madow's systematic sampling: K distinct positions, position e with probability weights[e]
    (weights in [0, 1] summing to K): one uniform u, the points u, u + 1, ..., u + K - 1 on the
    cumulative sums."""
    cum = np.cumsum(np.clip(weights, 0.0, 1.0))
    cum *= k / cum[-1]
    u = rng.random()
    pos = np.searchsorted(cum, u + np.arange(k), side="right")
    pos = np.unique(np.minimum(pos, weights.size - 1))
    if pos.size < k:  # rounding at an interval boundary: fill with the largest remaining weights
        rest = np.setdiff1d(np.arange(weights.size), pos)
        pos = np.union1d(pos, rest[top_k(weights[rest], k - pos.size)])
    return pos


@dataclass(frozen=True)
class PolishStats:
    """What the swap search after rounding did (``polish_fiedler``)."""

    solves: int            # eigenproblems solved for trial sets
    swaps: int             # candidates exchanged in accepted moves
    moves: int             # accepted moves (one or a block of paired swaps each)
    value_before: float    # lambda_2 of the rounded set
    value_after: float     # lambda_2 of the polished set (as computed during the search)
    stopped: str           # "no-ascent" | "no-improving-trial" | "solves"


def polish_fiedler(obj: FiedlerObjective, base: np.ndarray, cand: np.ndarray, pick: np.ndarray, *,
                   max_solves: int = POLISH_SOLVES, width: int = POLISH_WIDTH,
                   state: ObjectiveState | None = None) -> tuple[np.ndarray, ObjectiveState, PolishStats]:
    """Swap search on a K-subset of the candidates for a larger ``lambda_2``.

    ``pick``: positions in ``cand`` of the K selected candidates; ``base``: the weights of every
    edge with the fixed ones at 1. With ``v`` the unit Fiedler vector of the current set S and
    ``g_e = w_e (v_i - v_j)^2``, any set S' satisfies ``lambda_2(S') <= v^T L(S') v = R(v) + sum_{S'
    minus S} g - sum_{S minus S'} g`` (``lambda_2`` is a minimum of Rayleigh quotients): exchanging
    removals R for additions A can raise ``lambda_2`` above ``R(v)`` only if ``g(A) > g(R)``. The
    search stops when even the best single swap (largest g outside S against smallest g inside)
    has ``g_a <= g_r`` ("no-ascent"): then no K-subset exceeds ``R(v)``, S is optimal up to the
    eigensolver's accuracy (its Frank-Wolfe duality gap is zero). Trial moves per round, each
    costing one eigensolve warm-started at v: the ``p`` largest additions paired with the ``p``
    smallest removals for p = block, block/2, ..., 2 (block doubles after an accepted block move),
    then single swaps in decreasing order of ``g_a - g_r`` (at most ``width`` of them; additions and
    removals among the ``width`` best-ranked each). The first trial that raises ``lambda_2`` is
    accepted; the search stops when a round has none ("no-improving-trial") or after
    ``max_solves`` eigensolves. Never returns a set worse than ``pick`` as evaluated; the
    budget (K) and the fixed edges are unchanged by construction.
    """
    sel = np.zeros(cand.size, dtype=bool)
    sel[pick] = True
    x = base.copy()
    x[cand[sel]] = 1.0
    if state is None:
        state = obj.evaluate(x)
    before = state.value
    solves = swaps = moves = 0
    block = 2
    stopped = "solves"
    while solves < max_solves:
        ins, outs = np.flatnonzero(sel), np.flatnonzero(~sel)
        if ins.size == 0 or outs.size == 0:
            stopped = "no-ascent"
            break
        g = obj.gradient(state, cand)
        add = outs[np.argsort(-g[outs], kind="stable")[:width]]
        rem = ins[np.argsort(g[ins], kind="stable")[:width]]
        # an exchange must beat R(v) by more than the rounding of the values themselves
        eps = 1e-12 * abs(state.value)
        w = min(add.size, rem.size)
        paired = g[add[:w]] - g[rem[:w]]    # decreasing: rank-i addition with rank-i removal
        p_max = int(np.count_nonzero(paired > eps))
        if p_max == 0:
            stopped = "no-ascent"
            break
        trials = []
        p = min(block, p_max)
        while p >= 2:
            trials.append((add[:p], rem[:p]))
            p //= 2
        est = g[add][:, None] - g[rem][None, :]
        for f in np.argsort(-est, axis=None, kind="stable")[:width]:
            i, j = divmod(int(f), rem.size)
            if est[i, j] <= eps:
                break
            trials.append((add[i:i + 1], rem[j:j + 1]))
        accepted = False
        for a, r in trials:
            if solves >= max_solves:
                break
            x[cand[a]] = 1.0
            x[cand[r]] = 0.0
            trial = obj.evaluate(x, v0=state.data)
            solves += 1
            if trial.value > state.value + eps:
                sel[a], sel[r] = True, False
                state = trial
                swaps += a.size
                moves += 1
                block = max(2, 2 * a.size)
                accepted = True
                break
            x[cand[a]] = 0.0
            x[cand[r]] = 1.0
        if not accepted:
            if solves < max_solves:
                stopped = "no-improving-trial"
            break
    stats = PolishStats(solves=solves, swaps=swaps, moves=moves, value_before=float(before),
                        value_after=float(state.value), stopped=stopped)
    return np.flatnonzero(sel), state, stats



def round_relaxation(obj: LogDetObjective | FiedlerObjective, base: np.ndarray, cand: np.ndarray, k: int,
                     weights: np.ndarray, tiebreak: np.ndarray, rng: np.random.Generator
                     ) -> tuple[str, np.ndarray, dict[str, float]]:
    """Round relaxed weights to K candidates: top-K (ties by ``tiebreak``, larger first) and
    MADOW_DRAWS seeded Madow draws, each evaluated; the first best is kept (top-K wins ties).

    Returns (name of the kept rounding, its positions in ``cand``, the value of every rounding)."""
    picks = [("top-k", top_k(weights, k, tiebreak=tiebreak))] + [
        (f"madow-{i + 1}", madow(weights, k, rng)) for i in range(MADOW_DRAWS)]
    vals = {}
    for name, pick in picks:
        x = base.copy()
        x[cand[pick]] = 1.0
        vals[name] = (obj.value(x), pick)
    best = max(vals, key=lambda n: (vals[n][0], n == "top-k"))
    return best, vals[best][1], {n: v for n, (v, _) in vals.items()}
