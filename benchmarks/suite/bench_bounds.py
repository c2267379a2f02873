"""D-optimality: ``posecrb.bounds`` graph-only and at the file's vertices, and ``posecrb.timeline``."""
from __future__ import annotations

from . import inputs
from .common import Benchmark


class BoundsGraphOnly(Benchmark):
    """lb, ub, ub_lambda, Lemma 4's gap and T-optimality: ``bounds(graph, estimate=None)``."""

    params = [inputs.DATASETS + inputs.GRIDS]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.bounds(graph, estimate=None))

    def time_bounds(self, name: str) -> None:
        self.call(self.input)

    def peakmem_bounds(self, name: str) -> None:
        self.call(self.input)


class BoundsAtVertices(BoundsGraphOnly):
    """The same and the FIM's log-det with its accuracy bound at the file's vertices."""

    params = [inputs.WITH_VERTICES + inputs.GRIDS]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.bounds(graph, estimate="vertices"))


class Timeline(Benchmark):
    """Every prefix of the graph, graph-only (``timeline(graph, estimate=None)``); compare with
    ``BoundsGraphOnly`` on the same input (one ``bounds`` of the whole graph)."""

    params = [(inputs.GRID_2D_SMALL,) if inputs.QUICK else ("city10000", "sphere2500", "grid2d-100000")]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, lambda graph: posecrb.timeline(graph, estimate=None))

    def time_timeline(self, name: str) -> None:
        self.call(self.input)
