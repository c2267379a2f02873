"""Signals of the command line: SIGTERM becomes an exception, so every clean-up runs.

By default SIGTERM kills the process at once: a temporary being written stays behind, a folder
output being staged stays half-built next to its folder. ``main`` (``posecrb.cli``) runs every
command inside ``handle_sigterm``, which turns SIGTERM into the exception ``Terminated`` in the main
thread; the output layer's ``finally`` and ``except BaseException`` blocks then remove what they
were writing, and ``main`` exits with 128 + the signal number. SIGINT is Python's
``KeyboardInterrupt`` already. The output layer itself holds signals only while it swaps a folder
in (``posecrb.core.folders.deferred_signals``).
"""
from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator

_MAIN_PID: int | None = None


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM (installed by ``handle_sigterm``) so that every
    ``finally`` and output clean-up runs before the process exits."""

    def __init__(self, signum: int = signal.SIGTERM):
        self.signum = signum
        super().__init__(f"terminated by signal {signum}")


def _on_sigterm(signum, frame):  # pragma: no cover - exercised in a subprocess test
    if os.getpid() != _MAIN_PID:
        # A forked worker (process pool) inherited the handler: die as SIGTERM intends.
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    raise Terminated(signum)


@contextlib.contextmanager
def handle_sigterm() -> Iterator[None]:
    """While active (main thread only), SIGTERM raises ``Terminated`` instead of killing the
    process outright, so temporaries are removed and partial downloads discarded."""
    global _MAIN_PID

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _MAIN_PID = os.getpid()
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except (ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


__all__ = ["Terminated", "handle_sigterm"]
