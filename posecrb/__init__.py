"""posecrb: Fisher information, Cramér-Rao bounds and D-optimality bounds for pose-graph SLAM.

The library (``__all__``) in one page:

* ``load(source)`` reads a g2o or TORO file by path or dataset name, ``parse(text)`` its content;
* ``solve``, ``bounds``, ``fim``, ``crlb``, ``select`` and ``timeline`` take a graph, a path or a name, and
  keywords named as the command-line options (snake case, same defaults; timing runs once);
* each returns a frozen dataclass with ``to_dict()`` (the command's ``--format json`` object),
  ``from_dict()``, ``to_frame()`` (pandas), ``save``/``load`` (npz) and a ``status``;
* errors derive from ``PosecrbError``; a wrong argument is an ``ArgumentError`` naming it.

Conventions: pose ids as in the file (never internal indices), natural logarithms, translations
in the file's length units, rotations in radians (3D paper model: coordinates along
``G_k / sqrt(2)``). Names are imported on first use, so ``import posecrb`` loads no numpy.

Examples
--------
>>> import posecrb
>>> res = posecrb.bounds("intel")
>>> res.dataset, res.poses, res.status.ok
('intel', 1728, True)
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._version import __version__
from .core.errors import (
    ArgumentError,
    DatasetNotFound,
    DisconnectedGraph,
    NotPositiveDefinite,
    NumericalError,
    ParseError,
    PosecrbError,
    SolverError,
    UsageError,
)

if TYPE_CHECKING:
    from .api.functions import bounds, crlb, fim, load, parse, select, solve
    from .api.results import BoundsResult, SelectResult
    from .api.timeline import timeline
    from .core.graph import PoseGraph
    from .core.status import Status
    from .incremental.result import TimelineResult
    from .models.paper.crlb import InverseAccuracy
    from .models.results import CrlbResult, FimResult
    from .solver.estimate import Estimate
    from .solver.solve import SolveResult

# name -> module that defines it, imported on first access (numpy, scipy and the models load
# only when a function or a result class is used: the command line's start-up needs none).
_LAZY = {
    "load": "api.functions", "parse": "api.functions", "solve": "api.functions", "bounds": "api.functions",
    "fim": "api.functions", "crlb": "api.functions", "select": "api.functions", "timeline": "api.timeline",
    "PoseGraph": "core.graph", "Status": "core.status", "Estimate": "solver.estimate",
    "SolveResult": "solver.solve", "BoundsResult": "api.results", "FimResult": "models.results",
    "CrlbResult": "models.results", "InverseAccuracy": "models.paper.crlb", "SelectResult": "api.results",
    "TimelineResult": "incremental.result",
}

__all__ = [
    "load", "parse", "solve", "bounds", "fim", "crlb", "select", "timeline",
    "PoseGraph", "Estimate", "SolveResult", "BoundsResult", "FimResult", "CrlbResult", "InverseAccuracy",
    "SelectResult", "TimelineResult", "Status",
    "PosecrbError", "UsageError", "ArgumentError", "ParseError", "DatasetNotFound", "DisconnectedGraph",
    "NumericalError", "NotPositiveDefinite", "SolverError",
    "__version__",
]


def __getattr__(name: str) -> Any:
    """The names of ``_LAZY`` on first use (then cached in the module's namespace)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'posecrb' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
