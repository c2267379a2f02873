"""Timing protocol (docs/design.md#timing-protocol): warm-up once, then the median of k repeats.

``time.perf_counter`` wraps exactly the callable; callers document what is inside.
"""
from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import TypeVar

from .errors import UsageError

T = TypeVar("T")


def timed(fn: Callable[[], T], repeat: int = 1, warmup: bool = True) -> tuple[T, float]:
    """Run ``fn`` (once more first if ``warmup`` and repeat > 1) and return its last value and
    the median wall time over ``repeat`` runs, in seconds."""
    if repeat < 1:
        raise UsageError("repeat must be >= 1")
    if warmup and repeat > 1:
        fn()
    times, value = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return value, statistics.median(times)  # type: ignore[return-value]
