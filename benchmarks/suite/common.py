"""What every benchmark class of the suite shares: asv's sampling settings and the warm-up."""
from __future__ import annotations

import logging

from . import inputs


class Benchmark:
    """asv's settings for calls of 10 ms to a minute: one call per sample, at most five samples
    within 30 s, one process per benchmark (``rounds``), no timed warm-up (``setup`` warms up on a
    small grid instead: the lazy imports and numba's compiled kernels are not what is measured)."""

    number = 1
    repeat = (1, 5, 30.0)
    rounds = 1
    warmup_time = 0.0
    timeout = 900.0
    params: list[tuple[str, ...]] = []
    param_names = ["input"]

    def warm_up(self, name: str, call) -> None:
        """``call(graph)`` once on the 64-pose grid (8 x 8 or 4 x 4 x 4) of ``name``'s dimension."""
        import posecrb

        logging.getLogger("posecrb").setLevel(logging.ERROR)
        small = inputs.grid_file(inputs.dimension(name), 64)
        call(posecrb.load(small))

    def prepare(self, name: str, call) -> None:
        """Set up a benchmark of ``call(graph)``: the warm-up, then the input's graph, read once per
        benchmark process (neither is timed)."""
        import posecrb

        self.call = call
        self.warm_up(name, call)
        self.input = posecrb.load(inputs.path(name))
