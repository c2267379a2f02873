"""Readers and writers of pose-graph files, one module per format behind a small registry.

``load(path)`` finds the format from the content (never the extension) and returns a checked
``PoseGraph``; ``save(graph, path)`` writes the format of the suffix. Modules: ``formats``
(the registry, ``load``, ``save``), ``g2o`` and ``toro`` (record tables, field decoders,
writers), ``reader`` (the format-independent checks), ``text`` (lines, fields, numbers, limits;
a vectorised tokeniser and the reference one), ``records`` (what a format is), ``rotations``
(quaternions, Euler angles). Every file posecrb writes goes through
``posecrb.core.files.atomic_write``.
"""
from ..core.files import atomic_write, check_output_dir, check_output_file, read_regular_file
from .formats import FORMATS, QUATERNION_MODES, format_for_path, load, parse_bytes, parse_text, save
from .g2o import write_g2o
from .toro import write_toro

__all__ = ["FORMATS", "QUATERNION_MODES", "atomic_write", "check_output_dir", "check_output_file",
           "format_for_path", "load", "parse_bytes", "parse_text", "read_regular_file", "save", "write_g2o",
           "write_toro"]
