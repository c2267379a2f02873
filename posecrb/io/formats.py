"""The registry of pose-graph file formats, and reading and writing through it.

``FORMATS`` maps a name to its ``Format`` (``posecrb.io.g2o``, ``posecrb.io.toro``): a new line
format is a module with a record table, two decoders and a writer, registered here. Reading
never looks at the file name: the record tags decide the format (``Format.sniff``), so a TORO
file named ``x.g2o`` reads as TORO and a file mixing both families is an error at the first
line of the later one. Writing (``save``) picks the format by suffix, or by name.
"""
from __future__ import annotations

import os

import numpy as np

from ..core.errors import ArgumentError, UsageError
from ..core.graph import PoseGraph
from ..core.inputs import read_input
from .g2o import G2O
from .lines import decode_utf8
from .reader import QUATERNION_MODES, parse
from .records import Format
from .text import Fallback, scan_bytes, split_text
from .toro import TORO

FORMATS: dict[str, Format] = {fmt.name: fmt for fmt in (G2O, TORO)}

__all__ = ["FORMATS", "QUATERNION_MODES", "format_for_path", "load", "parse_bytes", "parse_text", "save"]


def load(path: str | os.PathLike, quaternions: str = "normalize") -> PoseGraph:
    """Read a g2o or TORO pose-graph file; the format is detected from its content.

    ``quaternions`` says how the g2o 3D edge quaternions (qx, qy, qz, qw) become R~:

    - ``"normalize"`` (default): ``q / |q|`` (computed after scaling q by its
      largest component, so no norm overflows or underflows) then the rotation matrix;
      every R~ is in SO(3).
    - ``"raw"``: SE-Sync's g2o reader, i.e. Eigen's ``Quaternion(qw, qx, qy, qz).toRotationMatrix()``
      applied to the quaternion AS WRITTEN (no normalisation). Files print quaternions with
      6-9 digits, so R~ is then slightly non-orthogonal (``|I - R~ R~^T|`` up to ~1e-5 on
      cubicle.g2o), and SE-Sync's objective (``posecrb.solver``, whose data matrix carries
      ``kappa I`` / ``-kappa R~`` blocks exactly as SE-Sync's) differs from the normalised
      reading by up to ~3e-5 relative. This mode exists ONLY to reproduce SE-Sync's numbers;
      the rest of posecrb (FIM, bounds, CRLB) assumes rotations and should get the default.
      A quaternion whose squared norm exceeds ``MAX_INFORMATION`` is an error in this mode.

    Either way a zero quaternion is an error, vertex quaternions (an estimate, which
    SE-Sync's reader ignores) are always normalised, and 2D/TORO files are unaffected.
    Only regular files are read (a directory, FIFO or device is an error saying so), no larger
    than the memory available allows, and a gzip-compressed file (``intel.g2o.gz``) is read
    transparently; ``sha256`` is that of the file as stored (``posecrb.core.inputs.read_input``).
    """
    inp = read_input(path)
    return parse_bytes(inp.data, path=inp.path, sha256=inp.sha256, quaternions=quaternions)


def parse_bytes(data: bytes, path: str = "<string>", sha256: str | None = None,
                quaternions: str = "normalize") -> PoseGraph:
    """Parse a file's bytes (see ``load``): the fast tokeniser where it applies, else the
    reference one, which gives the same graph and locates every error."""
    try:
        return parse(scan_bytes(data), FORMATS, path, sha256, quaternions)
    except Fallback:
        pass
    return parse(split_text(decode_utf8(data, path)), FORMATS, path, sha256, quaternions)


def parse_text(text: str, path: str = "<string>", sha256: str | None = None,
               quaternions: str = "normalize") -> PoseGraph:
    """Parse the content of a g2o/TORO file (see ``load``, also for ``quaternions``)."""
    if not isinstance(text, str):
        raise ArgumentError("text", type(text).__name__, "is not str (a file's bytes go to parse_bytes)", sep=": ")
    if text.isascii():
        try:
            return parse(scan_bytes(text.encode("ascii")), FORMATS, path, sha256, quaternions)
        except Fallback:
            pass
    return parse(split_text(text), FORMATS, path, sha256, quaternions)


def format_for_path(path: str | os.PathLike) -> Format:
    """The registered format whose suffixes include ``path``'s (case-insensitive)."""
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    for fmt in FORMATS.values():
        if suffix in fmt.suffixes:
            return fmt
    known = ", ".join(f"{s} ({fmt.name})" for fmt in FORMATS.values() for s in fmt.suffixes)
    raise UsageError(f"{os.fspath(path)}: no pose-graph format writes {suffix or 'files without a suffix'!r}; "
                     f"known suffixes: {known}")


def save(graph: PoseGraph, path: str | os.PathLike, format: str | None = None, rot: np.ndarray | None = None,
         trans: np.ndarray | None = None) -> None:
    """Write ``graph`` in ``format`` (a name in ``FORMATS``) or the format of ``path``'s suffix,
    atomically; vertices from (rot, trans) or the graph's own estimate."""
    if format is None:
        fmt = format_for_path(path)
    elif format in FORMATS:
        fmt = FORMATS[format]
    else:
        raise UsageError(f"unknown pose-graph format {format!r}; known: {', '.join(FORMATS)}")
    fmt.write(graph, os.fspath(path), rot, trans)
