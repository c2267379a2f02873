"""A Fisher information matrix as a scipy sparse ``.npz`` with its index map (``posecrb fim --save``)."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..core.files import atomic_write
from ..core.result import npz_path

if TYPE_CHECKING:
    import scipy.sparse as sp


def save_npz(path: str, matrix: sp.spmatrix | sp.sparray, row_ids: np.ndarray, row_coord: np.ndarray, names: list[str],
             model: str, anchors: list[int], frame: str = "mixed") -> str:
    """A scipy sparse .npz (``scipy.sparse.load_npz`` reads it) plus the index map:
    ``row_pose_id[k]`` and ``row_coordinate[k]`` (into ``coordinate_names``) for row k, and
    ``frame`` (world/body for sed, mixed for the paper model).
    Written atomically to ``npz_path(path)``, which is returned."""

    m = matrix.tocsc()
    target = npz_path(path)
    with atomic_write(target, "wb") as fh:
        np.savez(fh, data=m.data, indices=m.indices, indptr=m.indptr, format=np.array("csc"),
             shape=np.array(m.shape), row_pose_id=np.asarray(row_ids, np.int64),
             row_coordinate=np.asarray(row_coord, np.int64), coordinate_names=np.array(names),
                 model=np.array(model), anchor_ids=np.asarray(anchors, np.int64), frame=np.array(frame))
    return target
