"""Sparse Cholesky through CHOLMOD (scikit-sparse); every log-determinant goes through here.

docs/design.md#linear-algebra. ``SymbolicCholesky`` holds one fill-reducing ordering
(CHOLMOD's ``analyze``) and factors any matrix with the same sparsity pattern
with it, which is Algorithm 1's "compute the ordering once, reuse it".
A matrix that is not positive definite raises ``NotPositiveDefinite`` naming
the matrix and the failed pivot, never a NaN.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, eigsh
from sksparse.cholmod import CholmodNotPositiveDefiniteError, Factor, analyze

from ..core.errors import NotPositiveDefinite, UsageError


def _as_csc(a: sp.spmatrix) -> sp.csc_matrix:
    a = sp.csc_matrix(a) if not sp.isspmatrix_csc(a) else a
    if a.dtype != np.float64:
        a = a.astype(np.float64)
    return a


class SymbolicCholesky:
    """A CHOLMOD symbolic analysis (fill-reducing ordering + elimination tree) reused across
    matrices sharing one sparsity pattern."""

    def __init__(self, pattern: sp.spmatrix, mode: str = "auto", ordering_method: str = "default"):
        self.shape = pattern.shape
        self._symbolic: Factor = analyze(_as_csc(pattern), mode=mode, ordering_method=ordering_method)

    @property
    def permutation(self) -> np.ndarray:
        return self._symbolic.P()

    def factor(self, a: sp.spmatrix, name: str = "matrix", beta: float = 0.0) -> Factor:
        """Numeric factorization of ``a + beta I`` with this analysis; raises NotPositiveDefinite."""
        return self.factor_logdet(a, name, beta)[0]

    def factor_logdet(self, a: sp.spmatrix, name: str = "matrix", beta: float = 0.0) -> tuple[Factor, float]:
        """``factor`` and the log-determinant it already checked (no second pass over the factor)."""
        if a.shape != self.shape:
            raise UsageError(f"{name}: shape {a.shape} does not match the analysed pattern {self.shape}")
        a = _as_csc(a)
        try:
            f = self._symbolic.cholesky(a, beta=beta)
        except CholmodNotPositiveDefiniteError as exc:
            raise NotPositiveDefinite(name, str(exc).split(": ", 1)[-1]) from None
        return f, _checked_logdet(f, name)


def _checked_logdet(f: Factor, name: str) -> float:
    # CHOLMOD's simplicial mode does not raise on a failed pivot; it stops and
    # leaves a non-positive diagonal, so inspect the factor's diagonal.
    with np.errstate(all="ignore"):
        ld = f.logdet()
    if np.isfinite(ld):
        return float(ld)
    with np.errstate(all="ignore"):
        diag = f.D()
    bad = np.flatnonzero(~(diag > 0))
    col = int(f.P()[bad[0]]) if bad.size else None
    raise NotPositiveDefinite(name, "a pivot is zero or negative (singular or indefinite matrix)", col)


def cholesky(a: sp.spmatrix, name: str = "matrix", beta: float = 0.0,
             symbolic: SymbolicCholesky | None = None) -> Factor:
    """Factor ``a + beta I``, reusing ``symbolic`` when given."""
    symbolic = symbolic or SymbolicCholesky(a)
    return symbolic.factor(a, name=name, beta=beta)


def logdet(a: sp.spmatrix, name: str = "matrix", beta: float = 0.0,
           symbolic: SymbolicCholesky | None = None) -> float:
    """log det(a + beta I) for a sparse symmetric positive definite matrix."""
    return (symbolic or SymbolicCholesky(a)).factor_logdet(a, name=name, beta=beta)[1]


def lambda_min(a: sp.spmatrix, factor: Factor | None = None, name: str = "matrix") -> float:
    """Smallest eigenvalue of a sparse SPD matrix by shift-invert Lanczos at 0.

    Reuses ``factor`` (a Cholesky factor of ``a``) as the inverse operator, so no
    extra factorization happens when the caller already has one.
    """

    a = _as_csc(a)
    n = a.shape[0]
    if n <= 200:
        return float(np.linalg.eigvalsh(a.toarray())[0])
    factor = factor or cholesky(a, name=name)
    op_inv = LinearOperator((n, n), matvec=lambda x: factor(np.asarray(x, float)), dtype=float)
    vals = eigsh(a, k=1, sigma=0.0, which="LM", OPinv=op_inv, return_eigenvectors=False,
                 v0=np.ones(n), tol=1e-12)
    return float(vals[0])


def anchored_logdet(matrix, q: int, anchors: list[int], name: str) -> float:
    """log det of a pose-major (q per pose) FIM with the anchored poses' rows/columns removed."""

    n = matrix.shape[0] // q
    keep = np.ones(n, bool)
    keep[anchors] = False
    dofs = (np.flatnonzero(keep)[:, None] * q + np.arange(q)).ravel()
    return logdet(matrix[dofs][:, dofs].tocsc(), name=name)
