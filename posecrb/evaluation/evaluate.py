"""The one pipeline behind ``bounds``, ``tables`` and ``regress``: graph -> bounds -> estimate ->
paper FIM -> log-det (docs/design.md#tables, timing regions as in #timing-protocol).

``evaluate`` returns the ``BoundsResult`` of the graph (``posecrb.bounds`` passes it through) with
the FIM it was computed from and, when the pipeline stopped after the bounds, the error; ``tables``
and ``regress`` make their rows of it. The numbers come from here only.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..core.errors import PosecrbError
from ..core.graph import PoseGraph
from ..core.timing import Repeat, measure
from ..models.inputs import input_files
from ..models.paper.bounds import compute_bounds
from ..models.paper.fim import PaperFim, fim_logdet_accuracy, fim_symbolic_choice, paper_fim, trace_fim
from ..models.paper.result import BoundsResult, FimAtEstimate
from ..solver.estimate import Estimate, get_estimate


@dataclass(frozen=True, kw_only=True)
class EvaluationSettings:
    """``anchor``: internal index of the anchored pose; ``estimate``: "solve", "vertices", a file,
    or "none" (bounds only); ``solver``: options of the certified solver; ``repeat``: the timing
    protocol's repeats (``posecrb.core.timing.measure``; 1: each step runs once, untimed warm-up
    skipped; "auto": adaptive); ``ordering``: the
    fill-reducing ordering of every factorization (``posecrb.core.choices.ORDERINGS``; the
    values never depend on it beyond rounding)."""

    anchor: int = 0
    rotation_weight: str = "eq59"
    fim_variant: str = "consistent"
    repeat: Repeat = 1
    estimate: str = "solve"
    solver: Mapping[str, Any] = field(default_factory=dict)
    ordering: str = "auto"


@dataclass(frozen=True, kw_only=True)
class DatasetMetrics:
    """What the pipeline computed, as far as it got: ``result`` (the graph-only bounds, and the FIM's
    log-det when it got there), the estimate (also when the FIM failed after it), the FIM itself, and
    ``error``, the PosecrbError that stopped it after the bounds (only with ``errors="keep"``)."""

    graph: PoseGraph
    result: BoundsResult
    estimate: Estimate | None = None
    fim: PaperFim | None = None
    error: PosecrbError | None = None


def evaluate(graph: PoseGraph, settings: EvaluationSettings, *, step: Callable[[str], None] | None = None,
             errors: str = "raise", estimate: Estimate | None = None, times: Mapping[str, float] | None = None,
             runs: Mapping[str, int] | None = None) -> DatasetMetrics:
    """Bounds (section VII-B), the estimate, the anchored paper FIM there and its log-det.

    ``estimate``: poses to evaluate at instead of ``settings.estimate``'s (posecrb.bounds with an
    estimate object). ``times`` / ``runs``: stages timed before (the parse), first in the result's.

    ``step`` is told each stage's name ("bounds", "solve", "fim") before it starts.
    ``errors="keep"``: a PosecrbError after the bounds ends the pipeline and is returned in
    ``error`` with what was computed so far; ``"raise"`` lets it through."""
    say = step or (lambda s: None)
    say("bounds")
    b = compute_bounds(graph, settings.anchor, settings.rotation_weight, settings.repeat,
                       ordering=settings.ordering)
    used = dict(b.ordering)
    all_times = {**(times or {}), **b.times}
    all_runs = {**(runs or {}), **b.runs}

    def result(part: FimAtEstimate | None = None) -> BoundsResult:
        return BoundsResult(dataset=graph.name, path=graph.path, sha256=graph.sha256, dim=graph.dim, poses=graph.n,
                            edges=graph.m, components=graph.n_components, bounds=b, times=all_times, runs=all_runs,
                            fim=part, ordering={"requested": settings.ordering, **used},
                            inputs=input_files(graph, part.estimate if part is not None else None))

    if settings.estimate == "none" and estimate is None:
        return DatasetMetrics(graph=graph, result=result())
    est: Estimate | None = None
    try:
        say("solve")
        est = estimate if estimate is not None else get_estimate(graph, settings.estimate, **settings.solver)
        say("fim")
        m_build = measure(lambda: paper_fim(graph, est.rot, est.trans, settings.anchor, settings.rotation_weight,
                                            variant=settings.fim_variant), settings.repeat)
        fim = m_build.value

        factor: list[Any] = []

        def logdet() -> float:
            sym, choice = fim_symbolic_choice(fim, settings.ordering)
            used["fim"] = str(choice)
            f, value = sym.factor_logdet(fim.matrix, name="paper FIM")
            factor[:] = [f]
            return value

        m_ld = measure(logdet, settings.repeat)
        ld = m_ld.value
        # how many digits of it to trust, with the last run's factor and the matrix it factors: a
        # stage of its own (posecrb.linalg.accuracy's tiers)
        t0 = time.perf_counter()
        accuracy = fim_logdet_accuracy(fim, factor[0], ld, graph, est.rot, est.trans)
        accuracy_seconds = time.perf_counter() - t0
    except PosecrbError as exc:
        if errors != "keep":
            raise
        return DatasetMetrics(graph=graph, result=result(), estimate=est, error=exc)
    all_times.update(fim_build=m_build.seconds, fim_logdet=m_ld.seconds, logdet_accuracy=accuracy_seconds)
    all_runs.update(fim_build=m_build.runs, fim_logdet=m_ld.runs, logdet_accuracy=1)
    if est.solve_time is not None:
        all_times["solve"] = est.solve_time
        all_runs["solve"] = 1
    part = FimAtEstimate(logdet=ld, logdet_status=accuracy.status, trace=trace_fim(fim), variant=fim.variant,
                         estimate=est)
    return DatasetMetrics(graph=graph, result=result(part), estimate=est, fim=fim)

