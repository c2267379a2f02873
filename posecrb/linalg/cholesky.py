"""Sparse Cholesky through CHOLMOD (scikit-sparse); every log-determinant goes through here.

docs/design.md#linear-algebra. ``SymbolicCholesky`` holds one fill-reducing ordering
(CHOLMOD's ``analyze``) and factors any matrix with the same sparsity pattern
with it, which is Algorithm 1's "compute the ordering once, reuse it".
A matrix that is not positive definite raises ``NotPositiveDefinite`` naming
the matrix and the failed pivot, never a NaN.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp
from sksparse.cholmod import CholmodNotPositiveDefiniteError, Factor, analyze

from ..core.errors import NotPositiveDefinite, NumericalError, UsageError
from .factor_gc import disable_gc_clear
from .lanczos import largest_eigenpair
from .threads import cholmod_openmp_serial, cholmod_single_threaded, load_aware_threads

log = logging.getLogger("posecrb")


# scikit-sparse 0.4.16 corrupts memory when a Factor dies in a reference cycle; see factor_gc.py
# and docs/decisions/sksparse-factor-gc.md.
disable_gc_clear(Factor)


def _as_csc(a: sp.spmatrix) -> sp.csc_matrix:
    a = sp.csc_matrix(a) if not sp.isspmatrix_csc(a) else a
    if a.dtype != np.float64:
        a = a.astype(np.float64)
    return a


class SymbolicCholesky:
    """A CHOLMOD symbolic analysis (fill-reducing ordering + elimination tree) reused across
    matrices sharing one sparsity pattern.

    ``threaded``: factor with CHOLMOD's BLAS on its threads (the matrices with dense separators of
    thousands of rows, ``posecrb.linalg.ordering.threaded_matrix``); otherwise with one thread,
    where threads cost more than they save and collapse under load (posecrb.linalg.threads).

    ``permutation`` (optional) is a fill-reducing ordering computed elsewhere
    (``posecrb.linalg.ordering``: COLAMD, or a pose-level ordering expanded to each pose's rows):
    scikit-sparse cannot hand CHOLMOD a user permutation, so the pattern is permuted here, analysed
    with the natural ordering, and every factored matrix is permuted the same way; the factor
    returned (``PermutedFactor``) solves, and reports ``P()``, in the caller's ordering.
    """

    def __init__(self, pattern: sp.spmatrix, mode: str = "auto", ordering_method: str = "default",
                 permutation: np.ndarray | None = None, threaded: bool = False):
        self.shape = pattern.shape
        self.threaded = threaded
        self._perm: np.ndarray | None = None
        if permutation is None:
            self._symbolic: Factor = analyze(_as_csc(pattern), mode=mode, ordering_method=ordering_method)
            return
        perm = np.asarray(permutation, dtype=np.int64)
        if perm.shape != (self.shape[0],) or not np.array_equal(np.sort(perm), np.arange(self.shape[0])):
            raise UsageError(f"the ordering is not a permutation of the {self.shape[0]} rows")
        self._perm = perm
        self._inverse_perm = np.empty_like(perm)
        self._inverse_perm[perm] = np.arange(perm.size)
        pat = _as_csc(pattern)
        # Gather map of the permuted CSC data: any matrix stored with exactly this pattern is
        # permuted by one fancy index of its data instead of scipy's two-sided slicing.
        self._pattern_indptr, self._pattern_indices = pat.indptr.copy(), pat.indices.copy()
        # (column j of the permuted matrix is column perm[j] with its rows renumbered, then sorted)
        counts = np.diff(pat.indptr)[perm]
        indptr = np.zeros(perm.size + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        source = np.repeat(pat.indptr[perm] - indptr[:-1], counts) + np.arange(pat.nnz, dtype=np.int64)
        marker = sp.csc_matrix((source, self._inverse_perm[pat.indices[source]], indptr), shape=pat.shape)
        marker.sort_indices()
        self._gather = marker.data
        self._permuted_indptr, self._permuted_indices = marker.indptr, marker.indices
        self._symbolic = analyze(sp.csc_matrix((np.ones(marker.nnz), marker.indices, marker.indptr),
                                               shape=pat.shape), mode=mode, ordering_method="natural")

    @property
    def permutation(self) -> np.ndarray:
        p = self._symbolic.P()
        return p if self._perm is None else self._perm[p]

    def _permuted(self, a: sp.csc_matrix) -> sp.csc_matrix:
        assert self._perm is not None
        if (a.nnz == self._gather.size and np.array_equal(a.indptr, self._pattern_indptr)
                and np.array_equal(a.indices, self._pattern_indices)):
            return sp.csc_matrix((a.data[self._gather], self._permuted_indices, self._permuted_indptr),
                                 shape=a.shape)
        b = a[self._perm][:, self._perm].tocsc()
        b.sort_indices()
        return b

    def factor(self, a: sp.spmatrix, name: str = "matrix", beta: float = 0.0) -> Factor:
        """Numeric factorization of ``a + beta I`` with this analysis; raises NotPositiveDefinite."""
        return self.factor_logdet(a, name, beta)[0]

    def factor_logdet(self, a: sp.spmatrix, name: str = "matrix", beta: float = 0.0) -> tuple[Factor, float]:
        """``factor`` and the log-determinant it already checked (no second pass over the factor)."""
        if a.shape != self.shape:
            raise UsageError(f"{name}: shape {a.shape} does not match the analysed pattern {self.shape}")
        a = _as_csc(a)
        if self._perm is not None:
            a = self._permuted(a)
        blas_threads = load_aware_threads() if self.threaded else cholmod_single_threaded()
        try:
            # CHOLMOD's own OpenMP team stays off: it cost more than its loops save (threads module)
            with blas_threads, cholmod_openmp_serial():
                f = self._symbolic.cholesky(a, beta=beta)
        except CholmodNotPositiveDefiniteError as exc:
            raise NotPositiveDefinite(name, str(exc).split(": ", 1)[-1]) from None
        if self._perm is not None:
            f = PermutedFactor(f, self._perm, self._inverse_perm, self._permuted)
        return f, _checked_logdet(f, name)


class PermutedFactor:
    """A CHOLMOD factor of ``A[perm][:, perm]`` presented as a factor of ``A``.

    ``L L^T = A[P()][:, P()]`` with ``P() = perm[inner.P()]``, and ``f(b)``/``solve_A`` solve with
    ``A`` itself, as for a ``Factor`` whose ordering CHOLMOD computed. The triangular solves
    (``solve_L``, ...) act in the factor's ordering, as CHOLMOD's do, so ``apply_P`` composes them.
    """

    def __init__(self, inner: Factor, perm: np.ndarray, inverse_perm: np.ndarray,
                 permute: Callable[[sp.csc_matrix], sp.csc_matrix] | None = None):
        self._inner = inner
        self._perm = perm
        self._p = perm[inner.P()]
        self._inverse_perm = inverse_perm   # row i of A is row inverse_perm[i] of the factored matrix
        self._permute = permute             # A -> A[perm][:, perm] (the analysis' gather map, when known)

    def permuted(self, a: sp.csc_matrix) -> sp.csc_matrix:
        """``a[perm][:, perm]`` with sorted indices: the matrix the inner factor factors; one gather of
        the data for a matrix stored with the analysed pattern (``SymbolicCholesky``)."""
        if self._permute is not None:
            return self._permute(a)
        b = a[self._perm][:, self._perm].tocsc()
        b.sort_indices()
        return b

    def P(self) -> np.ndarray:
        return self._p

    def apply_P(self, b):
        return b[self._p]

    def apply_Pt(self, b):
        out = np.empty_like(b)
        out[self._p] = b
        return out

    def solve_A(self, b):
        if sp.issparse(b):
            b = b.toarray()
        b = np.asarray(b)
        out = np.empty(b.shape, dtype=np.result_type(b.dtype, np.float64))
        out[self._perm] = self._inner.solve_A(b[self._perm])
        return out

    __call__ = solve_A

    def solve_tail(self, first: int, W: np.ndarray) -> np.ndarray:
        """Rows ``first:`` of ``A^{-1} [0; W]`` (:func:`solve_tail`), permuted straight into and out of
        the factor's ordering."""
        return _tail_solution(self._inner, self._perm.size, self._inverse_perm[first:], W)

    def __getattr__(self, name: str) -> Any:
        # L, D, LD, L_D, logdet, slogdet, det, solve_L, solve_Lt, solve_D, ...: ordering-free
        # or in the factor's ordering, as for CHOLMOD's own Factor.
        if name in ("cholesky", "cholesky_inplace", "cholesky_AAt", "cholesky_AAt_inplace", "update_inplace",
                    "inv", "copy"):
            raise AttributeError(f"PermutedFactor does not provide {name}")
        return getattr(self._inner, name)


def _tail_solution(factor: Factor, n: int, rows: np.ndarray | slice, W: np.ndarray) -> np.ndarray:
    """``x[rows]`` for ``factor``'s ``A x = b`` (n rows), b zero except ``b[rows] = W`` (W: (m, k))."""
    k = W.shape[1]
    # CHOLMOD solves column-major right-hand sides: build b in that layout, one contiguous column
    # at a time, so that scikit-sparse does not copy it again.
    b = np.zeros((k, n))
    for j in range(k):
        b[j, rows] = W[:, j]
    x = factor.solve_A(b.T)
    return np.take(x, rows, axis=0) if isinstance(rows, np.ndarray) else np.ascontiguousarray(x[rows])


def solve_tail(factor: Factor | PermutedFactor, first: int, W: np.ndarray) -> np.ndarray:
    """Rows ``first:`` of ``A^{-1} [0; W]`` for a factor of A: the Schur-complement solves of
    block matrices whose last block is the one of interest (``posecrb.solver.problem``).

    The result equals ``factor(b)[first:]`` with ``b`` zero above row ``first``, bit for bit; it only
    skips the full-size copies and layout conversions around CHOLMOD's solve, a sizeable part of a
    preconditioner solve of a large graph (docs/decisions/solver-preconditioners.md).
    """
    W = np.asarray(W, dtype=float)
    if isinstance(factor, PermutedFactor):
        return factor.solve_tail(first, W)
    return _tail_solution(factor, first + W.shape[0], slice(first, None), W)


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
    """Smallest eigenvalue of a sparse SPD matrix: 1 / the largest eigenvalue of its inverse
    (Lanczos, posecrb.linalg.lanczos), applied through a Cholesky factor.

    Reuses ``factor`` (a Cholesky factor of ``a``) as the inverse operator, so no
    extra factorization happens when the caller already has one. An eigensolver that does not
    converge raises NumericalError rather than returning its estimate.
    """
    a = _as_csc(a)
    n = a.shape[0]
    if n <= 200:
        return float(np.linalg.eigvalsh(a.toarray())[0])
    factor = factor or cholesky(a, name=name)
    ritz = largest_eigenpair(factor, np.ones(n), tol=1e-12, max_restarts=10 * n)   # ARPACK's default
    if not ritz.converged:
        raise NumericalError(f"{name}: Lanczos did not converge on the smallest eigenvalue "
                             f"(residual {ritz.residual:.2g} after {ritz.matvecs} products)")
    return 1.0 / ritz.value



def refactor(factor: Factor | PermutedFactor, a: sp.spmatrix, name: str = "matrix", *,
             in_place: bool = False) -> Factor | PermutedFactor:
    """Factor ``a``, a matrix with the sparsity pattern of the one ``factor`` factors, with
    ``factor``'s own symbolic analysis (its ordering and supernodes: no new analysis), on one BLAS
    thread. Raises NotPositiveDefinite when ``a`` is not positive definite: a successful call is an
    inertia check (``posecrb.linalg.accuracy``'s certified lower bound of an eigenvalue).
    ``in_place``: overwrite ``factor``'s values (its ordering stays) instead of a copy of it, for a
    caller that has no further use for them: no copy of the factor (a sizeable part of the call,
    docs/decisions/logdet-accuracy-tiers.md), and ``factor`` itself is returned."""
    a = _as_csc(a)
    inner = factor._inner if isinstance(factor, PermutedFactor) else factor
    if isinstance(factor, PermutedFactor):
        a = factor.permuted(a)
    try:
        with cholmod_single_threaded(), cholmod_openmp_serial():
            if in_place:
                inner.cholesky_inplace(a)
                f = inner
            else:
                f = inner.cholesky(a)
    except CholmodNotPositiveDefiniteError as exc:
        raise NotPositiveDefinite(name, str(exc).split(": ", 1)[-1]) from None
    out: Factor | PermutedFactor = f if not isinstance(factor, PermutedFactor) else \
        factor if in_place else PermutedFactor(f, factor._perm, factor._inverse_perm, factor._permute)
    _checked_logdet(out, name)
    return out
