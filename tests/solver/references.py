"""Dense references for the relaxed problem's data matrices, built edge by edge from SE-Sync section 4.1."""
from __future__ import annotations

import numpy as np


def dense_M(graph):
    """M = sum_e [tau z z^T (translation rows) ; kappa (rotation residual)] built edge by edge (loops on purpose)."""
    n, d = graph.n, graph.dim
    N = n + d * n
    M = np.zeros((N, N))
    for e in range(graph.m):
        i, j = graph.src[e], graph.dst[e]
        tau, kap = graph.tau[e], graph.kappa[e]
        # translation residual t_j - t_i - R_i t~ = X z with X = [t R]
        z = np.zeros(N)
        z[j] += 1
        z[i] -= 1
        z[n + d * i: n + d * i + d] -= graph.trans[e]
        M += tau * np.outer(z, z)
        # rotation residual R_j - R_i R~ = X Z with Z: (N x d)
        Zr = np.zeros((N, d))
        Zr[n + d * j: n + d * j + d] = np.eye(d)
        Zr[n + d * i: n + d * i + d] -= graph.rot[e]
        M += kap * Zr @ Zr.T
    return M


def dense_Q(graph):
    n = graph.n
    M = dense_M(graph)
    Lt, V, C = M[:n, :n], M[:n, n:], M[n:, n:]
    return C - V.T @ np.linalg.pinv(Lt) @ V
