"""Compiled kernels of the incremental greedy (``posecrb.selection.greedy``): Woodbury downdates of
every candidate's ``H_f`` after an edge is added, and the fused steps of the one-Laplacian greedy.

They build on the path-restricted Cholesky primitives of ``posecrb.linalg.pathchol`` (reach,
forward solve along it, backward solve, rank-one update along it). Compiled with numba
(``cache=True``) like those; numba's cache is keyed on this file only, so after a change to those
primitives the cache of this module must be cleared too (``__pycache__/*.nbi``, ``*.nbc``).
"""
from __future__ import annotations

import numpy as np

from ..linalg.pathchol import _backward1, _forward, _rank_one_path, _reach, njit


@njit(cache=True, nogil=True)
def woodbury_downdate(h, u, rows, valid, alive, z, inv):  # pragma: no cover - compiled
    """``H_f <- H_f - C_f inv C_f^T`` with ``C_f = U_f^T Z[rows_f]`` for every alive f.

    h (c, r, r), u (c, p, r), rows/valid (c, p), alive (c,), z (n, r), inv (r, r)."""
    c, p, r = u.shape
    cf = np.empty((r, r))
    tmp = np.empty((r, r))
    for f in range(c):
        if not alive[f]:
            continue
        for a in range(r):
            for b in range(r):
                cf[a, b] = 0.0
        for t in range(p):
            if valid[f, t]:
                row = rows[f, t]
                for a in range(r):
                    ua = u[f, t, a]
                    if ua != 0.0:
                        for b in range(r):
                            cf[a, b] += ua * z[row, b]
        for a in range(r):
            for b in range(r):
                v = 0.0
                for t in range(r):
                    v += cf[a, t] * inv[t, b]
                tmp[a, b] = v
        for a in range(r):
            for b in range(r):
                v = 0.0
                for t in range(r):
                    v += tmp[a, t] * cf[b, t]
                h[f, a, b] -= v


@njit(cache=True, nogil=True)
def woodbury_downdate1(h, u, rows, valid, alive, z, inv):  # pragma: no cover - compiled
    """``woodbury_downdate`` for one column: ``h_f -= inv (u_f . z[rows_f])^2``."""
    c, p, _ = u.shape
    s = inv[0, 0]
    for f in range(c):
        if not alive[f]:
            continue
        acc = 0.0
        for t in range(p):
            if valid[f, t]:
                acc += u[f, t, 0] * z[rows[f, t], 0]
        h[f, 0, 0] -= s * acc * acc


@njit(cache=True, nogil=True)
def scalar_greedy_steps(indptr, indices, lval, parent, prow, valid, u, h, alive, nsteps, mult, update_last,
                        mark, y):  # pragma: no cover - compiled
    """``nsteps`` steps of the incremental greedy for one Laplacian block, fused (no Python per step).

    prow (c, p): permuted rows of the candidates' U; u (c, p); h (c,) current ``U_f^T M^{-1} U_f``
    (-inf once chosen); alive (c,). Per step: the argmax of h (first on ties), then
    ``z = M^{-1} u_e`` (forward along the reach, backward over all columns), the Woodbury
    downdate ``h_f -= (u_f . z)^2 / (1 + h_e)`` of every alive f, and the rank-one update of L.
    Returns the chosen positions and their gains ``mult * log1p(h_e)``."""
    c, p = u.shape
    n = indptr.shape[0] - 1
    chosen = np.empty(nsteps, np.int64)
    gains = np.empty(nsteps)
    starts = np.empty(p, np.int64)
    for step in range(nsteps):
        pos = -1
        best = -np.inf
        for f in range(c):
            if alive[f] and h[f] > best:
                best = h[f]
                pos = f
        he = max(h[pos], 0.0)
        chosen[step] = pos
        gains[step] = mult * np.log1p(he)
        alive[pos] = False
        h[pos] = -np.inf
        if step == nsteps - 1 and not update_last:
            break
        # z = M^{-1} u_e in permuted order
        for j in range(n):
            y[j] = 0.0
        nv = 0
        for a in range(p):
            if valid[pos, a]:
                starts[nv] = prow[pos, a]
                y[prow[pos, a]] += u[pos, a]
                nv += 1
        stamp = step + 1
        path = _reach(parent, starts[:nv], mark, stamp)
        _forward(indptr, indices, lval, path, y.reshape(n, 1))
        _backward1(indptr, indices, lval, y)
        inv = 1.0 / (1.0 + he)
        for f in range(c):
            if alive[f]:
                acc = 0.0
                for t in range(p):
                    if valid[f, t]:
                        acc += u[f, t] * y[prow[f, t]]
                h[f] -= inv * acc * acc
        # L L^T + u_e u_e^T along the same path (y is reused as the work vector)
        for j in path:
            y[j] = 0.0
        for a in range(p):
            if valid[pos, a]:
                y[prow[pos, a]] += u[pos, a]
        _rank_one_path(indptr, indices, lval, path, y)
    return chosen, gains
