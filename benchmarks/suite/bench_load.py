"""Reading a file: ``posecrb.load`` (read, SHA-256, tokenise, decode, check)."""
from __future__ import annotations

from . import inputs
from .common import Benchmark


class Load(Benchmark):
    params = [inputs.DATASETS + inputs.GRIDS]

    def setup(self, name: str) -> None:
        import posecrb

        self.path = inputs.path(name)
        self.load = posecrb.load
        self.warm_up(name, lambda graph: None)

    def time_load(self, name: str) -> None:
        self.load(self.path)

    def peakmem_load(self, name: str) -> None:
        self.load(self.path)
