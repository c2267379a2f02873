"""The certified solver: ``posecrb.solve`` (SE-Sync's Riemannian staircase, certificate included)."""
from __future__ import annotations

from . import inputs
from .common import Benchmark


class Solve(Benchmark):
    params = [inputs.DATASETS + inputs.GRIDS]

    def setup(self, name: str) -> None:
        import posecrb

        self.prepare(name, posecrb.solve)

    def time_solve(self, name: str) -> None:
        self.call(self.input)

    def peakmem_solve(self, name: str) -> None:
        self.call(self.input)
