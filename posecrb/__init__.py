"""posecrb: Fisher information, Cramér-Rao bounds and D-optimality bounds for pose-graph SLAM."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .core.errors import PosecrbError

if TYPE_CHECKING:
    from .core.graph import PoseGraph
    from .io import load

__version__ = "0.2.0"
__all__ = ["PoseGraph", "PosecrbError", "__version__", "load"]


def __getattr__(name: str) -> Any:
    """``PoseGraph`` and ``load`` on first use: importing them loads numpy and scipy, which the
    command line's start-up (``posecrb --help``, ``posecrb.cli``) does not need."""
    if name == "PoseGraph":
        from .core.graph import PoseGraph  # noqa: PLC0415 -- lazy: start-up time (numpy)
        return PoseGraph
    if name == "load":
        from .io import load  # noqa: PLC0415 -- lazy: start-up time (numpy)
        return load
    raise AttributeError(f"module 'posecrb' has no attribute {name!r}")
