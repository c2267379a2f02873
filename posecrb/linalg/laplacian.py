"""Weighted graph Laplacians assembled from edge arrays (vectorised COO, no loop over edges).

Section III-A of the paper: ``L_w^0 = A_0 Sigma_0 A_0^T`` for the incidence matrix
``A_0`` and the reduced Laplacian ``L_w`` with the anchor's row and column removed.
Parallel edges add; self-loops are rejected at parse time.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def laplacian(n: int, src: np.ndarray, dst: np.ndarray, weights: np.ndarray) -> sp.csc_matrix:
    """Full n x n weighted Laplacian ``sum_e w_e (e_i - e_j)(e_i - e_j)^T``."""
    w = np.asarray(weights, dtype=float)
    rows = np.concatenate([src, dst, src, dst])
    cols = np.concatenate([src, dst, dst, src])
    vals = np.concatenate([w, w, -w, -w])
    return sp.csc_matrix((vals, (rows, cols)), shape=(n, n))


def reduced_index(n: int, anchor: int) -> np.ndarray:
    """Map from pose index to its row in a reduced matrix; the anchor maps to -1."""
    idx = np.arange(n) - (np.arange(n) > anchor)
    idx[anchor] = -1
    return idx


def reduced_laplacian(n: int, src: np.ndarray, dst: np.ndarray, weights: np.ndarray,
                      anchor: int = 0) -> sp.csc_matrix:
    """(n-1) x (n-1) weighted Laplacian with the anchor's row and column removed."""
    w = np.asarray(weights, dtype=float)
    red = reduced_index(n, anchor)
    ri, rj = red[src], red[dst]
    rows = np.concatenate([ri, rj, ri, rj])
    cols = np.concatenate([ri, rj, rj, ri])
    vals = np.concatenate([w, w, -w, -w])
    keep = (rows >= 0) & (cols >= 0)
    return sp.csc_matrix((vals[keep], (rows[keep], cols[keep])), shape=(n - 1, n - 1))


def kron_identity(a: sp.spmatrix, k: int) -> sp.csc_matrix:
    """``a (x) I_k`` as a sparse matrix."""
    return sp.kron(a, sp.identity(k, format="csc"), format="csc") if k > 1 else sp.csc_matrix(a)
