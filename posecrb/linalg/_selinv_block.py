"""numpy's version of the selected inversion's kernels (``posecrb.linalg.selinv``), for factors
too small for numba's import to pay: every supernode through LAPACK/BLAS, gathers and scatters by
fancy indexing. A module of its own so that ``selinv`` stays about the recurrences and their
dispatch; ``selinv.inversion_steps`` decides which kernels a factor gets.
"""
from __future__ import annotations

import numpy as np

from ..core.errors import InternalError


class _BlockKernels:
    """The kernels of ``posecrb.linalg._selinv_kernels`` in numpy, for small factors
    (``selinv._inversion_kernels``): every supernode goes through ``selinv._wide_supernode``
    (LAPACK/BLAS), its gathers and scatters are fancy indexing, and no supernode is left to the
    compiled loop. The Python step per supernode (a dozen numpy and BLAS calls) costs less on such
    factors than numba's import and first call that the compiled kernels need in a fresh process
    (``selinv.inversion_steps``, ``selinv._BLOCK_MAX_STEPS``)."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray):
        self._n = indptr.size - 1
        # index arrays per block shape: supernodes of a pose graph repeat a few shapes
        self._lower: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._blocks: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        cols = np.repeat(np.arange(self._n, dtype=np.int64), np.diff(indptr))
        # (column, row) of every entry as one integer: sorted, since CSC rows are sorted
        self._keys = cols * self._n + indices

    def _positions(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions of entries (rows, cols), rows >= cols, in the factor's values, and which exist."""
        target = cols * self._n + rows
        pos = np.minimum(np.searchsorted(self._keys, target), self._keys.size - 1)
        return pos, self._keys[pos] == target

    def _tril(self, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows and columns of the lower triangle of an ``m x m`` matrix, and weights 2 off the
        diagonal and 1 on it (a symmetric matrix's sum from its lower triangle)."""
        if m not in self._lower:
            u, b = np.tril_indices(m)
            self._lower[m] = (u, b, np.where(u == b, 1.0, 2.0))
        return self._lower[m]

    def _block(self, indptr: np.ndarray, j0: int, w: int, s: int) -> tuple[np.ndarray, np.ndarray]:
        """Positions of the supernode's dense ``(w + s, w)`` block ``[L_JJ; L_SJ]`` in the values
        and the mask of its stored (lower) part: column c holds rows c.. of the block."""
        if (w, s) not in self._blocks:
            r = np.arange(w + s)[:, None]
            c = np.arange(w)
            self._blocks[w, s] = (r - c, r >= c)
        offset, stored = self._blocks[w, s]
        return np.maximum(indptr[j0:j0 + w] + offset, 0), stored

    @staticmethod
    def _row_squares(indptr: np.ndarray, indices: np.ndarray, val: np.ndarray, n: int) -> np.ndarray:
        return np.bincount(indices, weights=val * val, minlength=n)

    @staticmethod
    def _count_nonfinite(val: np.ndarray) -> int:
        return int(np.count_nonzero(~np.isfinite(val)))

    @staticmethod
    def _takahashi_range(indptr: np.ndarray, indices: np.ndarray, val: np.ndarray, bounds: np.ndarray,
                         col2sn: np.ndarray, hi: int, lo: int, posbuf: np.ndarray, terms: np.ndarray) -> int:
        if hi != lo:
            raise InternalError("the block kernels leave no supernode to the compiled loop")
        return 0

    def _gather_l(self, indptr: np.ndarray, val: np.ndarray, j0: int, w: int, s: int, ljj: np.ndarray,
                  lsj: np.ndarray) -> None:
        pos, stored = self._block(indptr, j0, w, s)
        block = np.where(stored, val[pos], 0.0)
        ljj[:] = block[:w]
        lsj[:] = block[w:]

    def _scatter(self, indptr: np.ndarray, val: np.ndarray, j0: int, w: int, s: int, zjj: np.ndarray,
                 zsj: np.ndarray) -> None:
        pos, stored = self._block(indptr, j0, w, s)
        val[pos[stored]] = np.concatenate((zjj, zsj))[stored]

    def _gather_zss(self, indptr: np.ndarray, indices: np.ndarray, val: np.ndarray, bounds: np.ndarray,
                    col2sn: np.ndarray, j0: int, w: int, s: int, zss: np.ndarray, posbuf: np.ndarray,
                    mirror: bool) -> int:
        if mirror:   # only the compiled loop reads the upper triangle; _wide_supernode never asks
            raise InternalError("the block kernels gather the lower triangle of Z_SS only")
        rows = np.asarray(indices[indptr[j0] + w: indptr[j0] + w + s], dtype=np.int64)
        u, b, _ = self._tril(s)
        pos, found = self._positions(rows[u], rows[b])
        if not found.all():
            return j0 + 1
        zss[u, b] = val[pos]
        return 0

    def _abs_lower_dot(self, z: np.ndarray, v: np.ndarray) -> float:
        u, b, weight = self._tril(z.shape[0])
        return float((np.abs(z[u, b]) * v[u, b]) @ weight)

    def _lookup(self, indptr: np.ndarray, indices: np.ndarray, zval: np.ndarray, rows: np.ndarray,
                cols: np.ndarray) -> np.ndarray:
        pos, found = self._positions(rows, cols)
        return np.where(found, zval[pos], np.nan)
