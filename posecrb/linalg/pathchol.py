"""A Cholesky factor with a fixed pattern: solves with sparse right-hand sides and rank-one
updates that touch only the elimination-tree paths of the nonzeros.

Measurement selection adds edges one by one to a matrix whose CHOLMOD analysis was done on the
full graph, so the factor's pattern already holds every fill entry any subset can create. For
``P A P^T = L L^T`` and a right-hand side ``b`` with a few nonzeros (one edge: two poses), the
forward solve ``y = L^{-1} P b`` is nonzero only on the union of the elimination-tree paths from
those rows to the root (Gilbert's reach), so ``b^T A^{-1} b = ||y||^2`` costs the column counts
along that path, not a pass over the whole factor. The rank-one update ``A + u u^T`` (Gill,
Golub, Murray & Saunders 1974, method C1; the column order of Davis & Hager 1999) likewise only
rewrites the columns on the path of u's nonzeros, and needs no new entries because the pattern
is closed under it. Kernels are compiled with numba (``cache=True``), like ``posecrb.linalg.selinv``.

The compiled primitives (``_reach``, ``_forward``, ``_backward``/``_backward1``, ``_rank_one_path``)
are generic: they know a factor's arrays, not what the matrix is. The selection's fused greedy
(``posecrb.selection._kernels``) calls them from its own compiled loop.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..core.errors import InternalError

try:  # numba is a declared dependency
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*args, **kwargs):  # type: ignore[no-redef]  # stands in for the untyped numba.njit
        if args and callable(args[0]):
            return args[0]
        return lambda f: f


@njit(cache=True, nogil=True)
def _reach(parent, starts, mark, stamp):  # pragma: no cover - compiled
    """Sorted union of the elimination-tree paths from ``starts`` to the root."""
    out = np.empty(parent.shape[0], np.int64)
    cnt = 0
    for s0 in starts:
        s = s0
        while s != -1 and mark[s] != stamp:
            mark[s] = stamp
            out[cnt] = s
            cnt += 1
            s = parent[s]
    return np.sort(out[:cnt])


@njit(cache=True, nogil=True)
def _valid_rows(iperm, rows, valid):  # pragma: no cover - compiled
    """The permuted rows ``iperm[rows[a]]`` of the valid entries of one edge, in order."""
    nv = 0
    for a in range(rows.shape[0]):
        if valid[a]:
            nv += 1
    out = np.empty(nv, np.int64)
    t = 0
    for a in range(rows.shape[0]):
        if valid[a]:
            out[t] = iperm[rows[a]]
            t += 1
    return out


@njit(cache=True, nogil=True)
def _forward(indptr, indices, lval, path, y):  # pragma: no cover - compiled
    """``y <- L^{-1} y`` for r columns (n, r) whose nonzeros lie on ``path`` (the reach), in place."""
    r = y.shape[1]
    for j in path:
        d = lval[indptr[j]]
        for c in range(r):
            y[j, c] /= d
        for q in range(indptr[j] + 1, indptr[j + 1]):
            i = indices[q]
            lij = lval[q]
            for c in range(r):
                y[i, c] -= lij * y[j, c]


@njit(cache=True, nogil=True)
def _backward(indptr, indices, lval, y):  # pragma: no cover - compiled
    """``y <- L^{-T} y`` for r columns (n, r), over every column of L, in place."""
    r = y.shape[1]
    for j in range(indptr.shape[0] - 2, -1, -1):
        for q in range(indptr[j] + 1, indptr[j + 1]):
            i = indices[q]
            lij = lval[q]
            for c in range(r):
                y[j, c] -= lij * y[i, c]
        d = lval[indptr[j]]
        for c in range(r):
            y[j, c] /= d


@njit(cache=True, nogil=True)
def _backward1(indptr, indices, lval, y, lo, hi):  # pragma: no cover - compiled
    """``_backward`` for one column (n,), columns ``hi - 1`` down to ``lo`` (0 and n: all of them).
    Kept apart: this pass over the whole factor is the scalar greedy's hottest loop, and the
    r-column kernel with r = 1 made ``select --objective tree`` on city10000 clearly slower
    (docs/decisions/selection-at-scale.md; the forward pass, along the reach only, showed no
    difference and is shared). A range
    of columns reads ``y`` only on its own columns and their ancestors', so once the columns above
    two disjoint subtrees of the elimination tree are done, the two subtrees can run at once."""
    for j in range(hi - 1, lo - 1, -1):
        acc = y[j]
        for q in range(indptr[j] + 1, indptr[j + 1]):
            acc -= lval[q] * y[indices[q]]
        y[j] = acc / lval[indptr[j]]


@njit(cache=True, nogil=True)
def _rank_one_path(indptr, indices, lval, path, w):  # pragma: no cover - compiled
    """``L L^T + w w^T`` in place (Gill et al. method C1), ``w`` (permuted order) nonzero only on
    ``path``; the columns of the path are rewritten and ``w`` is left zero on them."""
    for j in path:
        wj = w[j]
        if wj == 0.0:
            continue
        q0 = indptr[j]
        ljj = lval[q0]
        rr = np.sqrt(ljj * ljj + wj * wj)
        cc = rr / ljj
        ss = wj / ljj
        lval[q0] = rr
        for q in range(q0 + 1, indptr[j + 1]):
            i = indices[q]
            lval[q] = (lval[q] + ss * w[i]) / cc
            w[i] = cc * w[i] - ss * lval[q]
        w[j] = 0.0


@njit(cache=True, nogil=True)
def _h_edges(indptr, indices, lval, parent, iperm, rows, valid, u, mark, work):  # pragma: no cover
    """``H_e = U_e^T A^{-1} U_e`` for each edge: forward solves along the reach of its rows."""
    k, p, r = u.shape
    out = np.zeros((k, r, r))
    stamp = 1          # mark is all zeros on entry
    for e in range(k):
        path = _reach(parent, _valid_rows(iperm, rows[e], valid[e]), mark, stamp)
        stamp += 1
        for a in range(p):
            if valid[e, a]:
                pos = iperm[rows[e, a]]
                for c in range(r):
                    work[pos, c] += u[e, a, c]
        _forward(indptr, indices, lval, path, work)
        for j in path:
            for a in range(r):
                for b in range(r):
                    out[e, a, b] += work[j, a] * work[j, b]
            for c in range(r):
                work[j, c] = 0.0
    return out


@njit(cache=True, nogil=True)
def _update(indptr, indices, lval, parent, iperm, rows, valid, u, mark, vec):  # pragma: no cover
    """``L L^T + sum_c u_c u_c^T`` in place, one rank-one update per column of ``u`` (p, r)."""
    p, r = u.shape
    path = _reach(parent, _valid_rows(iperm, rows, valid), mark, 1)   # mark is all zeros on entry
    for c in range(r):
        for a in range(p):
            if valid[a]:
                vec[iperm[rows[a]]] += u[a, c]
        _rank_one_path(indptr, indices, lval, path, vec)


@njit(cache=True, nogil=True)
def _solve(indptr, indices, lval, parent, iperm, rows, valid, u, mark):  # pragma: no cover - compiled
    """``A^{-1} U`` (permuted order) for one edge: forward along the reach, backward over all."""
    p, r = u.shape
    y = np.zeros((indptr.shape[0] - 1, r))
    for a in range(p):
        if valid[a]:
            for c in range(r):
                y[iperm[rows[a]], c] += u[a, c]
    path = _reach(parent, _valid_rows(iperm, rows, valid), mark, 1)
    _forward(indptr, indices, lval, path, y)
    _backward(indptr, indices, lval, y)
    return y


@njit(cache=True, nogil=True)
def _solve1(indptr, indices, lval, parent, iperm, rows, valid, u, mark):  # pragma: no cover - compiled
    """``_solve`` for one column (Laplacian blocks), with the 1-D backward pass (``_backward1``)."""
    n = indptr.shape[0] - 1
    y = np.zeros(n)
    for a in range(u.shape[0]):
        if valid[a]:
            y[iperm[rows[a]]] += u[a, 0]
    path = _reach(parent, _valid_rows(iperm, rows, valid), mark, 1)
    _forward(indptr, indices, lval, path, y.reshape(n, 1))
    _backward1(indptr, indices, lval, y, 0, indptr.shape[0] - 1)
    return y


@njit(cache=True, nogil=True)
def logdet_eye_plus(h):  # pragma: no cover - compiled
    """logdet(I + H) for each symmetric PSD H (k, r, r), by an unpivoted Cholesky (I + H >= I)."""
    k, r, _ = h.shape
    out = np.zeros(k)
    a = np.empty((r, r))
    for e in range(k):
        if r == 1:
            out[e] = np.log1p(max(h[e, 0, 0], 0.0))
            continue
        for i in range(r):
            for j in range(r):
                a[i, j] = 0.5 * (h[e, i, j] + h[e, j, i]) + (1.0 if i == j else 0.0)
        acc = 0.0
        for j in range(r):
            d = a[j, j]
            for t in range(j):
                d -= a[j, t] * a[j, t]
            d = np.sqrt(max(d, 1.0))   # I + H >= I: a pivot below 1 is rounding
            a[j, j] = d
            acc += np.log(d)
            for i in range(j + 1, r):
                v = a[i, j]
                for t in range(j):
                    v -= a[i, t] * a[j, t]
                a[i, j] = v / d
        out[e] = 2.0 * acc
    return out


class PathFactor:
    """``P A P^T = L L^T`` held as a CSC lower factor (from a CHOLMOD factor), for path solves
    and in-place rank-one updates with the pattern fixed."""

    def __init__(self, factor):
        lower = sp.csc_matrix(factor.L())
        lower.sort_indices()
        self.indptr = lower.indptr.astype(np.int64)
        self.indices = lower.indices.astype(np.int64)
        self.lval = np.array(lower.data, dtype=np.float64)
        n = self.indptr.size - 1
        if np.any(self.indices[self.indptr[:-1]] != np.arange(n)):  # pragma: no cover - CHOLMOD's L
            raise InternalError("Cholesky factor without its diagonal first in every column")
        has_sub = self.indptr[1:] - self.indptr[:-1] > 1
        self.parent = np.full(n, -1, dtype=np.int64)
        self.parent[has_sub] = self.indices[self.indptr[:-1][has_sub] + 1]
        perm = np.asarray(factor.P(), dtype=np.int64)
        self.iperm = np.empty_like(perm)
        self.iperm[perm] = np.arange(n)
        self._mark = np.zeros(n, dtype=np.int64)
        self._vec = np.zeros(n)
        self.n = n

    def h(self, rows: np.ndarray, valid: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``U_e^T A^{-1} U_e`` for edges given by rows (k, p), valid (k, p), U (k, p, r)."""
        work = np.zeros((self.n, u.shape[2]))
        out = _h_edges(self.indptr, self.indices, self.lval, self.parent, self.iperm,
                       np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(valid),
                       np.ascontiguousarray(u, dtype=np.float64), self._mark, work)
        self._mark[:] = 0
        return out

    def update(self, rows: np.ndarray, valid: np.ndarray, u: np.ndarray) -> None:
        """``A <- A + U U^T`` for one edge (rows (p,), valid (p,), U (p, r))."""
        _update(self.indptr, self.indices, self.lval, self.parent, self.iperm,
                np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(valid),
                np.ascontiguousarray(u, dtype=np.float64), self._mark, self._vec)
        self._mark[:] = 0

    def solve(self, rows: np.ndarray, valid: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``A^{-1} U`` (n, r) in the original order for one edge's rows (p,), valid (p,), U (p, r)."""
        if u.shape[1] == 1:
            y1 = _solve1(self.indptr, self.indices, self.lval, self.parent, self.iperm,
                         np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(valid),
                         np.ascontiguousarray(u, dtype=np.float64), self._mark)
            self._mark[:] = 0
            return y1[self.iperm][:, None]
        y = _solve(self.indptr, self.indices, self.lval, self.parent, self.iperm,
                   np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(valid),
                   np.ascontiguousarray(u, dtype=np.float64), self._mark)
        self._mark[:] = 0
        return y[self.iperm]

    def logdet(self) -> float:
        return float(2.0 * np.log(self.lval[self.indptr[:-1]]).sum())
