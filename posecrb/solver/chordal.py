"""Chordal initialisation (SE-Sync section 4.4; Martinec & Pajdla 2007; Carlone et al. 2015).

Relax SO(d) to R^{d x d} and minimise ``sum kappa ||R_j - R_i R~_ij||_F^2`` with the
anchor's block fixed to the identity: ONE sparse Cholesky solve with the reduced
connection Laplacian L(G^rho), then project every block back to SO(d).
"""
from __future__ import annotations

import numpy as np

from ..linalg.cholesky import SymbolicCholesky
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
    symbolic = SymbolicCholesky(Lrr, mode=problem.factor_mode(d))   # d rows per pose
    factor = symbolic.factor(Lrr, name="reduced connection Laplacian L(G^rho)")
    Z = np.empty((n * d, d))
    Z[keep] = factor(np.asarray(rhs))
    Z[~keep] = np.eye(d)
    Zt = nearest_rotations(Z.reshape(n, d, d))   # blocks are R_i^T
    return np.ascontiguousarray(np.swapaxes(Zt, 1, 2))
