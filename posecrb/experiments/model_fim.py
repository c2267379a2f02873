"""The Fisher information of the Monte Carlo model (eq. 80) with frame-consistent coordinates.

Why this exists: in 3D the paper's FIM (eq. 64, ``posecrb.fim.paper_fim``) combines
translation/rotation cross terms and Psi_i written for a *right* (body-frame)
perturbation ``R_i Exp(delta_i)`` (eq. 54, 63: ``u = R_i^T (x_j - x_i)``) with a
rotation Laplacian ``L_w (x) I_3`` whose identity off-diagonal blocks hold only for
*left* (world-frame) perturbations. Under right perturbations the relative rotation
``R_i^T R_j`` moves as ``R_ij Exp(delta_j - R_ij^T delta_i)``, so the rotation
coupling of edge (i, j) is the connection-Laplacian block ``-w R_ij`` (``R_ij = R_i^T R_j``),
not ``-w I``. Both matrices have the same trace (T-optimality is unaffected) and the
same rotation-only log det at a consistent estimate, but their inverses differ once
the poses are rotated relative to each other: on tinyGrid3D at k_c = 20 the paper's
trace(F^{-1}) is about 3x smaller than the Monte Carlo MSE of the certified MLE,
while the consistent FIM below matches it (ratio ~0.97). In 2D rotations commute and
both are identical.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ..fim import PaperFim, paper_fim
from ..graph import PoseGraph
from ..laplacian import reduced_index
from ..noise import rotation_weight


def frame_consistent_fim(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0,
                         rotation_model: str = "eq59") -> PaperFim:
    """The anchored FIM of the isotropic model with every pose perturbed on the right.

    Same layout ("blocks") and coordinates as ``paper_fim`` (rotation along
    ``R_i E_k``, ``E_k = G_k / sqrt 2``); only the off-diagonal rotation blocks change
    from ``-w_ij I_3`` to ``-w_ij R_i^T R_j`` (block (i, j)) and its transpose (block (j, i)).
    """
    fim = paper_fim(graph, rot, trans, anchor=anchor, rotation_model=rotation_model, layout="blocks")
    if graph.dim == 2:
        return fim
    d, dr, npf = 3, 3, graph.n - 1
    red = reduced_index(graph.n, anchor)
    ri, rj = red[graph.src], red[graph.dst]
    both = (ri >= 0) & (rj >= 0)
    rot = np.asarray(rot, float)
    rij = np.swapaxes(rot[graph.src[both]], 1, 2) @ rot[graph.dst[both]]
    w = rotation_weight(graph.kappa, 3, rotation_model)[both]
    delta = -w[:, None, None] * (rij - np.eye(3))                   # (k, 3, 3) change of block (i, j)
    base = npf * d
    a = np.arange(dr)
    rows_i = base + ri[both][:, None] * dr + a[None, :]               # (k, 3)
    rows_j = base + rj[both][:, None] * dr + a[None, :]
    r = np.concatenate([np.repeat(rows_i, dr, 1).ravel(), np.repeat(rows_j, dr, 1).ravel()])
    c = np.concatenate([np.tile(rows_j, (1, dr)).ravel(), np.tile(rows_i, (1, dr)).ravel()])
    v = np.concatenate([delta.ravel(), np.swapaxes(delta, 1, 2).ravel()])
    size = fim.matrix.shape[0]
    mat = (fim.matrix + sp.csc_matrix((v, (r, c)), shape=(size, size))).tocsc()
    mat.sum_duplicates()
    mat.sort_indices()
    return replace(fim, matrix=mat, rotation_model=f"{rotation_model}+consistent")


def model_crlb(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0):
    """CRLB (trace, split, 3D curvature term eq. 68) from ``frame_consistent_fim``."""
    from ..crlb import crlb_from_fim

    return crlb_from_fim(frame_consistent_fim(graph, rot, trans, anchor), graph)
