"""Exact selected inversion of a sparse symmetric positive definite matrix.

The CRLB needs entries of ``A^{-1}`` (its trace, its per-pose diagonal blocks), never
the dense inverse. With the Cholesky factor ``P A P^T = L L^T`` (CHOLMOD, through
``posecrb.linalg.cholesky``) and ``Z = (L L^T)^{-1}``, the Takahashi recurrences (Takahashi,
Fagan & Chin 1973; Erisman & Tinney 1975)

    Z[S, j] = -Z[S, S] L[S, j] / L[j, j]
    Z[j, j] = 1 / L[j, j]^2 - Z[S, j]^T L[S, j] / L[j, j]

with ``S`` the row structure of column ``j`` of ``L`` below the diagonal, computed from
the last column to the first, give every entry of ``Z`` inside the pattern of ``L``
exactly (up to rounding), in about the flops of the factorization itself. The
recurrence only reads ``Z`` inside that pattern because a Cholesky pattern is closed:
``i, k in S, i > k`` implies ``(i, k)`` is in the pattern. The kernel checks this and
raises instead of returning a wrong number when a factor's pattern is not closed.

The kernel runs the block form of the recurrences supernode by supernode (dense
``Z_SS`` gathered from ancestor supernodes, products through BLAS with one thread), and
is compiled with numba (``cache=True``; the first call in a process loads the cached
machine code, ~0.3 s). Without numba the same code runs as plain Python, correct but slow.
Per-pose blocks of the inverse are only guaranteed in the factor's pattern when the
matrix's own diagonal blocks are structurally full, so ``inverse_block_diagonal`` pads
them with explicit zeros before the analysis.
"""
from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from ..core.errors import NumericalError, UsageError
from .cholesky import Factor, SymbolicCholesky

log = logging.getLogger("posecrb")

try:  # numba is a declared dependency; the fallback only keeps the module importable
    from numba import njit
except ImportError:  # pragma: no cover
    log.warning("numba is not installed: selected inversion runs as slow pure Python")

    def njit(*args, **kwargs):  # type: ignore[no-redef]  # stands in for the untyped numba.njit
        if args and callable(args[0]):
            return args[0]
        return lambda f: f


@njit(cache=True, nogil=True)
def _supernodes(indptr, indices):  # pragma: no cover - compiled
    """Column boundaries of the supernodes of a closed Cholesky pattern: column j+1 joins
    column j's supernode when L[j+1, j] != 0 and |col j+1| = |col j| - 1 (then, the pattern
    being closed, both columns have the same structure below the supernode)."""
    n = indptr.shape[0] - 1
    bounds = np.empty(n + 1, np.int64)
    bounds[0] = 0
    count = 1
    for j in range(n - 1):
        cj = indptr[j + 1] - indptr[j]
        if not (cj > 1 and indices[indptr[j] + 1] == j + 1 and indptr[j + 2] - indptr[j + 1] == cj - 1):
            bounds[count] = j + 1
            count += 1
    bounds[count] = n
    return bounds[:count + 1]


@njit(cache=True, nogil=True)
def _takahashi(indptr, indices, lval):  # pragma: no cover - compiled
    """Selected inverse ``Z = (L L^T)^{-1}`` on the pattern of ``L`` (CSC, rows sorted,
    diagonal first in each column), supernode by supernode from the root down:

        Y = L_SJ L_JJ^{-1},  Z_SJ = -Z_SS Y,  Z_JJ = L_JJ^{-T} L_JJ^{-1} - Y^T Z_SJ

    (the block form of the Takahashi recurrences; ``Z_SS`` is gathered from ancestor
    supernodes, the products go to BLAS). Returns (zval, status): status 0 = ok,
    otherwise 1 + a column whose pattern is not closed."""
    n = indptr.shape[0] - 1
    bounds = _supernodes(indptr, indices)
    nsn = bounds.shape[0] - 1
    col2sn = np.empty(n, np.int64)
    for sidx in range(nsn):
        col2sn[bounds[sidx]:bounds[sidx + 1]] = sidx
    zval = np.zeros(lval.shape[0])
    posbuf = np.empty(n, np.int64)
    for sn in range(nsn - 1, -1, -1):
        j0 = bounds[sn]
        w = bounds[sn + 1] - j0
        p0 = indptr[j0]
        s = indptr[j0 + 1] - p0 - w
        ljj = np.zeros((w, w))
        lsj = np.empty((s, w))
        for c in range(w):
            q = indptr[j0 + c] - c
            for r in range(c, w):
                ljj[r, c] = lval[q + r]
            for r in range(s):
                lsj[r, c] = lval[q + w + r]
        # inverse of the lower-triangular diagonal block: forward substitution for small
        # blocks, LAPACK for the large separator blocks near the root
        linv = np.zeros((w, w))
        if w > 48:
            full = np.linalg.inv(ljj)
            for c in range(w):
                for r in range(c, w):
                    linv[r, c] = full[r, c]
        else:
            for c in range(w):
                linv[c, c] = 1.0 / ljj[c, c]
                for r in range(c + 1, w):
                    acc = 0.0
                    for k in range(c, r):
                        acc += ljj[r, k] * linv[k, c]
                    linv[r, c] = -acc / ljj[r, r]
        zjj = np.dot(np.ascontiguousarray(linv.T), linv)
        zsj = np.empty((s, w))
        if s > 0:
            y = np.dot(lsj, linv)
            zss = np.empty((s, s))
            t = p0 + w  # S = indices[p0 + w: p0 + w + s]
            a = 0
            while a < s:
                k = indices[t + a]
                anc = col2sn[k]
                k0 = bounds[anc]
                k1 = bounds[anc + 1]
                r0 = indptr[k0]
                r1 = indptr[k0 + 1]
                ptr = r0
                for u in range(a, s):  # positions of S[a:] in the ancestor's row list
                    target = indices[t + u]
                    while ptr < r1 and indices[ptr] < target:
                        ptr += 1
                    if ptr == r1 or indices[ptr] != target:
                        return zval, j0 + 1
                    posbuf[u] = ptr - r0
                a2 = a
                while a2 < s and indices[t + a2] < k1:
                    a2 += 1
                for b in range(a, a2):
                    kk = indices[t + b]
                    base = indptr[kk] - (kk - k0)
                    for u in range(b, s):
                        v = zval[base + posbuf[u]]
                        zss[u, b] = v
                        zss[b, u] = v
                a = a2
            zsj = -np.dot(zss, y)
            zjj -= np.dot(np.ascontiguousarray(y.T), zsj)
        for c in range(w):
            q = indptr[j0 + c] - c
            for r in range(c, w):
                zval[q + r] = zjj[r, c]
            for r in range(s):
                zval[q + w + r] = zsj[r, c]
    return zval, 0


@njit(cache=True, nogil=True)
def _lookup(indptr, indices, zval, rows, cols):  # pragma: no cover - compiled
    """Z[rows[k], cols[k]] for rows >= cols (lower triangle); NaN where outside the pattern."""
    out = np.empty(rows.shape[0])
    for k in range(rows.shape[0]):
        i = rows[k]
        j = cols[k]
        lo = indptr[j]
        hi = indptr[j + 1]
        while lo < hi:  # binary search, rows sorted
            mid = (lo + hi) // 2
            if indices[mid] < i:
                lo = mid + 1
            else:
                hi = mid
        out[k] = zval[lo] if lo < indptr[j + 1] and indices[lo] == i else np.nan
    return out


def _one_blas_thread():
    return threadpool_limits(limits=1, user_api="blas")


class SelectedInverse:
    """Entries of ``A^{-1}`` on the (permuted) pattern of the Cholesky factor of ``A``."""

    def __init__(self, factor: Factor, name: str = "matrix") -> None:
        lower = factor.L()
        lower = sp.csc_matrix(lower)
        lower.sort_indices()
        self.perm = np.asarray(factor.P(), dtype=np.int64)
        self.iperm = np.empty_like(self.perm)
        self.iperm[self.perm] = np.arange(self.perm.size)
        self.indptr = lower.indptr.astype(np.int64)
        self.indices = lower.indices.astype(np.int64)
        # One BLAS thread: the kernel makes many small GEMM calls, where OpenBLAS threads only
        # add synchronisation (and collapse when another process holds the other core).
        with _one_blas_thread():
            zval, status = _takahashi(self.indptr, self.indices, np.asarray(lower.data, dtype=np.float64))
        if status:
            raise NumericalError(f"{name}: Cholesky pattern not closed at column {status - 1}; "
                               "cannot run the Takahashi recurrences")
        self.zval = zval
        self.n = self.perm.size

    def diagonal(self) -> np.ndarray:
        """diag(A^{-1}) in the original ordering."""
        return self.zval[self.indptr[:-1]][self.iperm]

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(A^{-1})[rows, cols] (original ordering); NaN where not in the factor's pattern."""
        a = self.iperm[np.asarray(rows, dtype=np.int64)]
        b = self.iperm[np.asarray(cols, dtype=np.int64)]
        return _lookup(self.indptr, self.indices, self.zval, np.maximum(a, b), np.minimum(a, b))


def _block_pattern_padded(a: sp.spmatrix, block: int) -> sp.csc_matrix:
    """``a`` with explicit zeros filling its diagonal ``block x block`` blocks, so that the
    factor's pattern holds every entry of the inverse's diagonal blocks."""
    coo = sp.coo_matrix(a)
    n = a.shape[0]
    nb = n // block
    base = np.repeat(np.arange(nb) * block, block * block)
    r = base + np.tile(np.repeat(np.arange(block), block), nb)
    c = base + np.tile(np.tile(np.arange(block), block), nb)
    rows = np.concatenate([coo.row, r])
    cols = np.concatenate([coo.col, c])
    vals = np.concatenate([coo.data.astype(float), np.zeros(r.size)])
    # COO -> CSC sums duplicates and keeps explicit zeros (it never prunes values)
    return sp.csc_matrix((vals, (rows, cols)), shape=a.shape)


# From this many rows on, pay for a METIS nested-dissection ordering: on the 3D pose graphs
# it cuts the factor's fill by ~20% against CHOLMOD's default (AMD) pick, and the selected
# inversion costs about as many flops as the factorization, so both get cheaper.
_METIS_FROM = 4000


def _factor(a: sp.spmatrix, name: str) -> Factor:
    ordering = "metis" if a.shape[0] >= _METIS_FROM else "default"
    try:
        symbolic = SymbolicCholesky(a, ordering_method=ordering)
    except Exception:  # pragma: no cover - CHOLMOD built without METIS
        symbolic = SymbolicCholesky(a)
    return symbolic.factor(a, name=name)


def inverse_block_diagonal(a: sp.spmatrix, block: int, name: str = "matrix",
                           factor: Factor | None = None) -> np.ndarray:
    """The ``(n // block, block, block)`` diagonal blocks of ``a^{-1}`` for a sparse SPD ``a``.

    Exact selected inversion (Takahashi recurrences on the Cholesky factor). ``factor``
    (a CHOLMOD factor of ``a`` from ``posecrb.linalg.cholesky``) is reused when its pattern holds
    the diagonal blocks; otherwise ``a`` is refactored with its blocks padded by explicit
    zeros. Raises NotPositiveDefinite (through posecrb.linalg.cholesky) when ``a`` is not SPD.
    """
    n = a.shape[0]
    if a.shape != (n, n) or n % block:
        raise UsageError(f"{name}: shape {a.shape} is not square with a multiple of {block} rows")
    nb = n // block
    if nb == 0:
        return np.zeros((0, block, block))
    base = np.repeat(np.arange(nb) * block, block * block)
    r = base + np.tile(np.repeat(np.arange(block), block), nb)
    c = base + np.tile(np.tile(np.arange(block), block), nb)
    if factor is not None:
        sel = SelectedInverse(factor, name)
        vals = sel.entries(r, c)
        if not np.isnan(vals).any():
            return vals.reshape(nb, block, block)
        log.debug("%s: factor pattern lacks diagonal-block entries; refactoring padded", name)
    padded = _block_pattern_padded(a, block)
    sel = SelectedInverse(_factor(padded, name), name)
    vals = sel.entries(r, c)
    if np.isnan(vals).any():  # pragma: no cover - CHOLMOD keeps the padded pattern
        raise NumericalError(f"{name}: factor pattern lost diagonal-block entries")
    return vals.reshape(nb, block, block)


def trace_inverse(a: sp.spmatrix, name: str = "matrix", factor: Factor | None = None) -> float:
    """trace(a^{-1}) exactly, from the selected inverse's diagonal."""
    if a.shape[0] == 0:
        return 0.0
    factor = factor if factor is not None else _factor(a, name)
    return float(SelectedInverse(factor, name).diagonal().sum())


def diagonal_inverse(a: sp.spmatrix, name: str = "matrix", factor: Factor | None = None) -> np.ndarray:
    """diag(a^{-1}) in the original ordering."""
    factor = factor if factor is not None else _factor(a, name)
    return SelectedInverse(factor, name).diagonal()
