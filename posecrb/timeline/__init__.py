"""The information timeline: D- and T-optimality of a pose graph as it grows, computed
incrementally (``timeline``), and which loop closures matter (docs/design.md#timeline)."""
from __future__ import annotations

from .compute import timeline
from .result import LoopClosure, Monotonicity, TimelineResult

__all__ = ["LoopClosure", "Monotonicity", "TimelineResult", "timeline"]
