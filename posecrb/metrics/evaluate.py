"""The one pipeline behind ``bounds``, ``tables`` and ``regress``: graph -> bounds -> estimate ->
paper FIM -> log-det (docs/design.md#tables, timing regions as in #timing-protocol).

Each command renders its own row from the ``DatasetMetrics`` (its keys are unchanged); the
numbers come from here only.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..core.errors import PosecrbError
from ..core.graph import PoseGraph
from ..core.timing import Repeat, measure
from ..models.paper.bounds import BoundsResult, compute_bounds
from ..models.paper.fim import PaperFim, fim_symbolic_choice, paper_fim, trace_fim
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
    rotation_model: str = "eq59"
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
    bounds: BoundsResult
    estimate: Estimate | None = None
    fim: PaperFim | None = None
    fim_logdet: float | None = None
    times: dict[str, float] = field(default_factory=dict)    # fim_build, fim_logdet (median of repeat)
    runs: dict[str, int] = field(default_factory=dict)       # per key of times: how many runs its median is of
    error: PosecrbError | None = None
    ordering: dict[str, str] = field(default_factory=dict)   # orderings used: lb, ub (bounds), fim


    def to_row(self, times: Mapping[str, float] | None = None, runs: Mapping[str, int] | None = None) -> dict:
        """The ``bounds`` command's row: the graph, ``BoundsResult.to_row()``, the times (``times``
        first, e.g. the parse time, then the bounds', the FIM's and the solve's; ``runs``: how many
        runs each of them is the median of, ``runs`` first) and, when an
        estimate was evaluated, the FIM log-det, trace (eq. 69/70) and variant, the estimate's source,
        certificate and objective; ``status`` is ``"uncertified"`` when the solver did not certify."""
        g, b = self.graph, self.bounds
        row: dict = {"dataset": g.name, "path": g.path, "sha256": g.sha256, "dim": g.dim, "poses": g.n,
                     "edges": g.m, "components": g.n_components, **b.to_row(),
                     "times": {**(times or {}), **b.times}, "runs": {**(runs or {}), **b.runs}}
        if self.estimate is not None and self.fim is not None:
            est, fim = self.estimate, self.fim
            row.update(fim_logdet=self.fim_logdet, trace_fim=trace_fim(fim), fim_variant=fim.variant,
                       estimate={"source": est.source, "certified": est.certified, "objective": est.objective})
            row["times"].update(fim_build=self.times["fim_build"], fim_logdet=self.times["fim_logdet"],
                                solve=est.solve_time)
            row["runs"].update(fim_build=self.runs["fim_build"], fim_logdet=self.runs["fim_logdet"],
                               solve=None if est.solve_time is None else 1)
            if est.certified is False:
                row["status"] = "uncertified"
        return row


def evaluate(graph: PoseGraph, settings: EvaluationSettings, *, step: Callable[[str], None] | None = None,
             errors: str = "raise") -> DatasetMetrics:
    """Bounds (section VII-B), the estimate, the anchored paper FIM there and its log-det.

    ``step`` is told each stage's name ("bounds", "solve", "fim") before it starts.
    ``errors="keep"``: a PosecrbError after the bounds ends the pipeline and is returned in
    ``error`` with what was computed so far; ``"raise"`` lets it through."""
    say = step or (lambda s: None)
    say("bounds")
    b = compute_bounds(graph, settings.anchor, settings.rotation_model, settings.repeat,
                       ordering=settings.ordering)
    used = dict(b.ordering)
    if settings.estimate == "none":
        return DatasetMetrics(graph=graph, bounds=b, ordering=used)
    est: Estimate | None = None
    try:
        say("solve")
        est = get_estimate(graph, settings.estimate, **settings.solver)
        say("fim")
        m_build = measure(lambda: paper_fim(graph, est.rot, est.trans, settings.anchor, settings.rotation_model,
                                            variant=settings.fim_variant), settings.repeat)
        fim = m_build.value

        def logdet() -> float:
            sym, choice = fim_symbolic_choice(fim, settings.ordering)
            used["fim"] = str(choice)
            return sym.factor_logdet(fim.matrix, name="paper FIM")[1]

        m_ld = measure(logdet, settings.repeat)
        ld = m_ld.value
    except PosecrbError as exc:
        if errors != "keep":
            raise
        return DatasetMetrics(graph=graph, bounds=b, estimate=est, error=exc, ordering=used)
    return DatasetMetrics(graph=graph, bounds=b, estimate=est, fim=fim, fim_logdet=ld,
                          times={"fim_build": m_build.seconds, "fim_logdet": m_ld.seconds},
                          runs={"fim_build": m_build.runs, "fim_logdet": m_ld.runs}, ordering=used)
