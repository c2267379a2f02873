"""How far an estimate is from the optimum in units of the estimator's own uncertainty
(docs/design.md#verify-distance).

Both estimates are put in the anchor's gauge (``X_i <- X_a^{-1} X_i``, the gauge of ``posecrb solve``
and of the anchored paper FIM). The difference of pose i is then the paper model's tangent vector at
the optimum that reaches the estimate: the translation difference in the world frame and the body
rotation ``R_opt,i^T R_i = Exp(a_i)``, in 3D in the paper's coordinates along ``G_k / sqrt 2``
(``sqrt 2`` times the rotation vector; docs/design.md#rotation-weights). With F the anchored paper
FIM at the optimum (what ``posecrb fim`` reports, eq. 42 / 64) ``delta^T F delta`` is the squared
Mahalanobis distance of the whole estimate, about its degrees of freedom q (n - 1) for a difference
of the size of the noise; per pose, ``delta_i^T C_i^{-1} delta_i`` with ``C_i`` the CRLB's marginal
block (eq. 67, first order in 3D) is about q.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..lie.so import so3_log
from ..solver.rounding import anchor_estimate

if TYPE_CHECKING:
    from ..core.graph import PoseGraph
    from ..models.paper.fim import PaperFim


def paper_delta(rot: np.ndarray, trans: np.ndarray, opt_rot: np.ndarray, opt_trans: np.ndarray,
                anchor: int) -> np.ndarray:
    """(n, q) difference of the estimate (``rot``, ``trans``) from the optimum, per pose, in the paper
    model's coordinates (module docstring); the anchor's row is zero."""
    r1, t1 = anchor_estimate(rot, trans, anchor)
    r0, t0 = anchor_estimate(opt_rot, opt_trans, anchor)
    rel = np.swapaxes(r0, 1, 2) @ r1
    if rot.shape[1] == 2:
        angle = np.arctan2(rel[:, 1, 0], rel[:, 0, 0])[:, None]
    else:
        angle = np.sqrt(2.0) * so3_log(rel)
    return np.hstack([t1 - t0, angle])


def fim_vector(fim: PaperFim, graph: PoseGraph, per_pose: np.ndarray) -> np.ndarray:
    """``per_pose`` (n, q) laid out as the FIM's rows (``PaperFim.index_map``)."""
    ids, coord = fim.index_map()
    return per_pose[np.searchsorted(graph.ids, ids), coord]


def squared_mahalanobis(fim: PaperFim, graph: PoseGraph, delta: np.ndarray) -> float:
    """``delta^T F delta`` of the (n, q) difference ``delta`` (the anchor's row is not in F)."""
    v = fim_vector(fim, graph, delta)
    return float(v @ (fim.matrix @ v))


def pose_mahalanobis(ids: np.ndarray, blocks: np.ndarray, graph: PoseGraph, delta: np.ndarray) -> np.ndarray:
    """``delta_i^T C_i^{-1} delta_i`` of the poses ``ids`` with their marginal blocks ``C_i``
    (``blocks``, (k, q, q): the CRLB's first-order blocks, ``posecrb.models.paper.crlb.crlb_blocks``),
    by a Cholesky solve of each block (vectorised)."""
    d = delta[np.searchsorted(graph.ids, ids)]
    chol = np.linalg.cholesky(blocks)
    y = np.linalg.solve(chol, d[:, :, None])[:, :, 0]
    return np.einsum("ka,ka->k", y, y)
