"""The command line's one progress display: rich bars on stderr, shown only on a terminal.

Two shapes share it: counted work (trials, selections, datasets; a transient bar that
vanishes when done) and downloads (bytes, speed; the bars stay as a record of what came in).
Off a terminal (logs, CI, pipes) the display is disabled and nothing reaches stderr.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Protocol

from rich.console import Console
from rich.progress import (
    BarColumn,
    DownloadColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
    TransferSpeedColumn,
)


class Advance(Protocol):
    """The callback ``progress`` yields: ``advance(k)`` counts k units done; ``description`` relabels."""

    def __call__(self, k: int = 1, description: str | None = None) -> None: ...


def progress_display(*, transfer: bool = False) -> Progress:
    """A rich ``Progress`` on stderr, disabled unless stderr is a terminal.

    ``transfer=False``: counted units (done/total, elapsed, remaining), transient.
    ``transfer=True``: bytes (size, speed, remaining), one persistent bar per task."""
    console = Console(stderr=True)
    columns: tuple[ProgressColumn, ...]
    if transfer:
        columns = (DownloadColumn(), TransferSpeedColumn(), TimeRemainingColumn())
    else:
        columns = (MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn())
    return Progress(TextColumn("{task.description}"), BarColumn(), *columns, console=console,
                    transient=not transfer, disable=not console.is_terminal)


@contextlib.contextmanager
def progress(total: int, label: str) -> Iterator[Advance]:
    """One counted bar of ``total`` units; yields the engines' callback ``advance(k, description=None)``."""
    display = progress_display()
    with display:
        task = display.add_task(label, total=total)

        def advance(k: int = 1, description: str | None = None) -> None:
            display.update(task, advance=k, description=description)

        yield advance
