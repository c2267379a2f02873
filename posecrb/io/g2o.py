"""g2o writer: original ids, every edge, vertices from an estimate (written atomically)."""
from __future__ import annotations

import io
import os

import numpy as np

from ..core.errors import UsageError
from ..core.files import atomic_write
from ..core.graph import PoseGraph
from ..lie.so import so2_log
from .rotations import rot_to_quat


def _fmt_rows(arr: np.ndarray) -> list[str]:
    buf = io.StringIO()
    np.savetxt(buf, arr, fmt="%.17g")
    return buf.getvalue().splitlines()


def write_g2o(graph: PoseGraph, path: str | os.PathLike, rot: np.ndarray | None = None,
              trans: np.ndarray | None = None) -> None:
    """Write ``graph`` as a g2o file; vertices from (rot, trans) or the graph's own estimate.

    Information matrices are written in g2o order whatever the input format was. Ids are
    written from the int64 ids as read (never through float64). The file is replaced
    atomically (``posecrb.core.files.atomic_write``): a failure or a signal leaves the previous
    file, if any, and no temporary.
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
    lines: list[str] = []
    if vcols is not None:
        lines += [f"{vtag} {i} {row}" for i, row in zip(graph.ids, _fmt_rows(vcols))]
    lines += [f"{etag} {i} {j} {row}" for i, j, row in
              zip(graph.ids[graph.src], graph.ids[graph.dst], _fmt_rows(ecols))]
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
