"""Measurement selection: ``posecrb.select`` at 20% of the loop closures."""
from __future__ import annotations

from . import inputs
from .common import Benchmark

# objective-method: the tree objective's greedy (the default) and its relaxation; the algebraic
# connectivity's relaxation (MAC's problem, benchmarks/peers/mac_select.py).
METHODS = ("tree-greedy", "tree-relax", "fiedler-relax")
# Datasets whose candidate edges are too few for 20% to select any (select refuses such a budget):
# tinyGrid3D has three.
TOO_FEW_CANDIDATES = ("tinyGrid3D",)
INPUTS = tuple(name for name in inputs.DATASETS if name not in TOO_FEW_CANDIDATES) + inputs.GRIDS_2D


class Select(Benchmark):
    params = [INPUTS, METHODS]
    param_names = ["input", "method"]

    def setup(self, name: str, method: str) -> None:
        import posecrb

        objective, how = method.split("-")
        self.prepare(name, lambda graph: posecrb.select(graph, budget=0.2, objective=objective, method=how))

    def time_select(self, name: str, method: str) -> None:
        self.call(self.input)
