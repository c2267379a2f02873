"""The g2o format: record table, field decoding and the writer (docs/design.md#formats).

``VERTEX_SE2 id x y theta``, ``EDGE_SE2 i j dx dy dtheta`` + the upper triangle of the 3x3
information row by row; ``VERTEX_SE3:QUAT id x y z qx qy qz qw``, ``EDGE_SE3:QUAT i j x y z qx qy
qz qw`` + the 21 upper-triangular entries row by row, order (x, y, z, rx, ry, rz).
"""
from __future__ import annotations

import io
import logging
import os

import numpy as np

from ..core.arguments import refuse_inputs
from ..core.errors import ParseError, UsageError
from ..core.graph import PoseGraph
from ..core.outputs import atomic_write
from ..lie.so import so2_exp, so2_log
from .records import Format, RecordKind
from .rotations import quat_to_rot, rot_to_quat
from .text import MAX_INFORMATION, fmt_number

log = logging.getLogger("posecrb")

# The smallest normal double; below it a number keeps fewer significant bits (spacing 2^-1074).
_TINY = float(np.finfo(float).tiny)
_SUBNORMAL_SPACING = 5e-324

RECORDS: dict[str, RecordKind] = {r.tag: r for r in [
    RecordKind("VERTEX_SE2", "g2o", 2, "vertex", 4),          # id x y theta
    RecordKind("EDGE_SE2", "g2o", 2, "edge", 11),             # i j dx dy dth + I11 I12 I13 I22 I23 I33
    RecordKind("VERTEX_SE3:QUAT", "g2o", 3, "vertex", 8),     # id x y z qx qy qz qw
    RecordKind("EDGE_SE3:QUAT", "g2o", 3, "edge", 30),        # i j x y z qx qy qz qw + 21
]}


def _quaternions(path: str, q: np.ndarray, lines: np.ndarray, tag: str, normalize: bool = True) -> np.ndarray:
    # Scale by the largest |component| first: q / s has components in [-1, 1] and norm in
    # [1, 2], so the normalisation neither overflows (1e308 1e308 0 0) nor underflows.
    s = np.max(np.abs(q), axis=1)
    bad = np.flatnonzero(~(s > 0))
    if bad.size:
        raise ParseError(path, int(lines[bad[0]]), f"{tag}: zero quaternion")
    sub = np.flatnonzero(s < _TINY)
    if sub.size:
        # Every component is subnormal: read from the file, each was rounded to a multiple of
        # 2^-1074, so the direction q/|q| (the rotation) is only known to that spacing over |q|.
        k = int(sub[0])
        rel = _SUBNORMAL_SPACING / float(s[k])
        log.warning("%s:%d: %s: %d quaternion(s) whose components are all subnormal (largest |q_i| = %s, below "
                    "%.3g): read to a relative precision of only about %.1g, so the rotation is that inaccurate; "
                    "write quaternions normalised", path, int(lines[k]), tag, sub.size, fmt_number(s[k]), _TINY,
                    rel)
    qs = q / s[:, None]
    ns = np.linalg.norm(qs, axis=1)
    if normalize:
        return quat_to_rot(qs / ns[:, None])
    # quat_to_rot is Eigen's toRotationMatrix formula (1 - 2(y^2 + z^2), 2(xy - zw), ...),
    # so the unnormalised input gives SE-Sync's R~ (load(..., quaternions="raw")).
    with np.errstate(over="ignore"):
        norm2 = (s * ns) ** 2
    big = np.flatnonzero(~(norm2 <= MAX_INFORMATION))
    if big.size:
        k = big[0]
        raise ParseError(path, int(lines[k]), f"{tag}: quaternion norm {fmt_number(s[k] * ns[k])} is too large to "
                                              "be used unnormalised (SE-Sync-compatible reading)")
    return quat_to_rot(q)


def decode_edges(path: str, rec: RecordKind, vals: np.ndarray, lines: np.ndarray,
                 normalize: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Edge rotations (angle or quaternion, see ``posecrb.io.load`` for ``normalize``) and
    information upper triangles, already in g2o order."""
    if rec.dim == 2:
        return so2_exp(vals[:, 2]), vals[:, 3:9]
    return _quaternions(path, vals[:, 3:7], lines, rec.tag, normalize), vals[:, 7:28]


def decode_vertices(path: str, rec: RecordKind, vals: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Vertex rotations; vertex quaternions (an estimate) are always normalised."""
    if rec.dim == 2:
        return so2_exp(vals[:, 2])
    return _quaternions(path, vals[:, 3:7], lines, rec.tag)


def format_rows(arr: np.ndarray) -> list[str]:
    """Rows of ``arr`` with 17 significant digits (which identify a double uniquely)."""
    buf = io.StringIO()
    np.savetxt(buf, arr, fmt="%.17g")
    return buf.getvalue().splitlines()


def write_lines(path: str | os.PathLike, vtag: str, etag: str, graph: PoseGraph, vcols: np.ndarray | None,
                ecols: np.ndarray) -> None:
    """One line per vertex (when ``vcols``) then per edge, ids as read (int64, never through
    float64), written atomically (``posecrb.core.outputs.atomic_write``); never onto the file the
    graph was read from (``ArgumentError``)."""
    refuse_inputs("path", path, (graph.path,))
    lines: list[str] = []
    if vcols is not None:
        lines += [f"{vtag} {i} {row}" for i, row in zip(graph.ids, format_rows(vcols))]
    lines += [f"{etag} {i} {j} {row}" for i, j, row in
              zip(graph.ids[graph.src], graph.ids[graph.dst], format_rows(ecols))]
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def write_g2o(graph: PoseGraph, path: str | os.PathLike, rot: np.ndarray | None = None,
              trans: np.ndarray | None = None) -> None:
    """Write ``graph`` as a g2o file; vertices from (rot, trans) or the graph's own estimate.

    Information matrices are written in g2o order whatever the input format was. Ids are
    written from the int64 ids as read (never through float64). The file is replaced
    atomically (``posecrb.core.outputs.atomic_write``): a failure or a signal leaves the previous
    file, if any, and no temporary. ``path`` is never the file ``graph`` was read from (its
    ``path``, also that of a graph derived from it, such as ``SelectResult.pruned_graph``): that is
    an ``ArgumentError`` and nothing is written.
    """
    rot = graph.vertex_rot if rot is None else rot
    trans = graph.vertex_trans if trans is None else trans
    if (rot is None) != (trans is None):
        raise UsageError("write_g2o: vertex rotations and translations must be given together")
    iu = np.triu_indices(graph.q)
    info = graph.info[:, iu[0], iu[1]]
    if graph.dim == 2:
        vtag, etag = "VERTEX_SE2", "EDGE_SE2"
        vcols = None if rot is None or trans is None else np.column_stack([trans, so2_log(rot)])
        ecols = np.column_stack([graph.trans, so2_log(graph.rot), info])
    else:
        vtag, etag = "VERTEX_SE3:QUAT", "EDGE_SE3:QUAT"
        vcols = None if rot is None or trans is None else np.column_stack([trans, rot_to_quat(rot)])
        ecols = np.column_stack([graph.trans, rot_to_quat(graph.rot), info])
    write_lines(path, vtag, etag, graph, vcols, ecols)


G2O = Format(name="g2o", suffixes=(".g2o",), records=RECORDS, decode_edges=decode_edges,
             decode_vertices=decode_vertices, write=write_g2o)
