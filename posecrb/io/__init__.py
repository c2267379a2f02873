"""Readers and writers for g2o and TORO pose-graph files.

``load(path)`` sniffs the format from the content (never the extension) and
returns a ``PoseGraph``. Parsing is vectorised: lines are grouped by tag and
each group's numeric columns are converted by numpy in one call.
"""
from .reader import QUATERNION_MODES, load, parse_text
from .g2o import write_g2o

__all__ = ["QUATERNION_MODES", "load", "parse_text", "write_g2o"]
