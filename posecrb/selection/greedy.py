"""Greedy selection: add, K times, the candidate edge with the largest marginal gain.

Log-det objectives (``tree``, ``fim``) are monotone submodular, so greedy keeps ``(1 - 1/e)`` of
the optimal gain. The incremental greedy (``incremental_greedy``) keeps every candidate's
``H_f = U_f^T M^{-1} U_f`` exact from step to step by the Woodbury identity (one solve
``M^{-1} U_e`` per accepted edge, posecrb.linalg.pathchol) and updates the factor in place by
rank-one updates along the elimination-tree path of the edge, never refactorising per candidate;
the textbook lazy greedy (``lazy_greedy``: priority queue, stale gains re-evaluated by path
solves, optionally seeded by random projections) is the other strategy. Both record Minoux's
bound ``f(OPT) <= f(S) + (sum of the K largest gains at S)`` on ~64 of their intermediate sets.

The fiedler objective is concave in x but not submodular; its greedy is MAC's GreedyEig
(``greedy_fiedler``: candidates evaluated in the order of the supergradient bound ``R(v) + g_e``).
"""
from __future__ import annotations

import contextlib
import heapq
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.errors import NumericalError, UsageError
from .objectives import FiedlerObjective, LogDetObjective, logdet_eye_plus
from .rounds import ROUNDS_FROM_POSES, ROUNDS_FROM_STEPS

if TYPE_CHECKING:
    from ..linalg.pathchol import PathFactor

GAINS = ("auto", "exact", "jl")
STRATEGIES = ("auto", "incremental", "lazy", "rounds")
ENGINES = ("auto", "path", "cholmod")
# ``auto`` takes the CHOLMOD engine, which loads no numba, when the whole greedy is a few thousand
# whole-factor solves of small blocks at most: at most this many entries of M^{-1} U touched over
# the first gains and the steps (block rows x columns x (candidates + steps)). Above it the path
# engine's compiled kernels pay for numba's import and first call in a fresh process
# (docs/decisions/selection-at-scale.md).
CHOLMOD_ENGINE_ENTRIES = 5_000_000
# Greedy refreshes every gain by one selected inversion when one step needs more re-evaluations
# than max(REFRESH_AFTER, remaining candidates / REFRESH_FRACTION) (deterministic: a count, not a
# time). A refresh re-evaluates every remaining candidate at once, so it pays off only when a
# comparable number of path solves would be needed.
REFRESH_AFTER = 64
REFRESH_FRACTION = 4
# The incremental greedy recomputes its factor and every gain by selected inversion this often.
REFRESH_EVERY = 256
_BATCH_GROWTH = 2
# The lazy greedy seeds its queue by random projections ("auto") from this many candidates on.
JL_FROM_CANDIDATES = 50_000
JL_PROJECTIONS = 64
# The one-Laplacian incremental greedy runs each step on two threads (when two cores are free) from
# this many entries of its factor on, if the elimination tree splits into two subtrees of at least
# SPLIT_SHARE of them each (nested dissection). Below, one step is too short to pay for the
# threads' hand-offs and runs fused in one compiled call (docs/decisions/selection-at-scale.md).
THREADED_FACTOR_ENTRIES = 500_000
SPLIT_SHARE = 0.25


def _compiled() -> tuple[ModuleType, ModuleType]:
    """``posecrb.linalg.pathchol`` and ``posecrb.selection._kernels``, imported on first use: they
    load numba, a large part of a small command's start-up (docs/decisions/fixed-costs.md), which
    the fiedler objective never needs."""
    from ..linalg import pathchol  # noqa: PLC0415 -- lazy: start-up time (numba)
    from . import _kernels  # noqa: PLC0415 -- lazy: start-up time (numba)

    return pathchol, _kernels


@dataclass(frozen=True)
class GreedyStats:
    evaluations: int          # stale gains re-evaluated by solves
    refreshes: int            # full refreshes by selected inversion (including the first)
    updates: int              # factor updates (edges added)
    gains: str                # "exact" | "jl"
    online_bound: float | None = None   # min over the greedy's steps of Minoux's bound


class UpdateEngine:
    """Solves and rank-r updates against the current factors of an objective's blocks.

    ``"path"``: posecrb.linalg.pathchol (forward solves along the elimination-tree reach of the edge's
    rows, in-place rank-one updates on the fixed full-graph pattern). ``"cholmod"``: CHOLMOD's
    own ``update_inplace`` and dense solves with the whole factor, numpy for the rest (no numba)."""

    def __init__(self, obj: LogDetObjective, factors: list, kind: str):
        self.obj, self.kind = obj, kind
        if kind == "path":

            self.factors: list[Any] = [_compiled()[0].PathFactor(f) for f in factors]  # CHOLMOD Factors otherwise
        else:
            self.factors = factors

    def gains(self, edges: np.ndarray) -> np.ndarray:
        total = np.zeros(edges.size)
        for b, f in zip(self.obj.blocks, self.factors):
            if self.kind == "path":
                total += b.mult * _compiled()[0].logdet_eye_plus(f.h(b.rows[edges], b.valid[edges], b.U[edges]))
            else:
                total += b.mult * logdet_eye_plus(b.h_solve(f, edges))
        return total

    def solve(self, i: int, e: int) -> np.ndarray:
        """``M_i^{-1} U_e`` (size x r) with the current factor of block i."""
        b, f = self.obj.blocks[i], self.factors[i]
        if self.kind == "path":
            return f.solve(b.rows[e], b.valid[e], b.U[e])
        return f.solve_A(b.rhs(np.array([e])))

    def add(self, e: int) -> None:
        for b, f in zip(self.obj.blocks, self.factors):
            if self.kind == "path":
                f.update(b.rows[e], b.valid[e], b.U[e])
            else:
                b.update(f, e)


def incremental_greedy(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int,
                        engine: str = "path", refresh_every: int | None = None) -> tuple[np.ndarray, GreedyStats]:
    """Greedy with every candidate's gain kept exact at every step.

    ``H_f = U_f^T M^{-1} U_f`` for all candidates comes from ``LogDetBlock.h_many`` (solves with the
    factor on small blocks, one selected inversion otherwise); adding e
    changes it by the Woodbury identity

        H_f <- H_f - C_f (I + H_e)^{-1} C_f^T,    C_f = U_f^T M^{-1} U_e,

    so one solve ``M^{-1} U_e`` with the current factor (then updated by U_e) and one compiled
    pass over the candidates replace re-evaluations: the argmax is the exact greedy choice (ties:
    the first edge in the file). Every ``refresh_every`` steps the factor is recomputed and every
    H re-derived the same way, so rounding in the updates cannot accumulate. ``engine``:
    ``ENGINES``, resolved by ``pick_engine``."""

    refresh_every = refresh_every or REFRESH_EVERY
    engine = pick_engine(engine, obj, cand.size, k)
    if engine == "path" and len(obj.blocks) == 1 and obj.blocks[0].U.shape[2] == 1:
        return incremental_greedy_scalar(obj, x, cand, k, refresh_every)
    compiled = engine == "path"
    logdet = _compiled()[0].logdet_eye_plus if compiled else logdet_eye_plus
    state = obj.evaluate(x)
    hs = [b.h_many(f, cand) for b, f in zip(obj.blocks, state.data)]
    local = [(np.ascontiguousarray(b.U[cand]), np.ascontiguousarray(b.rows[cand]),
              np.ascontiguousarray(b.valid[cand])) for b in obj.blocks]
    eng = UpdateEngine(obj, state.data, engine)
    alive = np.ones(cand.size, dtype=bool)
    chosen: list[int] = []
    solves = 0
    refreshes = 1
    value = state.value
    online = math.inf
    # One Laplacian block: the gain mult * log1p(h) is increasing in h, so h itself ranks the
    # candidates (chosen ones are set to -inf) and logarithms are only taken where needed.
    scalar = len(obj.blocks) == 1 and obj.blocks[0].U.shape[2] == 1
    mult0 = obj.blocks[0].mult
    every = max(1, k // 64)   # Minoux's bound on ~64 prefixes: any subset of them is a valid min

    def gains_alive():
        g: np.ndarray = sum((b.mult * logdet(h) for b, h in zip(obj.blocks, hs)), np.zeros(cand.size))
        g[~alive] = -np.inf
        return g

    for step in range(k):
        if scalar:
            key = hs[0][:, 0, 0]
            pos = int(np.argmax(key))
            gain = mult0 * math.log1p(max(float(key[pos]), 0.0))
        else:
            g = gains_alive()
            pos = int(np.argmax(g))
            gain = float(g[pos])
        if step % every == 0:
            # Minoux's online bound at S_t: f(OPT) <= f(S_t) + (sum of the K largest gains at S_t)
            top = gains_alive()[alive]
            online = min(online, value + (float(np.partition(top, top.size - k)[top.size - k:].sum())
                                          if top.size > k else float(top.sum())))
        value += gain
        e = int(cand[pos])
        chosen.append(e)
        alive[pos] = False
        x[e] = 1.0
        h_e = [h[pos].copy() for h in hs]
        if scalar:
            hs[0][pos] = -np.inf
        if step + 1 == k:
            break
        if (step + 1) % refresh_every == 0:
            state = obj.evaluate(x)
            idx = np.flatnonzero(alive)
            for h, b, f in zip(hs, obj.blocks, state.data):
                h[idx] = b.h_many(f, cand[idx])
            eng = UpdateEngine(obj, state.data, engine)
            refreshes += 1
            continue
        for i, (h, (uc, rc, vc)) in enumerate(zip(hs, local)):
            z = eng.solve(i, e)                                         # M^{-1} U_e (size, r)
            solves += 1
            he = h_e[i]
            inv = np.linalg.inv(np.eye(he.shape[0]) + 0.5 * (he + he.T))
            if compiled:
                kernels = _compiled()[1]
                (kernels.woodbury_downdate1 if inv.shape[0] == 1 else kernels.woodbury_downdate)(
                    h, uc, rc, vc, alive, np.ascontiguousarray(z), inv)
            else:
                woodbury_downdate(h, uc, rc, vc, alive, z, inv)
        eng.add(e)
    return np.array(chosen, dtype=np.int64), GreedyStats(solves, refreshes, len(chosen), "exact", online)


def woodbury_downdate(h: np.ndarray, u: np.ndarray, rows: np.ndarray, valid: np.ndarray, alive: np.ndarray,
                      z: np.ndarray, inv: np.ndarray) -> None:
    """``H_f <- H_f - C_f inv C_f^T`` with ``C_f = U_f^T Z[rows_f]`` for every alive f, in place, with
    numpy: the CHOLMOD engine's form of ``posecrb.selection._kernels.woodbury_downdate``.

    h (c, r, r), u (c, p, r), rows/valid (c, p), alive (c,), z (n, r), inv (r, r)."""
    idx = np.flatnonzero(alive)
    zc = z[rows[idx]] * valid[idx][:, :, None]                 # (a, p, r): Z at the candidates' rows
    cf = np.einsum("kpa,kpb->kab", u[idx], zc)                  # C_f (a, r, r)
    h[idx] -= np.einsum("kab,bc,kdc->kad", cf, inv, cf)


def pick_engine(engine: str, obj: LogDetObjective, candidates: int, k: int) -> str:
    """The update engine ``engine`` (``ENGINES``) stands for on this problem: ``auto`` is the CHOLMOD
    engine when its whole-factor solves stay within ``CHOLMOD_ENGINE_ENTRIES`` (no numba to load),
    the path engine otherwise. The choice depends on the sizes alone, so one problem always gets
    the same digits."""
    if engine not in ENGINES:
        raise UsageError(f"unknown update engine {engine!r}; choose from {', '.join(ENGINES)}")
    if engine != "auto":
        return engine
    entries = sum(b.size * b.U.shape[2] for b in obj.blocks) * (candidates + k)
    small = entries <= CHOLMOD_ENGINE_ENTRIES and all(b.solves_suffice(candidates) for b in obj.blocks)
    return "cholmod" if small else "path"


def incremental_greedy_scalar(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int,
                               refresh_every: int) -> tuple[np.ndarray, GreedyStats]:
    """``incremental_greedy`` for one Laplacian block with the path engine, every step of a
    stretch fused into one compiled call (``posecrb.selection._kernels.scalar_greedy_steps``); Python only
    between stretches: Minoux's bound on ~64 prefixes and a refresh every ``refresh_every`` steps.
    Large factors whose elimination tree splits in two run each step on two threads instead
    (``_steps_two_threads``), with the same result bit for bit."""

    pathchol, kernels = _compiled()
    b = obj.blocks[0]
    uc = np.ascontiguousarray(b.U[cand][:, :, 0])
    rc = b.rows[cand]
    vc = np.ascontiguousarray(b.valid[cand])
    alive = np.ones(cand.size, dtype=bool)
    every = max(1, k // 64)
    chosen: list[np.ndarray] = []
    online = math.inf
    refreshes = solves = 0
    step = 0
    h: np.ndarray        # h, pf, prow and split are set by the refresh at step 0
    pf: PathFactor
    prow: np.ndarray
    split: tuple[int, int] | None = None   # depends on the factor's pattern only: the same at every refresh
    value = 0.0
    with ThreadPoolExecutor(max_workers=1) if _two_threads_allowed(k) else contextlib.nullcontext() as pool:
        while step < k:
            if step % refresh_every == 0:
                state = obj.evaluate(x)
                value = state.value
                h = np.full(cand.size, -np.inf)
                idx = np.flatnonzero(alive)
                h[idx] = b.h_selected(state.data[0], cand[idx])[:, 0, 0]
                pf = pathchol.PathFactor(state.data[0])
                prow = np.ascontiguousarray(pf.iperm[rc])
                if split is None:
                    split = (kernels.subtree_split(pf.indptr, pf.indices, pf.parent, SPLIT_SHARE)
                             if pool is not None and pf.indptr[-1] >= THREADED_FACTOR_ENTRIES else (-1, -1))
                refreshes += 1
            if step % every == 0:
                top = b.mult * np.log1p(np.maximum(h[alive], 0.0))
                online = min(online, value + (float(np.partition(top, top.size - k)[top.size - k:].sum())
                                              if top.size > k else float(top.sum())))
            stop = min(k, (step // every + 1) * every, (step // refresh_every + 1) * refresh_every)
            update_last = stop < k and stop % refresh_every != 0
            pf._mark[:] = 0
            if pool is not None and split is not None and split[0] >= 0:
                pos, gains = _steps_two_threads(kernels, pool, pf, split, prow, vc, uc, h, alive, stop - step,
                                                b.mult, update_last)
            else:
                pos, gains = kernels.scalar_greedy_steps(pf.indptr, pf.indices, pf.lval, pf.parent, prow, vc, uc, h,
                                                         alive, stop - step, b.mult, update_last, pf._mark,
                                                         np.zeros(pf.n))
            pf._mark[:] = 0
            x[cand[pos]] = 1.0
            chosen.append(cand[pos])
            value += float(gains.sum())
            solves += stop - step - (0 if update_last else 1)
            step = stop
    return np.concatenate(chosen), GreedyStats(solves, refreshes, k, "exact", online)


def _two_threads_allowed(k: int) -> bool:
    """Whether the scalar greedy may run its steps on two threads: more than one step, and two cores
    that no other process keeps busy (not in a process pool's worker; posecrb.linalg.threads)."""
    if k < 2:
        return False
    from ..linalg.threads import own_usable_threads  # noqa: PLC0415 -- lazy: start-up time

    return own_usable_threads() >= 2


def _steps_two_threads(kernels: ModuleType, pool: ThreadPoolExecutor, pf: PathFactor, split: tuple[int, int],
                       prow: np.ndarray, valid: np.ndarray, u: np.ndarray, h: np.ndarray, alive: np.ndarray,
                       nsteps: int, mult: float, update_last: bool) -> tuple[np.ndarray, np.ndarray]:
    """``scalar_greedy_steps`` with the two parts of a step that pass over everything on two threads:
    the backward substitution's two subtrees below the trunk (``subtree_split``: disjoint entries
    of the work vector once the trunk is done) and the two halves of the candidates' downdate.
    Every entry is computed by the same operations in the same order as in the fused kernel, so
    the choices and gains are the same bit for bit. Python runs once per step here, a few compiled
    calls that each pass over the whole factor, long next to Python's own work on the factors this
    is used for (THREADED_FACTOR_ENTRIES); the kernels release the GIL."""
    from ..linalg.pathchol import _backward1  # noqa: PLC0415 -- lazy, like the kernels

    top, mid = split
    c = h.size
    half = c // 2
    y = np.zeros(pf.n)
    chosen = np.empty(nsteps, np.int64)
    gains = np.empty(nsteps)
    for step in range(nsteps):
        pos, he, gain = kernels.scalar_greedy_take(h, alive, mult)
        chosen[step], gains[step] = pos, gain
        if step == nsteps - 1 and not update_last:
            break
        path = kernels.scalar_greedy_solve(pf.indptr, pf.indices, pf.lval, pf.parent, prow, valid, u, pos, pf._mark,
                                           step + 1, y, top)
        other = pool.submit(_backward1, pf.indptr, pf.indices, pf.lval, y, mid, top)
        _backward1(pf.indptr, pf.indices, pf.lval, y, 0, mid)
        other.result()
        inv = 1.0 / (1.0 + he)
        other = pool.submit(kernels.scalar_greedy_downdate, h, alive, u, prow, valid, y, inv, half, c)
        kernels.scalar_greedy_downdate(h, alive, u, prow, valid, y, inv, 0, half)
        other.result()
        kernels.scalar_greedy_update(pf.indptr, pf.indices, pf.lval, path, prow, valid, u, pos, y)
    return chosen, gains


def pick_strategy(strategy: str, gains: str, k: int, poses: int) -> str:
    """The greedy strategy ``auto`` stands for on K steps over a graph of ``poses`` poses: the lazy
    greedy when its queue is to be seeded by random projections (``gains="jl"``); the round greedy
    (``posecrb.selection.rounds``) above ROUNDS_FROM_STEPS steps on ROUNDS_FROM_POSES poses or more;
    otherwise the incremental greedy, whose step costs one solve with
    the whole factor and one pass over the candidates, whatever the graph; the lazy greedy's costs
    as many path solves as stale gains it re-evaluates, 30-90 per step on the shared datasets, whose
    loop closures cluster, and about 200 on a regular grid, whose gains are nearly all equal: it was
    the slower of the two on every graph measured (docs/decisions/selection-at-scale.md)."""
    if strategy not in STRATEGIES:
        raise UsageError(f"unknown greedy strategy {strategy!r}; choose from {', '.join(STRATEGIES)}")
    if strategy != "auto":
        return strategy
    if gains == "jl":
        return "lazy"
    return "rounds" if k > ROUNDS_FROM_STEPS and poses >= ROUNDS_FROM_POSES else "incremental"


def lazy_greedy(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int, gains: str,
                 rng: np.random.Generator, engine: str = "path") -> tuple[np.ndarray, GreedyStats]:
    """Lazy greedy (Minoux) on a monotone submodular log-det objective.

    Stale gains in the priority queue are upper bounds on the current ones (submodularity), so an
    entry on top whose gain was computed at the current step is the exact greedy choice. Stale
    entries on top are re-evaluated in batches of 1, 2, 4, ... against the current factor; a step
    that needs many re-evaluations (REFRESH_AFTER, REFRESH_FRACTION) refreshes every gain by one
    selected inversion of a fresh factorisation instead. The first gains come from one selected inversion,
    or with ``gains="jl"`` from random projections (then the initial queue is an estimate and the
    choice greedy only approximately; every accepted gain is still computed exactly)."""
    engine = pick_engine(engine, obj, cand.size, k)
    state = obj.evaluate(x)
    if gains == "jl":
        g0 = obj.gains_projected(state, cand, JL_PROJECTIONS, rng)
    else:
        g0 = obj.gains(state, cand)
    eng = UpdateEngine(obj, state.data, engine)
    heap = [(-float(g), int(e), 0) for g, e in zip(g0, cand)]
    heapq.heapify(heap)
    chosen: list[int] = []
    step = evals = evals_step = 0
    refreshes = 1
    batch = 1
    while len(chosen) < k:
        if heap[0][2] == step:
            _, e, _ = heapq.heappop(heap)
            chosen.append(e)
            x[e] = 1.0
            eng.add(e)
            step += 1
            evals_step = 0
            batch = 1
            continue
        if evals_step >= max(REFRESH_AFTER, len(heap) // REFRESH_FRACTION):
            rest = np.array(sorted(t[1] for t in heap), dtype=np.int64)
            state = obj.evaluate(x)
            g = obj.gains(state, rest)
            eng = UpdateEngine(obj, state.data, engine)
            heap = [(-float(gv), int(ev), step) for gv, ev in zip(g, rest)]
            heapq.heapify(heap)
            refreshes += 1
            evals_step = 0
            continue
        stale: list[int] = []
        while heap and heap[0][2] != step and len(stale) < batch:
            stale.append(heapq.heappop(heap)[1])
        g = eng.gains(np.array(stale, dtype=np.int64))
        for gv, ev in zip(g, stale):
            heapq.heappush(heap, (-float(gv), ev, step))
        evals += len(stale)
        evals_step += len(stale)
        batch *= _BATCH_GROWTH
    return np.array(chosen, dtype=np.int64), GreedyStats(evals, refreshes, len(chosen), gains, None)


def greedy_fiedler(obj: FiedlerObjective, x: np.ndarray, cand: np.ndarray, k: int) -> tuple[np.ndarray, dict]:
    """MAC's GreedyEig: per step, candidates in decreasing order of the bound ``R(v) + g_e``
    (concavity), each evaluated exactly, until the bound cannot beat the best found."""
    avail = np.ones(cand.size, dtype=bool)
    chosen = []
    evals = 0
    state = obj.evaluate(x)
    for _ in range(k):
        idx = np.flatnonzero(avail)
        g = obj.gradient(state, cand[idx])
        order = idx[np.argsort(-g, kind="stable")]
        bounds = state.value + obj.gradient(state, cand[order])
        best, best_state, best_pos = -np.inf, None, -1
        for pos, ub in zip(order, bounds):
            if ub <= best:
                break
            x[cand[pos]] = 1.0
            st = obj.evaluate(x, v0=state.data)
            x[cand[pos]] = 0.0
            evals += 1
            if st.value > best:
                best, best_state, best_pos = st.value, st, pos
        if best_state is None:  # every candidate's lambda_2 was NaN (or there was no candidate)
            raise NumericalError("lambda_2 greedy: no candidate edge gives a finite algebraic connectivity")
        avail[best_pos] = False
        x[cand[best_pos]] = 1.0
        chosen.append(int(cand[best_pos]))
        state = best_state
    return np.array(chosen, dtype=np.int64), {"evaluations": evals}

