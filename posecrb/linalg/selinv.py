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
is compiled with numba (``cache=True``; the first call in a process imports numba and loads the
cached machine code, ~0.3 s; the kernels live in ``posecrb.linalg._selinv_kernels``, imported
only then). Without numba the same code runs as plain Python, correct but slow.
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

def _kernels():
    """The compiled kernels (``posecrb.linalg._selinv_kernels``), imported on first use: numba's
    import costs ~0.1-0.3 s of start-up that commands which never invert anything should not pay."""
    from . import _selinv_kernels  # noqa: PLC0415 -- lazy: start-up time (numba)

    return _selinv_kernels


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
            zval, status = _kernels()._takahashi(self.indptr, self.indices, np.asarray(lower.data, dtype=np.float64))
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
        return _kernels()._lookup(self.indptr, self.indices, self.zval, np.maximum(a, b), np.minimum(a, b))


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
