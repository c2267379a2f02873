"""The numba kernels of ``posecrb.linalg.selinv`` (selected inversion by the Takahashi recurrences).

A module of their own so that importing ``posecrb.linalg.selinv`` (and the models that use it)
does not import numba: ``selinv`` imports this module on the first inversion of a factor too
large for its numpy block kernels (``selinv.inversion_steps``). Compiled with
``cache=True``: the first call in a process loads the cached machine code.
"""
from __future__ import annotations

import logging

import numpy as np

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
def _row_squares(indptr, indices, val, n):  # pragma: no cover - compiled
    """``sum_k L[j, k]^2`` per row ``j``: the diagonal of ``L L^T``."""
    out = np.zeros(n)
    for j in range(n):
        for p in range(indptr[j], indptr[j + 1]):
            out[indices[p]] += val[p] * val[p]
    return out


@njit(cache=True, nogil=True)
def _count_nonfinite(val):  # pragma: no cover - compiled
    """How many entries are NaN or infinite (without numpy's temporaries of the factor's size)."""
    bad = 0
    for p in range(val.shape[0]):
        if not np.isfinite(val[p]):
            bad += 1
    return bad


@njit(cache=True, nogil=True)
def _gather_l(indptr, val, j0, w, s, ljj, lsj):  # pragma: no cover - compiled
    """Dense copies of the supernode's diagonal block ``L_JJ`` (lower triangle; the caller
    zeroes the rest) and of its rows below, ``L_SJ`` (``s`` rows)."""
    for c in range(w):
        q = indptr[j0 + c] - c
        for r in range(c, w):
            ljj[r, c] = val[q + r]
        for r in range(s):
            lsj[r, c] = val[q + w + r]


@njit(cache=True, nogil=True)
def _scatter(indptr, val, j0, w, s, zjj, zsj):  # pragma: no cover - compiled
    """Store ``Z_JJ`` (lower triangle) and ``Z_SJ`` over the supernode's entries of ``val``."""
    for c in range(w):
        q = indptr[j0 + c] - c
        for r in range(c, w):
            val[q + r] = zjj[r, c]
        for r in range(s):
            val[q + w + r] = zsj[r, c]


@njit(cache=True, nogil=True)
def _gather_zss(indptr, indices, val, bounds, col2sn, j0, w, s, zss, posbuf, mirror):  # pragma: no cover - compiled
    """``Z_SS`` (its lower triangle, and the upper when ``mirror``), ``S`` the rows below
    supernode ``J`` (first column ``j0``, width ``w``, ``s`` rows), read from the already inverted
    ancestor supernodes. Returns 0, or ``j0 + 1`` when an entry of ``S x S`` is missing (pattern
    not closed)."""
    t = indptr[j0] + w  # S = indices[t: t + s]
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
                return j0 + 1
            posbuf[u] = ptr - r0
        a2 = a
        while a2 < s and indices[t + a2] < k1:
            a2 += 1
        for b in range(a, a2):
            kk = indices[t + b]
            base = indptr[kk] - (kk - k0)
            for u in range(b, s):
                zss[u, b] = val[base + posbuf[u]]
            if mirror:
                for u in range(b + 1, s):
                    zss[b, u] = zss[u, b]
        a = a2
    return 0


@njit(cache=True, nogil=True)
def _abs_quadratic(vj, vs, zjj, zsj, zss):  # pragma: no cover - compiled
    """``sum_k v_k^T |Z_TT| v_k`` over the columns k of a supernode: ``v_k`` column k of
    ``V = [|L_JJ|; |L_SJ|]`` (``vj`` lower triangular), ``Z_TT`` the inverse on ``T = J + S``
    (``zjj`` symmetric, ``zsj``, ``zss`` symmetric and full). Its sum over supernodes is
    ``sum_ij |Z_ij| (|L| |L^T|)_ij`` (posecrb.linalg.accuracy)."""
    azjj = np.abs(zjj)
    total = np.sum(vj * np.dot(azjj, vj))
    if vs.shape[0] > 0:
        azsj = np.abs(zsj)
        total += 2.0 * np.sum(vs * np.dot(azsj, vj))
        total += np.sum(vs * np.dot(np.abs(zss), vs))
    return total


@njit(cache=True, nogil=True)
def _abs_lower_dot(z, v):  # pragma: no cover - compiled
    """``sum_ij |z_ij| v_ij`` for symmetric ``z`` and ``v`` given by their lower triangles (nothing
    above the diagonal is read): twice the strictly lower sum plus the diagonal's. One pass over
    half of each, column by column (Fortran order), no temporary."""
    n = z.shape[0]
    off = 0.0
    diag = 0.0
    for j in range(n):
        diag += abs(z[j, j]) * v[j, j]
        for i in range(j + 1, n):
            off += abs(z[i, j]) * v[i, j]
    return 2.0 * off + diag


@njit(cache=True, nogil=True)
def _takahashi_range(indptr, indices, val, bounds, col2sn, hi, lo, posbuf, terms):  # pragma: no cover - compiled
    """The block Takahashi recurrences on supernodes ``hi - 1`` down to ``lo``, in place: on
    entry ``val`` holds ``L`` on these supernodes and ``Z = (L L^T)^{-1}`` on every later one;
    on return ``Z`` on these as well. For each supernode ``J`` (columns ``J``, rows ``S`` below):

        Y = L_SJ L_JJ^{-1},  Z_SJ = -Z_SS Y,  Z_JJ = L_JJ^{-T} L_JJ^{-1} - Y^T Z_SJ

    with ``L_JJ^{-1}`` by forward substitution (meant for narrow supernodes; the wide ones near
    the root go through LAPACK, ``posecrb.linalg.selinv``). Only ``L`` of ``J`` itself and ``Z``
    of its ancestors are read, so ``Z_J`` may overwrite ``L_J``. Where ``terms`` has an entry,
    ``terms[0]`` accumulates each supernode's ``_abs_quadratic``. Returns 0, or ``1 + a column``
    whose pattern is not closed."""
    for sn in range(hi - 1, lo - 1, -1):
        j0 = bounds[sn]
        w = bounds[sn + 1] - j0
        s = indptr[j0 + 1] - indptr[j0] - w
        ljj = np.zeros((w, w))
        lsj = np.empty((s, w))
        _gather_l(indptr, val, j0, w, s, ljj, lsj)
        linv = np.zeros((w, w))
        for c in range(w):
            linv[c, c] = 1.0 / ljj[c, c]
            for r in range(c + 1, w):
                acc = 0.0
                for k in range(c, r):
                    acc += ljj[r, k] * linv[k, c]
                linv[r, c] = -acc / ljj[r, r]
        zjj = np.dot(np.ascontiguousarray(linv.T), linv)
        zsj = np.empty((s, w))
        zss = np.empty((s, s))
        if s > 0:
            y = np.dot(lsj, linv)
            status = _gather_zss(indptr, indices, val, bounds, col2sn, j0, w, s, zss, posbuf, True)
            if status:
                return status
            zsj = -np.dot(zss, y)
            zjj -= np.dot(np.ascontiguousarray(y.T), zsj)
        if terms.shape[0] > 0:
            terms[0] += _abs_quadratic(np.abs(ljj), np.abs(lsj), zjj, zsj, zss)
        _scatter(indptr, val, j0, w, s, zjj, zsj)
    return 0


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
