"""The one pipeline behind ``bounds``, ``tables`` and ``regress``: graph -> bounds -> estimate ->
paper FIM -> log-det (docs/design.md#tables, timing regions as in #timing-protocol).

``posecrb.bounds`` builds its ``BoundsResult`` from the ``DatasetMetrics``, ``tables`` and
``regress`` their rows; the numbers come from here only.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..core.errors import PosecrbError
from ..core.graph import PoseGraph
from ..core.status import OK, Status
from ..core.timing import Repeat, measure
from ..linalg.accuracy import logdet_accuracy
from ..models.paper.bounds import GraphBounds, compute_bounds
from ..models.paper.fim import PaperFim, fim_symbolic_choice, paper_fim
from ..solver.estimate import Estimate, get_estimate


@dataclass(frozen=True, kw_only=True)
class EvaluationSettings:
    """``anchor``: internal index of the anchored pose; ``estimate``: "solve", "vertices", a file,
    or "none" (bounds only); ``solver``: options of the certified solver; ``repeat``: the timing
    protocol's repeats (``posecrb.core.timing.measure``; 1: each step runs once, untimed warm-up
    skipped; "auto": adaptive); ``ordering``: the
    fill-reducing ordering of every factorization (``posecrb.linalg.ordering.ORDERINGS``; the
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
    """What the pipeline computed, as far as it got: ``error`` is the PosecrbError that stopped it
    after the bounds (only with ``errors="keep"``)."""

    graph: PoseGraph
    bounds: GraphBounds
    estimate: Estimate | None = None
    fim: PaperFim | None = None
    fim_logdet: float | None = None
    fim_logdet_status: Status = OK      # its accuracy (posecrb.linalg.accuracy.logdet_accuracy)
    times: dict[str, float] = field(default_factory=dict)    # fim_build, fim_logdet (median of repeat)
    runs: dict[str, int] = field(default_factory=dict)       # per key of times: how many runs its median is of
    error: PosecrbError | None = None
    ordering: dict[str, str] = field(default_factory=dict)   # orderings used: lb, ub (bounds), fim


def evaluate(graph: PoseGraph, settings: EvaluationSettings, *, step: Callable[[str], None] | None = None,
             errors: str = "raise", estimate: Estimate | None = None) -> DatasetMetrics:
    """Bounds (section VII-B), the estimate, the anchored paper FIM there and its log-det.

    ``estimate``: poses to evaluate at instead of ``settings.estimate``'s (posecrb.bounds with an
    estimate object).

    ``step`` is told each stage's name ("bounds", "solve", "fim") before it starts.
    ``errors="keep"``: a PosecrbError after the bounds ends the pipeline and is returned in
    ``error`` with what was computed so far; ``"raise"`` lets it through."""
    say = step or (lambda s: None)
    say("bounds")
    b = compute_bounds(graph, settings.anchor, settings.rotation_weight, settings.repeat,
                       ordering=settings.ordering)
    used = dict(b.ordering)
    if settings.estimate == "none" and estimate is None:
        return DatasetMetrics(graph=graph, bounds=b, ordering=used)
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
        # how many digits of it to trust, with the last run's factor: a stage of its own (a selected
        # inversion, about twice the factorization's flops)
        t0 = time.perf_counter()
        accuracy = logdet_accuracy(factor[0], ld, "paper FIM")
        accuracy_seconds = time.perf_counter() - t0
    except PosecrbError as exc:
        if errors != "keep":
            raise
        return DatasetMetrics(graph=graph, bounds=b, estimate=est, error=exc, ordering=used)
    return DatasetMetrics(graph=graph, bounds=b, estimate=est, fim=fim, fim_logdet=ld,
                          fim_logdet_status=accuracy.status,
                          times={"fim_build": m_build.seconds, "fim_logdet": m_ld.seconds,
                                 "logdet_accuracy": accuracy_seconds},
                          runs={"fim_build": m_build.runs, "fim_logdet": m_ld.runs, "logdet_accuracy": 1},
                          ordering=used)
