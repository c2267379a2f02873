"""Timing protocol (docs/design.md#timing-protocol).

``time.perf_counter`` wraps exactly the callable; callers document what is inside. Three ways to
time one region, chosen by ``repeat``:

* ``1``: one run, no warm-up (what every library call does unless asked otherwise);
* ``k > 1``: one untimed warm-up, then the median of ``k`` runs;
* ``"auto"`` (the command line's default), like ``timeit``'s autorange: one run when it takes at
  least ``AUTO_SINGLE_PASS`` seconds (a big input is never computed twice); otherwise that first
  run was the warm-up, and timed runs follow while they fit, together with the warm-up, in
  ``AUTO_BUDGET`` seconds, at least one and at most ``AUTO_MAX_RUNS``.

Every figure comes with the number of runs it is the median of (``Timing.runs``).
"""
from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Generic, Literal, NamedTuple, TypeVar

from .errors import UsageError

T = TypeVar("T")

Repeat = int | Literal["auto"]
AUTO = "auto"
# A run this long is measured once: a second run would double the wait for a figure whose
# relative noise is already small.
AUTO_SINGLE_PASS = 1.0
# Warm-up plus timed runs of a short region stay within about this many seconds.
AUTO_BUDGET = 2.0
# Short regions stop here: a median of 5 is stable, and a command times several regions.
AUTO_MAX_RUNS = 5


class Timing(NamedTuple, Generic[T]):
    """The last value of the timed callable, the median wall time in seconds, how many timed
    runs it is the median of, and whether an untimed warm-up run preceded them."""

    value: T
    seconds: float
    runs: int
    warmup: bool


def check_repeat(repeat: Repeat) -> Repeat:
    """``repeat`` when it is ``"auto"`` or an integer >= 1; UsageError otherwise."""
    if repeat == AUTO:
        return AUTO
    if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 1:
        raise UsageError(f"repeat must be an integer >= 1 or 'auto', got {repeat!r}")
    return repeat


def _run(fn: Callable[[], T]) -> tuple[T, float]:
    t0 = time.perf_counter()
    value = fn()
    return value, time.perf_counter() - t0


def measure(fn: Callable[[], T], repeat: Repeat = 1, warmup: bool = True) -> Timing[T]:
    """Time ``fn`` by the protocol of the module docstring.

    Parameters
    ----------
    fn : callable
        The work, without arguments; its value of the last run is returned.
    repeat : int or "auto"
        1 (one run), k > 1 (warm-up, then the median of k) or ``"auto"``.
    warmup : bool
        With an integer ``repeat > 1``: whether to run ``fn`` once untimed first.

    Returns
    -------
    Timing
        ``(value, seconds, runs, warmup)``.

    Raises
    ------
    UsageError
        ``repeat`` is neither ``"auto"`` nor an integer >= 1.

    Examples
    --------
    >>> t = measure(lambda: sum(range(10)), repeat=3)
    >>> t.value, t.runs, t.warmup
    (45, 3, True)
    >>> measure(lambda: 1, repeat="auto").runs
    5
    """
    repeat = check_repeat(repeat)
    if repeat == AUTO:
        value, first = _run(fn)
        if first >= AUTO_SINGLE_PASS:
            return Timing(value, first, 1, False)
        spent, times = first, list[float]()
        while len(times) < AUTO_MAX_RUNS and (not times or spent + times[-1] <= AUTO_BUDGET):
            value, t = _run(fn)
            times.append(t)
            spent += t
        return Timing(value, statistics.median(times), len(times), True)
    assert isinstance(repeat, int)
    warm = warmup and repeat > 1
    if warm:
        fn()
    times = []
    for _ in range(repeat):
        value, t = _run(fn)
        times.append(t)
    return Timing(value, statistics.median(times), repeat, warm)


def timed(fn: Callable[[], T], repeat: Repeat = 1, warmup: bool = True) -> tuple[T, float]:
    """``measure`` reduced to (last value, median seconds)."""
    m = measure(fn, repeat, warmup)
    return m.value, m.seconds


def auto_runs(seconds: float) -> int:
    """How many timed runs ``"auto"`` makes of a region whose every run takes ``seconds``
    (documentation and tests: the number ``measure`` arrives at for a steady region)."""
    if seconds >= AUTO_SINGLE_PASS:
        return 1
    if seconds <= 0:
        return AUTO_MAX_RUNS
    fit = math.floor((AUTO_BUDGET - seconds) / seconds + 1e-9)
    return max(1, min(AUTO_MAX_RUNS, fit))
