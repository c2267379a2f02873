"""Chordal initialisation (SE-Sync section 4.4; Martinec & Pajdla 2007; Carlone et al. 2015).

Relax SO(d) to R^{d x d} and minimise ``sum kappa ||R_j - R_i R~_ij||_F^2`` with the
anchor's block fixed to the identity: ONE sparse Cholesky solve with the reduced
connection Laplacian L(G^rho), then project every block back to SO(d).
"""
from __future__ import annotations

import numpy as np

from ..linalg.ordering import solver_symbolic
from ..linalg.threads import factorization_threads
from .problem import Problem
from .stiefel import nearest_rotations


def chordal_rotations(problem: Problem, anchor: int = 0) -> np.ndarray:
    """(n, d, d) rotations R_i (anchor = I) from the relaxed least-squares solution."""
    n, d = problem.n, problem.d
    L = problem.conlap.tocsc()
    keep = np.ones(n * d, bool)
    keep[anchor * d:(anchor + 1) * d] = False
    Lrr = L[keep][:, keep]
    rhs = -(L[keep][:, ~keep] @ np.eye(d))   # Z_anchor = I_d
    # d rows per pose; on large graphs the pose graph's nested dissection that M_red uses too, and
    # CHOLMOD's BLAS threads, as for M_red (posecrb.linalg.threads)
    symbolic = solver_symbolic(Lrr, d, n, mode=problem.factor_mode(d), pose_of_row=np.repeat(np.arange(n), d)[keep],
                               pose_order=problem.pose_order())
    with factorization_threads():
        factor = symbolic.factor(Lrr, name="reduced connection Laplacian L(G^rho)")
    Z = np.empty((n * d, d))
    Z[keep] = factor(np.asarray(rhs))
    Z[~keep] = np.eye(d)
    Zt = nearest_rotations(Z.reshape(n, d, d))   # blocks are R_i^T
    return np.ascontiguousarray(np.swapaxes(Zt, 1, 2))
