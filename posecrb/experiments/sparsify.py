"""Pose-graph sparsification: what each selection method keeps, and what it costs the SLAM answer.

For every budget (a share of the loop closures, MAC's protocol) and every method, select the
candidate edges (``posecrb.selection.select``), then solve the pruned graph (fixed + selected edges) with
the certified solver and compare it with the full graph:

* the method's own objective value, the upper bound on the best K-subset and the certified
  ratio ``(value - base) / (upper_bound - base)``, and the selection time;
* the same selection under the three objectives: the eq. (75) tree bound, lambda_2 of the
  rotation-weighted Laplacian (MAC's), and ``logdet F`` / ``trace F^{-1}`` (the CRLB trace) of
  the pruned graph's frame-consistent Fisher information at the full graph's certified optimum
  (one common point for every method, so only the edges differ);
* the pruned graph's certified optimum: its objective, its certificate, and its ATE (rigid
  alignment of the positions, Horn/Umeyama without scale; translation RMSE and rotation RMSE)
  and RPE (consecutive poses; translation and rotation RMSE) against the full graph's optimum.

Methods are ``[objective-]method``: ``greedy``, ``relax``, ``random``, ``naive`` use
``objective`` (default tree); ``fiedler-relax`` is MAC's method, ``fim-greedy`` etc. name the
objective explicitly. Selections run as independent tasks on the Monte Carlo engine
(``posecrb.sim.montecarlo``): serial, local processes or Dask, identical results for a given seed.
"""
from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.errors import SolverError, UsageError
from ..core.graph import PoseGraph
from ..core.status import put
from ..linalg.cholesky import SymbolicCholesky
from ..linalg.selinv import SelectedInverse
from ..models.paper.fim import paper_fim
from ..selection import (
    METHODS,
    OBJECTIVES,
    FiedlerObjective,
    parse_budget,
    pruned_graph,
    select_edges,
    split_edges,
    tree_objective,
)
from ..sim.montecarlo import Task, make_tasks, run_tasks, seed_record
from ..solver import SolverOptions, solve
from ..solver.estimate import from_solve_result
from ..verification.trajectory import trajectory_error

DEFAULT_BUDGETS = tuple(f"{p}%" for p in range(10, 101, 10))
QUICK_BUDGETS = ("20%", "50%")
DEFAULT_METHODS = ("greedy", "relax", "fiedler-relax", "random", "naive")


def parse_budgets(spec: str | Sequence[str]) -> list[str]:
    """Comma-separated budgets, each K or P% (checked against the candidates later)."""
    parts = spec.split(",") if isinstance(spec, str) else list(spec)
    out = []
    for p in (str(x).strip() for x in parts):
        if not p:
            continue
        if not re.fullmatch(r"[0-9]+(\.[0-9]*)?%|[0-9]+", p):
            raise UsageError(f"--budgets: {p!r} is neither K nor P%")
        if p not in out:
            out.append(p)
    if not out:
        raise UsageError("--budgets needs at least one budget")
    return out


def parse_methods(spec: str | Sequence[str], objective: str = "tree") -> list[tuple[str, str, str]]:
    """``[objective-]method`` labels -> (label, objective, method)."""

    parts = spec.split(",") if isinstance(spec, str) else list(spec)
    out: list[tuple[str, str, str]] = []
    for label in (str(x).strip() for x in parts):
        if not label:
            continue
        obj, _, meth = label.rpartition("-")
        obj = obj or objective
        if obj not in OBJECTIVES or meth not in METHODS:
            raise UsageError(f"--methods: {label!r} is not [objective-]method with objective in "
                             f"{', '.join(OBJECTIVES)} and method in {', '.join(METHODS)}")
        if label not in [o[0] for o in out]:
            out.append((label, obj, meth))
    if not out:
        raise UsageError("--methods needs at least one method")
    return out


# ---------------------------------------------------------------- one selection and its consequences
@dataclass(frozen=True)
class SparsifyRow:
    budget_spec: str
    budget: int
    percent: float              # budget / candidates * 100
    method: str
    objective: str
    value: float
    base_value: float
    upper_bound: float | None
    certified_ratio: float | None
    rounding: str | None
    time_select: float          # selection + bounds, seconds
    tree: float                 # eq. (75) lower bound of the pruned graph
    fiedler: float              # lambda_2 of its rotation-weighted Laplacian
    fim_logdet: float           # logdet F of the pruned graph at the full graph's optimum
    crlb_trace: float | None    # trace F^{-1} there (None: not available, see crlb_trace_status)
    solve_objective: float
    certified: bool
    ate_trans: float
    ate_rot_deg: float
    rpe_trans: float
    rpe_rot_deg: float
    time_solve: float
    edges: int                  # kept edges


def _evaluate(context: dict, keep_mask: np.ndarray) -> dict:
    """Objective-independent measures of the kept edges (weights over all edges)."""

    graph: PoseGraph = context["graph"]
    ref = context["reference"]
    anchor = context["anchor"]
    x = keep_mask.astype(float)
    tree = tree_objective(graph, anchor).value(x)
    lam = FiedlerObjective(graph, graph.rotation_weights, anchor).value(x)
    pruned = pruned_graph(graph, np.flatnonzero(keep_mask))
    fim = paper_fim(pruned, ref.rot, ref.trans, anchor, variant="consistent")
    f, ld = SymbolicCholesky(fim.matrix).factor_logdet(fim.matrix, "pruned graph FIM")
    # A pruned graph can leave some unknowns barely observed: the trace then carries the selected
    # inverse's status (``crlb_trace_status`` beside it when not ok; None when it has no digit).
    inverse = SelectedInverse(f, "pruned graph FIM", repeated=True)   # one per selection evaluated
    out = {"tree": float(tree), "fiedler": float(lam), "fim_logdet": float(ld), "pruned": pruned}
    put(out, "crlb_trace", float(inverse.diagonal().sum()), inverse.status)
    return out


def _sparsify_task(context: dict, task: Task) -> dict:


    budget, label, objective, method = context["jobs"][task.trial]
    graph = context["graph"]
    t0 = time.perf_counter()
    res = select_edges(graph, budget, objective=objective, method=method, split=context["split"],
                       reference=context["reference"], certify=context["certify"], seed=context["seed"],
                       anchor=context["anchor"], max_iter=context["max_iter"])
    t_sel = time.perf_counter() - t0
    keep = np.zeros(graph.m, dtype=bool)
    keep[res.kept_edges] = True
    ev = _evaluate(context, keep)
    crlb_status = ev.pop("crlb_trace_status", None)
    t0 = time.perf_counter()
    sol = solve(ev.pop("pruned"), SolverOptions(anchor=context["anchor"]))
    t_solve = time.perf_counter() - t0
    ref = context["reference"]
    err = trajectory_error(sol.rot, sol.trans, ref.rot, ref.trans)
    cand = context["split"].candidates.size
    row = vars(SparsifyRow(
        budget_spec=budget, budget=res.budget, percent=100.0 * res.budget / cand, method=label,
        objective=objective, value=res.value, base_value=res.base_value, upper_bound=res.upper_bound,
        certified_ratio=res.certified_ratio, rounding=res.rounding, time_select=t_sel, **ev,
        solve_objective=float(sol.objective), certified=bool(sol.certified), **vars(err),
        time_solve=t_solve, edges=int(res.kept_edges.size)))
    if crlb_status is not None:
        row["crlb_trace_status"] = crlb_status
    return row


@dataclass
class SparsifyResult:
    dataset: str
    path: str | None
    sha256: str | None
    dim: int
    poses: int
    edges: int
    fixed: int
    fixed_rule: str
    candidates: int
    anchor_id: int
    objective: str
    reference: dict                 # the full graph: solve objective, certificate, tree, fiedler, fim, crlb;
                                    # "fixed_only": tree, fiedler, fim, crlb of the fixed edges alone
    rows: list[dict]
    budgets: list[str]
    methods: list[str]
    seed: int
    seeds: list[dict] = field(default_factory=list)

    def table_rows(self) -> list[dict]:
        return self.rows


def sparsify_experiment(graph: PoseGraph, budgets: Sequence[str] = DEFAULT_BUDGETS,
                        methods: Sequence[str] | str = DEFAULT_METHODS, *, objective: str = "tree",
                        fixed: str = "odometry", seed: int = 0, certify: bool = False,
                        max_iter: int | None = None, anchor: int = 0, executor: str = "serial", jobs: int = 1,
                        scheduler: str | None = None, progress: Callable[[int], None] | None = None
                        ) -> SparsifyResult:
    """Every (budget, method) pair: selection, bounds, and the pruned graph's certified solution.

    The full graph is solved first (the reference for ATE/RPE and the point of every FIM);
    raises SolverError when it cannot be certified."""

    budgets = parse_budgets(budgets)
    triples = parse_methods(methods, objective)
    split = split_edges(graph, fixed)
    for b in budgets:
        parse_budget(b, split.candidates.size)
    full = solve(graph, SolverOptions(anchor=anchor))
    if not full.certified:
        raise SolverError(f"{graph.name}: the full graph's optimum is not certified ({full.reason}); "
                          "it cannot serve as the reference")
    ref = from_solve_result(full, float(full.times["total"]))
    context: dict[str, Any] = {"graph": graph, "split": split, "reference": ref, "anchor": anchor, "seed": seed,
               "certify": certify, "max_iter": max_iter,
               "jobs": [(b, label, obj, meth) for b in budgets for (label, obj, meth) in triples]}
    ev = _evaluate(context, np.ones(graph.m, dtype=bool))
    ev.pop("pruned")
    fixed_only = np.zeros(graph.m, dtype=bool)
    fixed_only[split.fixed] = True
    base = _evaluate(context, fixed_only)
    base.pop("pruned")
    reference = {"solve_objective": float(full.objective), "certified": True, "time_solve": full.times["total"], **ev,
                 "fixed_only": base}
    tasks = make_tasks(seed, len(context["jobs"]), [(0,)])
    rows = run_tasks(_sparsify_task, [context], tasks, executor=executor, jobs=jobs, scheduler=scheduler,
                     progress=progress)
    return SparsifyResult(
        dataset=graph.name, path=graph.path, sha256=graph.sha256, dim=graph.dim, poses=graph.n, edges=graph.m,
        fixed=int(split.fixed.size), fixed_rule=split.rule, candidates=int(split.candidates.size),
        anchor_id=int(graph.ids[anchor]), objective=objective, reference=reference, rows=rows,
        budgets=budgets, methods=[t[0] for t in triples], seed=seed,
        seeds=[{"task": t.trial, **seed_record(t)} for t in tasks])
