"""posecrb: Fisher information, Cramér-Rao bounds and D-optimality bounds for pose-graph SLAM."""
from .core.errors import PosecrbError
from .core.graph import PoseGraph
from .io import load

__version__ = "0.2.0"
__all__ = ["PoseGraph", "PosecrbError", "load", "__version__"]
