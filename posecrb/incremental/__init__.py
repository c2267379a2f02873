"""Incremental computations on a growing pose graph: the information timeline (``timeline``), the
D- and T-optimality of every prefix and which loop closures matter (docs/design.md#timeline).

The package is not called ``timeline`` so that a top-level ``posecrb.timeline`` function can exist
beside it (a subpackage of that name would replace the attribute when imported)."""
from __future__ import annotations

from .compute import timeline
from .parts import LoopClosure, Monotonicity, TimelineRows
from .result import TimelineResult

__all__ = ["LoopClosure", "Monotonicity", "TimelineResult", "TimelineRows", "timeline"]
