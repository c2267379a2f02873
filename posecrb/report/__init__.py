"""Rendering of results: tables and files of rows (``render``, ``latex``, ``outputs``) and figures
(``plots``: ``plot_timeline(result, path)`` and the experiments' figures).

The figures load matplotlib, so they are imported on first use: ``posecrb.report.plot_timeline``
works without the command line's start-up paying for it.
"""
from __future__ import annotations

import importlib
from typing import Any

_PLOTS = ("plot_timeline", "plot_tables", "plot_crlb_sweep", "plot_octagon", "plot_thesis")


def __getattr__(name: str) -> Any:
    """The figures of ``posecrb.report.plots`` on first use."""
    if name not in _PLOTS:
        raise AttributeError(f"module 'posecrb.report' has no attribute {name!r}")
    return getattr(importlib.import_module(".plots", __name__), name)


__all__ = list(_PLOTS)
