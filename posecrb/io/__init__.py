"""Readers and writers for g2o and TORO pose-graph files, and safe file access.

``load(path)`` sniffs the format from the content (never the extension) and
returns a ``PoseGraph``. Parsing is vectorised: lines are grouped by tag and
each group's numeric columns are converted by numpy in one call. Every file
posecrb writes goes through ``posecrb.core.files.atomic_write``.
"""
from ..core.files import atomic_write, check_output_dir, check_output_file, read_regular_file
from .g2o import write_g2o
from .text import QUATERNION_MODES, load, parse_text

__all__ = ["QUATERNION_MODES", "atomic_write", "check_output_dir", "check_output_file", "load", "parse_text",
           "read_regular_file", "write_g2o"]
