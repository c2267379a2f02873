"""Compiled kernels of the incremental greedy (``posecrb.selection.greedy``): Woodbury downdates of
every candidate's ``H_f`` after an edge is added, the fused steps of the one-Laplacian greedy, the
parts of one such step (which its two-thread form calls one by one), and where a factor's
elimination tree splits in two.

They build on the path-restricted Cholesky primitives of ``posecrb.linalg.pathchol`` (reach,
forward solve along it, backward solve, rank-one update along it). Compiled with numba
(``cache=True``) like those; numba's cache is keyed on this file only, so after a change to those
primitives the cache of this module must be cleared too (``__pycache__/*.nbi``, ``*.nbc``).
"""
from __future__ import annotations

import numpy as np

from ..linalg.pathchol import _backward1, _forward, _rank_one_path, _reach, njit


@njit(cache=True, nogil=True)
def sandwich_subtract(h, c, inv, tmp):  # pragma: no cover - compiled
    """``h <- h - c inv c^T`` for r x r matrices (``tmp`` r x r work): one Woodbury term."""
    r = h.shape[0]
    for a in range(r):
        for b in range(r):
            v = 0.0
            for t in range(r):
                v += c[a, t] * inv[t, b]
            tmp[a, b] = v
    for a in range(r):
        for b in range(r):
            v = 0.0
            for t in range(r):
                v += tmp[a, t] * c[b, t]
            h[a, b] -= v


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
        sandwich_subtract(h[f], cf, inv, tmp)


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
def scalar_greedy_take(h, alive, mult):  # pragma: no cover - compiled
    """One step's choice for one Laplacian block: the alive candidate of largest ``h`` (the first on
    ties), marked chosen (``alive`` False, ``h`` -inf). Returns its position, its ``h`` (at least 0)
    and its gain ``mult * log1p(h)``."""
    pos = -1
    best = -np.inf
    for f in range(h.shape[0]):
        if alive[f] and h[f] > best:
            best = h[f]
            pos = f
    he = max(h[pos], 0.0)
    alive[pos] = False
    h[pos] = -np.inf
    return pos, he, mult * np.log1p(he)


@njit(cache=True, nogil=True)
def scalar_greedy_solve(indptr, indices, lval, parent, prow, valid, u, pos, mark, stamp, y, top):  # pragma: no cover
    """``y = L^{-T} L^{-1} u_e`` for the chosen candidate ``pos`` (permuted order), except that the
    backward substitution stops at column ``top`` (0: complete; else columns ``top:`` only, the rest
    for the caller, ``_backward1``). The forward pass runs along the reach of u_e's rows, which it
    returns for the factor's update (``scalar_greedy_update``)."""
    n = indptr.shape[0] - 1
    p = u.shape[1]
    for j in range(n):
        y[j] = 0.0
    starts = np.empty(p, np.int64)
    nv = 0
    for a in range(p):
        if valid[pos, a]:
            starts[nv] = prow[pos, a]
            y[prow[pos, a]] += u[pos, a]
            nv += 1
    path = _reach(parent, starts[:nv], mark, stamp)
    _forward(indptr, indices, lval, path, y.reshape(n, 1))
    _backward1(indptr, indices, lval, y, top, n)
    return path


@njit(cache=True, nogil=True)
def scalar_greedy_downdate(h, alive, u, prow, valid, y, inv, lo, hi):  # pragma: no cover - compiled
    """``h_f -= inv (u_f . y[rows_f])^2`` for the alive candidates ``lo <= f < hi`` (Woodbury)."""
    p = u.shape[1]
    for f in range(lo, hi):
        if alive[f]:
            acc = 0.0
            for t in range(p):
                if valid[f, t]:
                    acc += u[f, t] * y[prow[f, t]]
            h[f] -= inv * acc * acc


@njit(cache=True, nogil=True)
def scalar_greedy_update(indptr, indices, lval, path, prow, valid, u, pos, y):  # pragma: no cover - compiled
    """``L L^T + u_e u_e^T`` along the reach ``path`` of the chosen candidate (``y`` is the work
    vector: zeroed on the path, then left zero by the update)."""
    for j in path:
        y[j] = 0.0
    for a in range(u.shape[1]):
        if valid[pos, a]:
            y[prow[pos, a]] += u[pos, a]
    _rank_one_path(indptr, indices, lval, path, y)


@njit(cache=True, nogil=True)
def scalar_greedy_steps(indptr, indices, lval, parent, prow, valid, u, h, alive, nsteps, mult, update_last,
                        mark, y):  # pragma: no cover - compiled
    """``nsteps`` steps of the incremental greedy for one Laplacian block, fused (no Python per step).

    prow (c, p): permuted rows of the candidates' U; u (c, p); h (c,) current ``U_f^T M^{-1} U_f``
    (-inf once chosen); alive (c,). Per step: the argmax of h (first on ties), then
    ``z = M^{-1} u_e`` (forward along the reach, backward over all columns), the Woodbury
    downdate ``h_f -= (u_f . z)^2 / (1 + h_e)`` of every alive f, and the rank-one update of L.
    ``mark`` holds no positive stamp (step s stamps s + 1). Returns the chosen positions and their
    gains ``mult * log1p(h_e)``."""
    c = u.shape[0]
    chosen = np.empty(nsteps, np.int64)
    gains = np.empty(nsteps)
    for step in range(nsteps):
        pos, he, gain = scalar_greedy_take(h, alive, mult)
        chosen[step] = pos
        gains[step] = gain
        if step == nsteps - 1 and not update_last:
            break
        path = scalar_greedy_solve(indptr, indices, lval, parent, prow, valid, u, pos, mark, step + 1, y, 0)
        scalar_greedy_downdate(h, alive, u, prow, valid, y, 1.0 / (1.0 + he), 0, c)
        scalar_greedy_update(indptr, indices, lval, path, prow, valid, u, pos, y)
    return chosen, gains


@njit(cache=True, nogil=True)
def subtree_split(indptr, indices, parent, min_share):  # pragma: no cover - compiled
    """Where the backward substitution of a factor splits in two: ``(top, mid)`` such that columns
    ``top:`` are the elimination tree's trunk (the root and its single-child chain down to the first
    node with two children) and ``0:mid`` and ``mid:top`` are the subtrees of those two children, each
    holding at least ``min_share`` of the factor's entries; (-1, -1) when the tree is not a single
    postordered tree (every subtree a contiguous range of columns) that splits so (nested dissection
    orderings do: their top separator is the trunk). No column of ``0:mid`` has a row in
    ``mid:top`` (checked), so the backward substitutions of the two ranges touch disjoint entries
    of the work vector once the trunk is done."""
    n = indptr.shape[0] - 1
    size = np.ones(n, np.int64)
    children = np.zeros(n, np.int64)
    child = np.full(n, -1, np.int64)
    roots = 0
    root = -1
    for j in range(n):
        pj = parent[j]
        if pj == -1:
            roots += 1
            root = j
        else:
            size[pj] += size[j]
            children[pj] += 1
            if child[pj] == -1:
                child[pj] = j
    if roots != 1 or root != n - 1:
        return -1, -1
    for j in range(n):   # postordered: a subtree starts where its first descendant does
        pj = parent[j]
        if pj != -1 and pj - size[pj] + 1 > j - size[j] + 1:
            return -1, -1
    b = root
    while children[b] == 1:
        b = child[b]
    if children[b] != 2:
        return -1, -1
    c1 = child[b]              # the first child (the smaller column); the second is b - 1
    mid = c1 + 1
    if c1 - size[c1] + 1 != 0 or b - 1 - size[b - 1] + 1 != mid:
        return -1, -1
    nnz = indptr[n]
    if indptr[mid] < min_share * nnz or indptr[b] - indptr[mid] < min_share * nnz:
        return -1, -1
    for q in range(indptr[mid]):   # what makes the halves independent, checked on the pattern itself
        if mid <= indices[q] < b:
            return -1, -1
    return b, mid
