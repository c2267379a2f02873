"""posecrb: Fisher information, Cramér-Rao bounds and D-optimality bounds for pose-graph SLAM."""
from .errors import PosecrbError
from .graph import PoseGraph
from .io import load

__version__ = "0.1.0"
__all__ = ["PoseGraph", "PosecrbError", "load", "__version__"]
