"""The selection driver: ``select_edges`` choose K candidate edges by one method and certify them.

Its steps, one small function each: check the options (``_check_options``), set the problem up (fixed
edges and candidates, budget, anchor, estimate, objective, the fixed edges' value:
``_prepare``), choose by the method (``_choose``: greedy, relaxation, random or naive), evaluate
the chosen set with its bounds (``_evaluate``), optionally run the relaxation for a bound
(``_certify``), and assemble the result (``SelectResult`` with its certificate).
"""
from __future__ import annotations

import logging
import math
import numbers
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..core.choices import METHODS
from ..core.errors import NotPositiveDefinite, UsageError
from ..core.graph import PoseGraph
from ..solver.estimate import Estimate, get_estimate
from .budget import EdgeSplit, budget_spec, parse_budget, split_edges
from .certificate import RatioCertificate, ratio_certificate, submodular_bound, supergradient_bound
from .greedy import (
    GAINS,
    JL_FROM_CANDIDATES,
    greedy_fiedler,
    incremental_greedy,
    lazy_greedy,
    pick_engine,
    pick_strategy,
)
from .objectives import OBJECTIVES, FiedlerObjective, LogDetObjective, ObjectiveState, make_objective
from .relaxation import (
    POLISH_SOLVES,
    Relaxation,
    frank_wolfe,
    heaviest,
    polish_fiedler,
    projected_gradient,
    round_relaxation,
)
from .result import SelectResult, pruned_graph, selection_result
from .rounds import round_greedy

__all__ = ["METHODS", "SelectResult", "pruned_graph", "select_edges"]

log = logging.getLogger("posecrb")


@dataclass
class _Problem:
    """What every method works on: the objective over all m edges, the candidates and K, and the
    weights ``base`` with the fixed edges at 1 (the candidates at 0)."""

    graph: PoseGraph
    split: EdgeSplit
    k: int
    anchor: int
    obj: LogDetObjective | FiedlerObjective
    base: np.ndarray
    w_rot: np.ndarray                      # the naive method's weights (and top-K's tie-break)
    max_iter: int                          # relaxation iterations
    estimate: Estimate | None = None
    base_state: ObjectiveState | None = None
    full_value: float = float("nan")
    times: dict[str, float] = field(default_factory=dict)

    @property
    def cand(self) -> np.ndarray:
        return self.split.candidates

    def weights(self, chosen: np.ndarray) -> np.ndarray:
        """Edge weights with the fixed edges and ``chosen`` (edge indices) at 1."""
        x = self.base.copy()
        x[chosen] = 1.0
        return x


@dataclass
class _Choice:
    """What a method chose, and what it learned on the way."""

    chosen: np.ndarray                     # edge indices, sorted
    order: np.ndarray | None = None        # greedy: in the order chosen
    rounding: str | None = None            # relax: which rounding was kept
    relax: Relaxation | None = None
    stats: dict[str, Any] = field(default_factory=dict)
    online_bound: float | None = None      # the greedy's smallest Minoux bound (log-det objectives)


def _check_options(objective: str, method: str, gains: str, tol: float, max_iter: int | None,
                   rounds: int | None) -> None:
    for value, allowed, what in ((objective, OBJECTIVES, "objective"), (method, METHODS, "method"),
                                 (gains, GAINS, "gains mode")):
        if value not in allowed:
            raise UsageError(f"unknown {what} {value!r}; choose from {', '.join(allowed)}")
    if isinstance(tol, bool) or not (isinstance(tol, numbers.Real) and math.isfinite(tol) and tol > 0):
        raise UsageError(f"tol must be a finite number > 0, not {tol!r}")
    if max_iter is not None and (isinstance(max_iter, bool) or not (isinstance(max_iter, numbers.Integral)
                                                                     and max_iter >= 1)):
        raise UsageError(f"max_iter must be an integer >= 1, not {max_iter!r}")
    if rounds is not None and (isinstance(rounds, bool) or not (isinstance(rounds, numbers.Integral) and rounds >= 1)):
        raise UsageError(f"rounds must be an integer >= 1, not {rounds!r}")


def _prepare(graph: PoseGraph, budget: str | int | float, objective: str, fixed: str, anchor: int | None,
             estimate: str, fiedler_weight: str, split: EdgeSplit | None, reference: Estimate | None,
             max_iter: int | None) -> _Problem:
    """Fixed edges and candidates, K, the anchor, the estimate (fim), the objective, and the values
    with the fixed edges only and with every candidate."""
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    split = split or split_edges(graph, fixed)
    if split.candidates.size == 0:
        raise UsageError(f"{graph.name}: no candidate edges (every edge is fixed)")
    k = parse_budget(budget, split.candidates.size)
    anchor = graph.anchor_index(None) if anchor is None else int(anchor)
    est = reference
    if objective == "fim":
        if est is None:
            t1 = time.perf_counter()
            est = get_estimate(graph, estimate, anchor=anchor) if estimate == "solve" else get_estimate(graph, estimate)
            times["estimate"] = time.perf_counter() - t1
        if est.certified is False:
            log.warning("%s: the estimate of the full graph is NOT certified; the fim objective is evaluated "
                        "at an uncertified point", graph.name)
    obj = make_objective(graph, objective, anchor, est, fiedler_weight)
    base = np.zeros(graph.m)
    base[split.fixed] = 1.0
    times["setup"] = time.perf_counter() - t0 - times.get("estimate", 0.0)
    problem = _Problem(graph=graph, split=split, k=k, anchor=anchor, obj=obj, base=base,
                       w_rot=graph.rotation_weights if fiedler_weight == "w" else graph.kappa,
                       max_iter=max_iter if max_iter is not None else (20 if obj.kind == "fiedler" else 100),
                       estimate=est if objective == "fim" else None, times=times)
    t0 = time.perf_counter()
    try:
        problem.base_state = obj.evaluate(base)
    except NotPositiveDefinite as exc:
        # Every selection starts from the fixed edges alone; name them rather than the whole graph.
        raise NotPositiveDefinite(
            f"{graph.name}: {exc.matrix} of the {split.fixed.size} fixed edges (the selection's starting point)",
            f"{exc.reason}; the fixed edges alone must determine every pose to working precision",
            exc.column) from None
    problem.full_value = obj.value(problem.weights(split.candidates))
    times["base"] = time.perf_counter() - t0
    return problem


def _greedy_logdet(p: _Problem, gains: str, strategy: str, engine: str, rng: np.random.Generator,
                   rounds: int | None) -> _Choice:
    obj = p.obj
    assert isinstance(obj, LogDetObjective)
    strategy = pick_strategy(strategy, gains, p.k, p.graph.n)
    mode = gains
    if mode == "auto":
        mode = "jl" if strategy == "lazy" and p.cand.size > JL_FROM_CANDIDATES else "exact"
    elif mode == "jl" and strategy != "lazy":
        raise UsageError(f"random-projection gains (--jl) only seed the lazy greedy's queue; "
                         f"the {strategy} greedy takes every gain exactly")
    if strategy == "rounds":
        order, rstats = round_greedy(obj, p.base.copy(), p.cand, p.k, rounds)
        return _Choice(np.sort(order), order=order, stats=rstats.to_dict(), online_bound=rstats.online_bound)
    engine = pick_engine(engine, obj, p.cand.size, p.k)
    if strategy == "incremental":
        order, gstats = incremental_greedy(obj, p.base.copy(), p.cand, p.k, engine)
    else:
        order, gstats = lazy_greedy(obj, p.base.copy(), p.cand, p.k, mode, rng, engine)
    return _Choice(np.sort(order), order=order, stats={**vars(gstats), "strategy": strategy, "engine": engine},
                   online_bound=gstats.online_bound)


def _greedy_fiedler(p: _Problem) -> _Choice:
    assert isinstance(p.obj, FiedlerObjective)
    if p.k * p.graph.n > 2_000_000:
        log.warning("%s: the lambda_2 greedy (MAC's GreedyEig) solves at least one eigenproblem of %d poses "
                    "per selected edge (%d); this takes long, fiedler-relax is the scalable method",
                    p.graph.name, p.graph.n, p.k)
    order, fstats = greedy_fiedler(p.obj, p.base.copy(), p.cand, p.k)
    return _Choice(np.sort(order), order=order, stats=dict(fstats))


def _relax_logdet(p: _Problem, tol: float, gains: str, strategy: str, engine: str,
                  rng: np.random.Generator, rounds: int | None) -> _Choice:
    """The relaxation by projected gradient from the uniform point (its bound), rounded by top-K and
    Madow; the greedy selection competes with the roundings and is kept when it is at least as good.

    The relaxation's optimum is fractional (on intel and city10000 at 20%: no candidate at 1, and
    fewer than 2% at 0), so its roundings lose to the greedy (by 31 and 378 in the tree objective);
    what the relaxation adds is its bound, within ``tol`` of the relaxation's optimum."""
    assert p.base_state is not None and isinstance(p.obj, LogDetObjective)
    greedy = _greedy_logdet(p, gains, strategy, engine, rng, rounds)
    relax = projected_gradient(p.obj, p.base, p.cand, p.k, np.full(p.cand.size, p.k / p.cand.size),
                               max_iter=p.max_iter, tol=tol, base_value=p.base_state.value)
    rounding, pick, values = round_relaxation(p.obj, p.base, p.cand, p.k, relax.weights, p.w_rot[p.cand], rng)
    greedy_value = p.obj.value(p.weights(greedy.chosen))
    values = {"greedy": greedy_value, **values}
    stats = {"rounding_values": values, "greedy": greedy.stats}
    if greedy_value >= values[rounding]:
        return _Choice(greedy.chosen, order=greedy.order, rounding="greedy", relax=relax, stats=stats,
                       online_bound=greedy.online_bound)
    return _Choice(np.sort(p.cand[pick]), rounding=rounding, relax=relax, stats=stats,
                   online_bound=greedy.online_bound)


def _relax(p: _Problem, tol: float, polish: int | None, rng: np.random.Generator) -> _Choice:
    """fiedler: MAC's Frank-Wolfe from the naive selection, rounding (top-K and Madow), the swap polish."""
    obj, cand, k = p.obj, p.cand, p.k
    assert p.base_state is not None and isinstance(obj, FiedlerObjective)
    start = np.zeros(cand.size)
    start[heaviest(p.w_rot[cand], k, rng)] = 1.0   # MAC's initial point: the naive selection
    relax = frank_wolfe(obj, p.base, cand, k, start, max_iter=p.max_iter, tol=tol, base_value=p.base_state.value)
    rounding, pick, values = round_relaxation(obj, p.base, cand, k, relax.weights, p.w_rot[cand], rng)
    choice = _Choice(np.sort(cand[pick]), rounding=rounding, relax=relax, stats={"rounding_values": values})
    n_polish = POLISH_SOLVES if polish is None else int(polish)
    if n_polish > 0:
        pos, _, pstats = polish_fiedler(obj, p.base, cand, pick, max_solves=n_polish)
        polished = obj.value(p.weights(cand[pos]))   # recomputed from a cold start, as every reported value
        # keep the rounded set unless the recomputed value confirms the search's improvement
        if polished > values[rounding]:
            choice.chosen = np.sort(cand[pos])
            choice.rounding = rounding + "+polish"
        choice.stats["polish"] = {**vars(pstats), "recomputed": polished}
    return choice


def _choose(p: _Problem, method: str, *, gains: str, strategy: str, engine: str, tol: float, polish: int | None,
            rng: np.random.Generator, rounds: int | None) -> _Choice:
    """The K candidates chosen by ``method`` (every candidate when K is all of them)."""
    if p.k == p.cand.size:
        return _Choice(p.cand.copy())
    if method == "random":
        return _Choice(np.sort(rng.choice(p.cand, size=p.k, replace=False)))
    if method == "naive":
        return _Choice(np.sort(p.cand[heaviest(p.w_rot[p.cand], p.k, rng)]))
    if method == "greedy":
        return _greedy_logdet(p, gains, strategy, engine, rng, rounds) if p.obj.kind == "logdet" else _greedy_fiedler(p)
    if p.obj.kind == "logdet":
        return _relax_logdet(p, tol, gains, strategy, engine, rng, rounds)
    return _relax(p, tol, polish, rng)


def _evaluate(p: _Problem, choice: _Choice) -> tuple[ObjectiveState | None, float, float | None]:
    """(final state (fiedler), value of the chosen set, submodular bound (log-det))."""
    xs = p.weights(choice.chosen)
    if isinstance(p.obj, LogDetObjective):
        value, sub = submodular_bound(p.obj, xs, p.cand, p.k)
        if choice.online_bound is not None:
            sub = min(sub, choice.online_bound)
        return None, value, sub
    final = p.obj.evaluate(xs)
    return final, final.value, None


def _certify(p: _Problem, choice: _Choice, tol: float) -> Relaxation:
    """The relaxation warm-started at the selection itself: the bound is then at most value + gap there."""
    assert p.base_state is not None
    start = p.weights(choice.chosen)[p.cand].copy()
    if isinstance(p.obj, LogDetObjective):
        return projected_gradient(p.obj, p.base, p.cand, p.k, start, max_iter=p.max_iter, tol=tol,
                                  base_value=p.base_state.value)
    return frank_wolfe(p.obj, p.base, p.cand, p.k, start, max_iter=p.max_iter, tol=tol,
                       base_value=p.base_state.value)


def _certificate(p: _Problem, choice: _Choice, relax: Relaxation | None, final: ObjectiveState | None,
                 value: float, sub: float | None) -> RatioCertificate:
    every = p.k == p.cand.size
    relax_bound = relax.bound if relax else None
    if relax_bound is not None and final is not None and not every:
        assert isinstance(p.obj, FiedlerObjective)
        own = supergradient_bound(p.obj, final, p.cand, p.k)
        relax_bound = min(relax_bound, own)
        choice.stats["bound_at_selection"] = own
    return ratio_certificate(value, relax, relax_bound, sub, every)


def select_edges(graph: PoseGraph, budget: str | int | float, *, objective: str = "tree",
                 method: str = "greedy",
                 fixed: str = "odometry", certify: bool = False, seed: int = 0, anchor: int | None = None,
                 estimate: str = "solve", gains: str = "auto", max_iter: int | None = None,
                 tol: float = 1e-3, fiedler_weight: str = "w", split: EdgeSplit | None = None,
                 reference: Estimate | None = None, engine: str = "auto", strategy: str = "auto",
                 polish: int | None = None, rounds: int | None = None) -> SelectResult:
    """Choose ``budget`` candidate edges maximising ``objective`` (``posecrb.selection``).

    ``budget``: K, a fraction of the candidates in (0, 1], or the text "K" / "P%". ``method``:
    ``greedy`` (exact greedy; MAC's GreedyEig for fiedler), ``relax`` (the relaxation: spectral
    projected gradient for the log-dets, MAC's Frank-Wolfe for fiedler; rounded by top-K and by MADOW_DRAWS seeded Madow
    draws, the best kept; the log-dets keep the greedy selection unless a rounding beats it),
    ``random`` (seeded), ``naive`` (the K heaviest by rotation weight, MAC's baseline; ties at
    random). ``certify``: also run the
    relaxation for a bound (greedy, random, naive; relax always has one). Log-det objectives always
    report the submodular bound.
    ``estimate`` (fim only): "solve" (certified optimum of the full graph), "vertices" or a
    file; ``reference`` an already computed ``posecrb.solver.estimate.Estimate``. ``strategy`` (log-det
    greedy): "incremental" (every gain exact at every step), "lazy" (priority queue), "rounds" (the
    round greedy, ``posecrb.selection.rounds``: exact gains at the start of each of ``rounds``
    rounds, default ROUNDS, locally corrected choices within them; the set may differ from the exact
    greedy's, the value and bounds are exact) or "auto" (rounds above ROUNDS_FROM_STEPS steps on
    graphs of ROUNDS_FROM_POSES poses or more, lazy with ``gains="jl"``, incremental otherwise).
    ``gains`` (lazy only): "exact" (selected inversion), "jl" (random projections seed the queue)
    or "auto" (jl above 50000 candidates).
    ``engine`` (log-det greedy): "path" (posecrb.linalg.pathchol's compiled kernels), "cholmod" (CHOLMOD
    update_inplace and whole-factor solves, numpy for the rest: no numba to
    load) or "auto" (cholmod on small problems, ``posecrb.selection.greedy.pick_engine``; path
    otherwise). ``polish`` (fiedler relax): at most this many eigensolves of swap search
    after the rounding (``polish_fiedler``; default POLISH_SOLVES, 0 = none); the polished set is
    kept only if its recomputed lambda_2 is larger. ``max_iter``/``tol``: the relaxation's limits (default 100 for
    the log-dets, 20 for fiedler as MAC). ``split``: precomputed fixed/candidate edges.

    BLAS runs single-threaded inside, as in the solver: the work is many small products (vectors
    of the graph's size, selected inversions of Laplacians), for which OpenBLAS's threads cost more
    than they save and collapse when another process holds the other core
    (docs/decisions/blas-threads.md). threadpoolctl scans the libraries loaded at the call; a
    library loaded later (scipy's BLAS, on the first selected inversion) is limited by that
    inversion's own call (posecrb.linalg.selinv). The tree objective's
    incremental greedy on a large factor runs each step on two threads of its own when two cores
    are free (``posecrb.selection.greedy``), with the same choices bit for bit.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _select_edges(graph, budget, objective=objective, method=method, fixed=fixed, certify=certify,
                             seed=seed, anchor=anchor, estimate=estimate, gains=gains, max_iter=max_iter, tol=tol,
                             fiedler_weight=fiedler_weight, split=split, reference=reference, engine=engine,
                             strategy=strategy, polish=polish, rounds=rounds)


def _select_edges(graph: PoseGraph, budget: str | int | float, *, objective: str, method: str, fixed: str,
                  certify: bool, seed: int, anchor: int | None, estimate: str, gains: str, max_iter: int | None,
                  tol: float, fiedler_weight: str, split: EdgeSplit | None, reference: Estimate | None, engine: str,
                  strategy: str, polish: int | None, rounds: int | None) -> SelectResult:
    t_total = time.perf_counter()
    _check_options(objective, method, gains, tol, max_iter, rounds)
    p = _prepare(graph, budget, objective, fixed, anchor, estimate, fiedler_weight, split, reference, max_iter)
    times = p.times
    rng = np.random.default_rng(seed)

    t0 = time.perf_counter()
    choice = _choose(p, method, gains=gains, strategy=strategy, engine=engine, tol=tol, polish=polish, rng=rng,
                     rounds=rounds)
    times["select"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    final, value, sub = _evaluate(p, choice)
    times["value"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    relax = choice.relax
    if relax is None and certify and p.k < p.cand.size:
        relax = _certify(p, choice, tol)
    if relax is not None:
        # a relax run is timed as "relax" (its selection included), a certifying one as "certify"
        times["certify" if method != "relax" else "relax"] = time.perf_counter() - t0 + (
            times.pop("select") if method == "relax" else 0.0)
    cert = _certificate(p, choice, relax, final, value, sub)
    times["total"] = time.perf_counter() - t_total
    assert p.base_state is not None
    return selection_result(
        graph, anchor=p.anchor, objective=objective, method=method, budget=p.k,
        budget_spec=str(budget) if isinstance(budget, str) else budget_spec(budget),
        split=p.split, chosen=choice.chosen, value=value, base_value=p.base_state.value, full_value=p.full_value,
        certificate=cert, rounding=choice.rounding, order=choice.order, seed=seed, stats=choice.stats,
        estimate=p.estimate, times=times)
