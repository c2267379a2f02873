"""What the machine can give a run: available memory, and checks of a request against it.

Options whose cost grows with their value (``datasets synth --poses``, ``experiment ... --trials``)
and inputs whose reading grows with their size (``posecrb.core.inputs.read_input``) are checked
against the memory available *before* the work starts, so that a request the machine cannot honour
is a usage error with the estimate, never a ``MemoryError`` (or the OOM killer) after minutes.
"""
from __future__ import annotations

import os

from .errors import UsageError

GIB = 1024 ** 3


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation without swapping (Linux ``MemAvailable``;
    elsewhere the physical memory), or None when the system does not say."""
    try:
        with open("/proc/meminfo", "rb") as fh:
            for line in fh:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError, AttributeError):
        return None


def format_bytes(n: float) -> str:
    """``1.5 GiB``, ``320 MiB``, ``12 KiB``, ``900 B``."""
    for unit, size in (("GiB", GIB), ("MiB", 1024 ** 2), ("KiB", 1024)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} B"


def check_memory(needed: float, what: str, hint: str | None = None) -> None:
    """UsageError (exit 2) when ``needed`` bytes exceed the available memory.

    ``what`` names the request (``"--poses 100000000000"``); the message gives the estimate and
    what is available. Where the system does not report its memory, nothing is refused."""
    avail = available_memory()
    if avail is not None and needed > avail:
        extra = f"; {hint}" if hint else ""
        raise UsageError(f"{what} needs about {format_bytes(needed)} of memory, more than the "
                         f"{format_bytes(avail)} available{extra}")


__all__ = ["GIB", "available_memory", "check_memory", "format_bytes"]
