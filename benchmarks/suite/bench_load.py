"""Reading a file: ``posecrb.load`` (read, SHA-256, tokenise, decode, check).

Besides the datasets and the scaling grids, the full suite reads the 2D grid of a million poses
(330 MB, well within a benchmark's budget of a minute): the reader's own scaling, where no other
command of the suite goes.
"""
from __future__ import annotations

from . import inputs
from .common import Benchmark

# Inputs only this benchmark reads (the others would take minutes on them).
LOAD_ONLY = () if inputs.QUICK else ("grid2d-1000000",)


class Load(Benchmark):
    params = [inputs.DATASETS + inputs.GRIDS + LOAD_ONLY]

    def setup(self, name: str) -> None:
        import posecrb

        self.path = inputs.path(name)
        self.load = posecrb.load
        self.warm_up(name, lambda graph: None)

    def time_load(self, name: str) -> None:
        self.load(self.path)

    def peakmem_load(self, name: str) -> None:
        self.load(self.path)
