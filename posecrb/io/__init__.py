"""Readers and writers of pose-graph files, one module per format behind a small registry.

``load(path)`` finds the format from the content (never the extension) and returns a checked
``PoseGraph``; ``save(graph, path)`` writes the format of the suffix. Modules: ``formats``
(the registry, ``load``, ``save``), ``g2o`` and ``toro`` (record tables, field decoders,
writers), ``reader`` (the format-independent checks), ``text`` (fields, numbers, limits; a
vectorised tokeniser and the reference one), ``decimals`` (decimal tokens to float64 and int64,
vectorised and correctly rounded), ``lines`` (the line rules of every text input, and
``read_lines``), ``records`` (what a format is), ``rotations`` (quaternions, Euler angles). Files
are read through ``posecrb.core.inputs`` and written through ``posecrb.core.outputs.atomic_write``.
"""
from .formats import FORMATS, QUATERNION_MODES, format_for_path, load, parse_bytes, parse_text, save
from .g2o import write_g2o
from .toro import write_toro

__all__ = ["FORMATS", "QUATERNION_MODES", "format_for_path", "load", "parse_bytes", "parse_text", "save", "write_g2o",
           "write_toro"]
