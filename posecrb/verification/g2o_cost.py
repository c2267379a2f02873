"""The cost g2o minimises: the chi-square of a graph's own edges at an estimate (docs/design.md#g2o-cost).

For an edge i -> j with measurement Z and information matrix Omega (the file's, translation block
first), g2o's error at poses X_i, X_j is the vector of ``Z^{-1} (X_i^{-1} X_j)``:

* ``EdgeSE2``: ``(x, y, theta)`` with theta normalised to (-pi, pi];
* ``EdgeSE3``: ``(x, y, z, qx, qy, qz)``, the translation and the vector part of the unit quaternion
  with ``qw >= 0`` (about half the rotation vector),

and the cost is ``chi2 = sum_e e^T Omega e`` (g2o's ``activeChi2``). TORO files are scored the same
way on their information matrices (posecrb stores every format's translation block first). This is
not the maximum-likelihood objective of the isotropic model that ``posecrb solve`` minimises (which
keeps one precision per edge for the translation and one concentration for the rotation); GTSAM's
geodesic cost is close to it. Vectorised over the edges.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..io.rotations import rot_to_quat

if TYPE_CHECKING:
    from ..core.graph import PoseGraph


def g2o_errors(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """(m, q) g2o error vectors of every edge at the poses ``rot`` (n, d, d), ``trans`` (n, d)."""
    src, dst = graph.src, graph.dst
    rel_rot = np.swapaxes(rot[src], 1, 2) @ rot[dst]
    rel_t = np.einsum("eba,eb->ea", rot[src], trans[dst] - trans[src])
    zt = np.swapaxes(graph.rot, 1, 2)                         # Z^{-1} = (R~^T, -R~^T t~)
    delta_rot = zt @ rel_rot
    delta_t = np.einsum("eab,eb->ea", zt, rel_t - graph.trans)
    if graph.dim == 2:
        theta = np.arctan2(delta_rot[:, 1, 0], delta_rot[:, 0, 0])
        return np.column_stack([delta_t, theta])
    q = rot_to_quat(delta_rot)                                 # (x, y, z, w), w >= 0
    return np.column_stack([delta_t, q[:, :3]])


def g2o_chi2(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray) -> float:
    """g2o's total chi-square ``sum_e e^T Omega_e e`` at the poses (see the module docstring)."""
    e = g2o_errors(graph, rot, trans)
    return float(np.einsum("ea,eab,eb->", e, graph.info, e))
