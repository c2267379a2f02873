"""The command line's one progress display: rich bars on stderr, shown only on a terminal.

Two shapes share it: counted work (trials, selections, datasets; a transient bar that
vanishes when done) and downloads (bytes, speed; the bars stay as a record of what came in).
Off a terminal (logs, CI, pipes) the display is disabled and nothing reaches stderr.
"""
from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from rich.progress import Progress


class Advance(Protocol):
    """The callback ``progress`` yields: ``advance(k)`` counts k units done; ``description`` relabels."""

    def __call__(self, k: int = 1, description: str | None = None) -> None: ...


def progress_display(*, transfer: bool = False) -> Progress:
    """A rich ``Progress`` on stderr, disabled unless stderr is a terminal.

    ``transfer=False``: counted units (done/total, elapsed, remaining), transient.
    ``transfer=True``: bytes (size, speed, remaining), one persistent bar per task."""
    # lazy: rich's import is a noticeable part of start-up (docs/decisions/fixed-costs.md) and is
    # not needed off a terminal (see ``progress``)
    from rich.console import Console  # noqa: PLC0415
    from rich.progress import (  # noqa: PLC0415
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
    """One counted bar of ``total`` units; yields the engines' callback ``advance(k, description=None)``.

    Off a terminal the callback does nothing and rich is not even imported."""
    if not sys.stderr.isatty():
        def ignore(k: int = 1, description: str | None = None) -> None:
            return None

        yield ignore
        return
    display = progress_display()
    with display:
        task = display.add_task(label, total=total)

        def advance(k: int = 1, description: str | None = None) -> None:
            display.update(task, advance=k, description=description)

        yield advance
