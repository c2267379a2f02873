"""posecrb: Fisher information, Cramér-Rao bounds and D-optimality bounds for pose-graph SLAM.

The library (``__all__``) in one page:

* ``load(source)`` reads a g2o or TORO file by path or dataset name, ``parse(text)`` its content;
* ``solve``, ``bounds``, ``fim``, ``crlb``, ``select`` and ``timeline`` take a graph, a path or a name, and
  keywords named as the command-line options (snake case, same defaults; timing runs once) with Python
  values (pose ids as a sequence, a budget as a number; each choice a ``Literal`` of
  ``posecrb.core.choices``);
* each returns a frozen dataclass with ``to_dict()`` (the command's ``--format json`` object),
  ``from_dict()``, ``to_frame()`` (pandas), ``save``/``load`` (npz) and a ``status``; results with natural
  parts hold them as typed results (``BoundsResult.bounds``, ``SelectResult.certificate``, ...);
* ``verify(graph, estimate)`` judges an estimate another program computed: is it the global optimum,
  how far from it, in map units and in units of the CRLB;
* no function writes a file: ``result.save(path)``, ``posecrb.io.write_g2o(graph, path, ...)`` and
  ``posecrb.report.plot_timeline(result, path)`` do, and refuse the files they were given;
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
    from .api.bounds import bounds
    from .api.graphs import load, parse
    from .api.models import crlb, fim
    from .api.select import select
    from .api.solve import solve
    from .api.timeline import timeline
    from .api.verify import verify
    from .core.graph import PoseGraph
    from .core.status import Status
    from .incremental.parts import LoopClosure, Monotonicity
    from .incremental.result import TimelineResult
    from .models.paper.bounds import GraphBounds
    from .models.paper.crlb import InverseAccuracy
    from .models.paper.result import BoundsResult, FimAtEstimate
    from .models.results import CrlbResult, FimResult
    from .selection.result import CertificateBounds, FixedEdges, SelectionCertificate, SelectResult
    from .solver.estimate import Estimate
    from .solver.solve import SolveResult
    from .verification.result import VerifyResult

# name -> module that defines it, imported on first access (numpy, scipy and the models load
# only when a function or a result class is used: the command line's start-up needs none).
_LAZY = {
    "load": "api.graphs", "parse": "api.graphs", "solve": "api.solve", "bounds": "api.bounds",
    "fim": "api.models", "crlb": "api.models", "select": "api.select", "timeline": "api.timeline",
    "verify": "api.verify", "VerifyResult": "verification.result",
    "PoseGraph": "core.graph", "Status": "core.status", "Estimate": "solver.estimate",
    "SolveResult": "solver.solve", "BoundsResult": "models.paper.result",
    "GraphBounds": "models.paper.bounds", "FimAtEstimate": "models.paper.result", "FimResult": "models.results",
    "CrlbResult": "models.results", "InverseAccuracy": "models.paper.crlb", "SelectResult": "selection.result",
    "FixedEdges": "selection.result", "SelectionCertificate": "selection.result",
    "CertificateBounds": "selection.result",
    "TimelineResult": "incremental.result", "LoopClosure": "incremental.parts", "Monotonicity": "incremental.parts",
}

__all__ = [
    "load", "parse", "solve", "bounds", "fim", "crlb", "select", "timeline", "verify",
    "PoseGraph", "Estimate", "SolveResult", "BoundsResult", "GraphBounds", "FimAtEstimate", "FimResult", "CrlbResult",
    "InverseAccuracy",
    "SelectResult", "FixedEdges", "SelectionCertificate", "CertificateBounds", "TimelineResult",
    "LoopClosure", "Monotonicity", "VerifyResult", "Status",
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
