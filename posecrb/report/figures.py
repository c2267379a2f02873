"""Saving a matplotlib figure: the one way a figure becomes a file.

The figure functions of ``posecrb.report.plots`` draw; ``save_figure`` writes, through the output
layer (``posecrb.core.outputs.atomic_write``: a temporary renamed into place, an ``OutputError``
with the path when the system refuses). Importing this module imports no matplotlib (the command
line's path options read ``FIGURE_EXTENSIONS`` from here at start-up).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..core.outputs import atomic_write, check_extension, escape_surrogates

# The format follows the extension; matplotlib writes each without a display.
FIGURE_EXTENSIONS = (".png", ".svg", ".pdf")


def _escape_texts(fig: Any) -> None:
    """Every text of ``fig`` as valid text: a title, label or tick label built from a file name that
    is not valid UTF-8 (lone surrogates, ``os.fsdecode``) shows each undecodable byte as ``\\xNN``
    instead of failing in the font renderer. Tick labels are made by the axes' formatters only when
    the figure is drawn, so each formatter's output is escaped as it is made."""
    from matplotlib.axis import Axis  # noqa: PLC0415 -- matplotlib only for figures
    from matplotlib.text import Text  # noqa: PLC0415 -- matplotlib only for figures

    for artist in fig.findobj(Text):
        text = artist.get_text()
        if not text.isascii():
            escaped = escape_surrogates(text)
            if escaped != text:
                artist.set_text(escaped)
    for axis in fig.findobj(Axis):
        for formatter in {id(f): f for f in (axis.get_major_formatter(), axis.get_minor_formatter())}.values():
            ticks, offset = formatter.format_ticks, formatter.get_offset
            formatter.format_ticks = lambda values, ticks=ticks: [escape_surrogates(t) for t in ticks(values)]
            formatter.get_offset = lambda offset=offset: escape_surrogates(offset())


def save_figure(fig: Any, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Write a matplotlib figure through ``atomic_write``; the format follows the extension, one of
    ``FIGURE_EXTENSIONS`` (UsageError otherwise: ``x.xyz`` is never a PNG under another name). The
    figure is closed either way; SVG text stays text (searchable, smaller than glyph paths)."""
    import matplotlib.pyplot as plt  # noqa: PLC0415 -- matplotlib only for figures

    p = Path(path)
    try:
        check_extension(p, FIGURE_EXTENSIONS)
        _escape_texts(fig)
        fig.tight_layout()
        with atomic_write(p, "wb") as fh, plt.rc_context({"svg.fonttype": "none"}):
            fig.savefig(fh, dpi=dpi, format=p.suffix[1:].lower())
    finally:
        plt.close(fig)
    return p


__all__ = ["FIGURE_EXTENSIONS", "save_figure"]
