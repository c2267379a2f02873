"""The TORO format: record table, field decoding and the writer (docs/design.md#formats).

``VERTEX2 id x y theta``, ``EDGE2 i j dx dy dtheta I11 I12 I22 I33 I13 I23`` (TORO's order, not
g2o's); ``VERTEX3 id x y z roll pitch yaw``, ``EDGE3 i j x y z roll pitch yaw`` + 21
upper-triangular entries row by row, R = Rz(yaw) Ry(pitch) Rx(roll).
"""
from __future__ import annotations

import os

import numpy as np

from ..core.graph import PoseGraph
from ..lie.so import so2_exp, so2_log
from .g2o import write_lines
from .records import Format, RecordKind
from .rotations import euler_to_rot, rot_to_euler

RECORDS: dict[str, RecordKind] = {r.tag: r for r in [
    RecordKind("VERTEX2", "toro", 2, "vertex", 4),            # id x y theta
    RecordKind("EDGE2", "toro", 2, "edge", 11),               # i j dx dy dth + I11 I12 I22 I33 I13 I23
    RecordKind("VERTEX3", "toro", 3, "vertex", 7),            # id x y z roll pitch yaw
    RecordKind("EDGE3", "toro", 3, "edge", 29),               # i j x y z roll pitch yaw + 21
]}

# TORO's EDGE2 stores the information matrix as I11 I12 I22 I33 I13 I23 (TORO's
# posegraph2.cpp); position in that list of each upper-triangular entry (r, c).
TORO2_INFO_ORDER = {(0, 0): 0, (0, 1): 1, (1, 1): 2, (2, 2): 3, (0, 2): 4, (1, 2): 5}
_G2O_FROM_TORO2 = [TORO2_INFO_ORDER[(int(r), int(c))] for r, c in zip(*np.triu_indices(3))]   # column k of g2o's order
_TORO2_FROM_G2O = list(np.argsort(_G2O_FROM_TORO2))


def decode_edges(path: str, rec: RecordKind, vals: np.ndarray, lines: np.ndarray,
                 normalize: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Edge rotations (angle or Euler angles) and information upper triangles in g2o order."""
    if rec.dim == 2:
        return so2_exp(vals[:, 2]), vals[:, 3:9][:, _G2O_FROM_TORO2]
    return euler_to_rot(vals[:, 3], vals[:, 4], vals[:, 5]), vals[:, 6:27]


def decode_vertices(path: str, rec: RecordKind, vals: np.ndarray, lines: np.ndarray) -> np.ndarray:
    if rec.dim == 2:
        return so2_exp(vals[:, 2])
    return euler_to_rot(vals[:, 3], vals[:, 4], vals[:, 5])


def write_toro(graph: PoseGraph, path: str | os.PathLike, rot: np.ndarray | None = None,
               trans: np.ndarray | None = None) -> None:
    """Write ``graph`` as a TORO file (the inverse of reading one), as ``write_g2o`` does for g2o:
    vertices from (rot, trans) or the graph's own estimate, ids as read, written atomically.
    3D rotations become Euler angles, so they come back to within a few ulps."""
    rot = graph.vertex_rot if rot is None else rot
    trans = graph.vertex_trans if trans is None else trans
    iu = np.triu_indices(graph.q)
    info = graph.info[:, iu[0], iu[1]]
    if graph.dim == 2:
        vtag, etag = "VERTEX2", "EDGE2"
        vcols = None if rot is None or trans is None else np.column_stack([trans, so2_log(rot)])
        ecols = np.column_stack([graph.trans, so2_log(graph.rot), info[:, _TORO2_FROM_G2O]])
    else:
        vtag, etag = "VERTEX3", "EDGE3"
        vcols = None if rot is None or trans is None else np.column_stack([trans, rot_to_euler(rot)])
        ecols = np.column_stack([graph.trans, rot_to_euler(graph.rot), info])
    write_lines(path, vtag, etag, graph, vcols, ecols)


TORO = Format(name="toro", suffixes=(".graph", ".toro"), records=RECORDS, decode_edges=decode_edges,
              decode_vertices=decode_vertices, write=write_toro)
