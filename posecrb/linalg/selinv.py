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

The block form of the recurrences runs supernode by supernode from the root down, in place:
supernode ``J`` reads only its own columns of ``L`` and ``Z`` of its ancestors, so ``Z`` overwrites
a copy of ``L``'s values and the memory is that of the factor's nonzeros (its pattern, int32
rows, and one value each; CHOLMOD's own copy of the factor is the caller's) plus the dense
blocks of one supernode (``Z_SS`` gathered from the ancestors, at most the factor's size).
Supernodes at least ``_WIDE`` columns wide, the separators near the root that carry nearly all
the flops, go through LAPACK/BLAS (dtrsm, dpotri, dsymm, dgemm: about twice the flops of the
factorization); the narrow ones run in a loop compiled with numba (``cache=True``; the first call
in a process imports numba and loads the cached machine code, as much interpreter work as about
``_BLOCK_MAX_STEPS`` supernodes of the block kernels; the kernels live in
``posecrb.linalg._selinv_kernels``, imported only then). Small factors, whose whole inversion
costs less than that, never load numba: ``_BlockKernels`` takes every supernode through
LAPACK/BLAS with numpy's gathers and scatters (``inversion_steps`` counts its Python steps,
``_BLOCK_MAX_STEPS`` bounds them). Without numba the compiled code runs as plain Python,
correct but slow. numpy's BLAS runs with one thread (many small calls), except in the
supernodes of at least ``_THREADED_FLOPS``, the top separators of large graphs, which take the cores
no other process keeps busy (``posecrb.linalg.threads.python_blas_usable_threads``).
Per-pose blocks of the inverse are only guaranteed in the factor's pattern when the
matrix's own diagonal blocks are structurally full, so ``inverse_block_diagonal`` pads
them with explicit zeros before the analysis.
"""
from __future__ import annotations

import contextlib
import logging
from types import ModuleType

import numpy as np
import scipy.sparse as sp

from ..core.errors import NumericalError, UsageError
from ..core.status import OK, Status
from ._selinv_block import _BlockKernels
from .cholesky import Factor, SymbolicCholesky

log = logging.getLogger("posecrb")

EPS = float(np.finfo(float).eps)

def _kernels():
    """The compiled kernels (``posecrb.linalg._selinv_kernels``), imported on first use: numba's
    import is start-up work that commands which never invert anything should not pay."""
    from . import _selinv_kernels  # noqa: PLC0415 -- lazy: start-up time (numba)

    return _selinv_kernels


def supernode_bounds(indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Column boundaries of the supernodes of a closed Cholesky pattern (CSC, sorted rows,
    diagonal first): column j+1 joins column j's supernode when L[j+1, j] != 0 and
    |col j+1| = |col j| - 1 (then, the pattern being closed, both columns have the same structure
    below the supernode)."""
    n = indptr.size - 1
    if n < 2:
        return np.arange(n + 1, dtype=np.int64)
    count = np.diff(indptr)
    # the entry after column j's diagonal; every column holds its diagonal, so it exists for j < n - 1
    second = indices[np.minimum(indptr[:-2] + 1, indptr[-1] - 1)]
    joins = (count[:-1] > 1) & (second == np.arange(1, n)) & (count[1:] == count[:-1] - 1)
    return np.concatenate(([0], np.flatnonzero(~joins) + 1, [n])).astype(np.int64)


# Supernodes at least this wide go through LAPACK/BLAS from Python (triangular solve, dpotri,
# symmetric product), one call each; narrower ones run inside one compiled loop. On nested-
# dissection orderings of pose graphs the wide ones are the few hundred separators near the root
# that carry nearly all the flops (3D grid of 21,952 poses: 344 of 11,239 supernodes, 99% of the
# Z_SS Y products), so the Python loop over them is small next to their BLAS calls.
_WIDE = 32

# Wide supernodes whose inversion takes at least this many flops (``_supernode_flops``) run
# numpy's BLAS on its threads (``python_blas_usable_threads``); below it threads cost more than
# they save.
_THREADED_FLOPS = 1e9

# A factor is inverted without numba (``_BlockKernels``) when the block kernels' overhead, counted
# in steps of their Python loop (``inversion_steps``), is at most what numba's import and cache load
# cost: one step per supernode (a dozen numpy and BLAS calls on its blocks) and one per
# ``_ENTRIES_PER_STEP`` entries of the ``Z_SS`` blocks it gathers by fancy indexing. Both are counts
# of interpreter work, so the threshold is a ratio of costs on one interpreter, not seconds on one
# machine: on the shared datasets' FIMs a step cost as much CPU as 400-450 gathered entries, and a
# fresh process's numba import and first compiled call as much as 7,600-9,500 steps
# (docs/decisions/logdet-accuracy-tiers.md). The flops are the same on both paths (LAPACK/BLAS for
# every wide supernode) and do not enter. A caller that inverts many factors in one process (a
# selection's iterations) shares numba's one-time cost and takes the compiled kernels
# (``repeated``): with the block kernels at every iteration, `select --method relax` on intel took
# several times longer in-process (docs/decisions/selected-inversion-kernels.md).
_ENTRIES_PER_STEP = 400
_BLOCK_MAX_STEPS = 8_000.0


def _supernode_flops(w: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Flops of ``_wide_supernode`` without the accuracy sum for ``w`` columns with ``s`` rows below:
    dsymm ``2 s^2 w``, dgemm ``2 s w^2``, dtrsm ``s w^2``, dpotri ``2 w^3 / 3``."""
    return 2.0 * s * s * w + 3.0 * s * w * w + 2.0 * w ** 3 / 3.0


def _wide_supernode(k: ModuleType | _BlockKernels, indptr: np.ndarray, indices: np.ndarray, val: np.ndarray,
                    bounds: np.ndarray, col2sn: np.ndarray, sn: int, posbuf: np.ndarray,
                    terms: np.ndarray) -> str | None:
    """The block Takahashi step of supernode ``sn`` through LAPACK/BLAS, in place on ``val``
    (see ``_selinv_kernels._takahashi_range``): ``Y = L_SJ L_JJ^{-1}`` (dtrsm),
    ``(L_JJ L_JJ^T)^{-1}`` (dpotri, a third of the flops of an explicit inverse and product),
    ``Z_SJ = -Z_SS Y`` (dsymm), ``Z_JJ -= Y^T Z_SJ`` (dgemm); where ``terms`` has an entry,
    ``terms[0]`` accumulates the supernode's ``_abs_quadratic`` in three parts, each with the fewest
    flops: ``sum(|Z_SS| o |L_SJ| |L_SJ|^T)`` through the symmetric rank-w product (dsyrk: half the
    flops of a product with ``|Z_SS|``), ``sum(|Z_JJ| o |L_JJ| |L_JJ|^T)`` through the product of two
    triangles (dlauum: a third of a general product) and twice ``sum(|L_SJ| o |Z_SJ| |L_JJ|)``
    (dtrmm: half). Returns None or why it failed."""
    from scipy.linalg.blas import dgemm, dsymm, dsyrk, dtrmm, dtrsm  # noqa: PLC0415 -- lazy, like the kernels
    from scipy.linalg.lapack import dlauum, dpotri  # noqa: PLC0415

    j0 = int(bounds[sn])
    w = int(bounds[sn + 1]) - j0
    s = int(indptr[j0 + 1] - indptr[j0]) - w
    ljj = np.zeros((w, w), order="F")
    lsj = np.empty((s, w), order="F")
    k._gather_l(indptr, val, j0, w, s, ljj, lsj)
    want = terms.size > 0
    if want:
        vj, vs = np.abs(ljj), np.abs(lsj)
    y = dtrsm(1.0, ljj, lsj, side=1, lower=1, overwrite_b=1) if s else lsj
    zjj, info = dpotri(ljj, lower=1, overwrite_c=1)
    if info:
        return f"zero pivot in the diagonal block of columns {j0}..{j0 + w - 1}"
    if s:
        zss = np.empty((s, s), order="F")   # lower half only: dsymm and the sum below read no other
        if k._gather_zss(indptr, indices, val, bounds, col2sn, j0, w, s, zss, posbuf, False):
            return f"Cholesky pattern not closed at column {j0}"
        zsj = dsymm(-1.0, zss, y, side=0, lower=1)
        if want:
            terms[0] += k._abs_lower_dot(zss, dsyrk(1.0, vs, lower=1))
        del zss
        zjj = dgemm(-1.0, y, zsj, beta=1.0, c=zjj, trans_a=1, overwrite_c=1)   # valid below the diagonal
    else:
        zsj = y
    if want:
        # |L_JJ| |L_JJ|^T = R (U U^T) R with U = R |L_JJ| R upper triangular, R the reversal
        uut, _ = dlauum(np.array(vj[::-1, ::-1], order="F"), lower=0, overwrite_c=1)   # a copy: vj is read below
        terms[0] += k._abs_lower_dot(zjj, np.asfortranarray(uut[::-1, ::-1]))
        if s:
            azsj = dtrmm(1.0, vj, np.abs(zsj), side=1, lower=1, overwrite_b=1)
            terms[0] += 2.0 * float(np.einsum("ij,ij->", vs, azsj))
    k._scatter(indptr, val, j0, w, s, zjj, zsj)
    return None


def _inversion_kernels(indptr: np.ndarray, indices: np.ndarray, bounds: np.ndarray,
                       repeated: bool = False) -> ModuleType | _BlockKernels:
    """The kernels for a factor with supernodes ``bounds``: numpy's (``_BlockKernels``) where
    ``inversion_steps`` is within ``_BLOCK_MAX_STEPS``, the compiled ones otherwise, and
    always the compiled ones for ``repeated`` inversions (``SelectedInverse``). The choice depends
    on the factor and the caller alone, so one matrix always gets the same digits from a caller."""
    if not repeated and inversion_steps(indptr, bounds) <= _BLOCK_MAX_STEPS:
        return _BlockKernels(indptr, indices)
    return _kernels()


def inversion_steps(indptr: np.ndarray, bounds: np.ndarray) -> float:
    """Steps of ``_BlockKernels``' Python loop on a factor (CSC ``indptr``, supernodes ``bounds``):
    one per supernode and one per ``_ENTRIES_PER_STEP`` entries of the lower triangles of the
    ``Z_SS`` blocks it gathers, ``s (s + 1) / 2`` for a supernode with ``s`` rows below it."""
    width = np.diff(bounds)
    below = (indptr[bounds[:-1] + 1] - indptr[bounds[:-1]] - width).astype(float)
    entries = float(np.sum(below * (below + 1) / 2))
    return width.size + entries / _ENTRIES_PER_STEP


def _takahashi_inplace(indptr: np.ndarray, indices: np.ndarray, val: np.ndarray,
                       terms: np.ndarray | None = None, bounds: np.ndarray | None = None,
                       k: ModuleType | _BlockKernels | None = None) -> str | None:
    """Overwrite ``val`` (the values of ``L``, CSC with sorted rows, diagonal first) with
    ``Z = (L L^T)^{-1}`` on the same pattern: supernode by supernode from the root down, the
    wide ones through LAPACK (``_wide_supernode``), runs of narrow ones in one compiled call.
    In place because supernode ``J`` reads only its own ``L`` and its ancestors' ``Z``: no
    second array of the factor's size. ``terms`` (one entry): accumulates
    ``sum_ij |Z_ij| (|L| |L^T|)_ij`` on the way (``SelectedInverse.absolute_terms``). Returns None
    or why it failed. ``bounds`` (``supernode_bounds``) and ``k`` (``_inversion_kernels``) are
    computed here when not given. With the block kernels every supernode is a step of the Python
    loop below; they are only chosen where ``inversion_steps`` bounds those steps (at most
    ``_BLOCK_MAX_STEPS``), so the loop does not grow with the dataset."""
    terms = np.zeros(0) if terms is None else terms
    n = indptr.size - 1
    bounds = supernode_bounds(indptr, indices) if bounds is None else bounds
    k = _inversion_kernels(indptr, indices, bounds) if k is None else k
    col2sn = np.repeat(np.arange(bounds.size - 1, dtype=np.int64), np.diff(bounds))
    posbuf = np.empty(n, np.int64)
    # the block kernels take every supernode through LAPACK; the compiled ones the wide ones only
    wide = np.flatnonzero(np.diff(bounds) >= (_WIDE if isinstance(k, ModuleType) else 0))
    hi = bounds.size - 1
    # The largest separators run on every core no other process keeps busy (3D grid of 21,952
    # poses: the supernodes of at least 10^9 flops carry nearly all of the inversion's flops)
    widths = np.diff(bounds)[wide].astype(float)
    below = (indptr[bounds[wide] + 1] - indptr[bounds[wide]]) - widths
    big = wide[_supernode_flops(widths, below) >= _THREADED_FLOPS]
    import scipy.linalg.blas  # noqa: F401, PLC0415 -- loads scipy's BLAS before its threads are set

    from .threads import python_blas, python_blas_usable_threads  # noqa: PLC0415

    threads = python_blas_usable_threads() if big.size else 1
    threaded = set(big.tolist()) if threads > 1 else set()
    # Otherwise one BLAS thread (numpy's/scipy's own OpenBLAS): the calls are many and mostly small, where
    # OpenBLAS threads only add synchronisation, and its threads collapse when another process
    # holds a core (on a loaded 2-core machine, 2D grids' inversions took an order of magnitude
    # longer with two threads than with one: docs/decisions/blas-threads.md). The factorization
    # before it runs CHOLMOD's BLAS under its own policy (posecrb.linalg.threads).
    blas = python_blas()
    with blas.limit(limits=1):
        for sn in [*wide[::-1].tolist(), -1]:
            status = k._takahashi_range(indptr, indices, val, bounds, col2sn, hi, sn + 1, posbuf, terms)
            if status:
                return f"Cholesky pattern not closed at column {status - 1}"
            if sn >= 0:
                with blas.limit(limits=threads) if sn in threaded else contextlib.nullcontext():
                    why = _wide_supernode(k, indptr, indices, val, bounds, col2sn, sn, posbuf, terms)
                if why:
                    return why
            hi = sn
    return None


# Above this lower bound on the scaled condition number, ``SelectedInverse.status`` warns: fewer
# than about six correct digits in the largest entries of the inverse.
WARN_CONDITION = 1e-6 / EPS


def _condition_status(bound: float, name: str) -> Status:
    if bound * EPS >= 1.0:
        return Status.unavailable(
            f"the {name} is numerically singular: its diagonally scaled condition number is at least "
            f"{bound:.2g}, so the computed inverse has no correct digit",
            "some unknowns are (nearly) unobservable")
    if bound > WARN_CONDITION:
        return Status.warning(
            f"the {name} is ill-conditioned (diagonally scaled condition number at least {bound:.2g}): "
            f"entries of its inverse may carry relative errors up to about {bound * EPS:.1g}")
    return OK


class SelectedInverse:
    """Entries of ``A^{-1}`` on the (permuted) pattern of the Cholesky factor of ``A``.

    Memory: the factor's pattern (int32 rows) and one value per nonzero, ``Z`` computed over a
    copy of ``L``'s values, plus dense blocks of the widest supernode.

    ``condition_lower_bound = max_j A_jj (A^{-1})_jj`` is a lower bound on the 2-norm condition
    number of the diagonally scaled ``D^{-1/2} A D^{-1/2}`` (its inverse's diagonal entries are
    at most its largest eigenvalue's inverse, and its largest eigenvalue is at least 1), the
    number that governs the accuracy of a Cholesky-based inverse (van der Sluis). ``status`` is
    *unavailable* when it reaches ``1 / eps`` (the inverse has no correct digit) and a *warning*
    above ``WARN_CONDITION``: a cheap necessary check; callers that report an accuracy estimate
    (``posecrb.models.paper.crlb.inverse_accuracy``) keep theirs.

    ``repeated``: the caller inverts many factors in one process (a selection's iterations), so the
    compiled kernels' one-time cost is shared and they are used whatever the factor's size; by
    default small factors are inverted without numba (``_inversion_kernels``). ``lower``: the
    factor's L as CSC with sorted rows when the caller has it already; its values are then
    overwritten with the inverse's (no second copy of the factor).
"""

    def __init__(self, factor: Factor, name: str = "matrix", absolute_terms: bool = False,
                 repeated: bool = False, lower: sp.csc_matrix | None = None) -> None:
        if lower is None:
            lower = factor.L()
            if not sp.isspmatrix_csc(lower):  # pragma: no cover - CHOLMOD returns CSC
                lower = sp.csc_matrix(lower)
            lower.sort_indices()  # CHOLMOD's are sorted: a check only
        self.perm = np.asarray(factor.P(), dtype=np.int64)
        self.iperm = np.empty_like(self.perm)
        self.iperm[self.perm] = np.arange(self.perm.size)
        self.indptr = lower.indptr.astype(np.int64)
        self.indices = lower.indices
        zval = np.require(lower.data, dtype=np.float64, requirements=["C", "W"])
        del lower
        bounds = supernode_bounds(self.indptr, self.indices)
        self._kernels = _inversion_kernels(self.indptr, self.indices, bounds, repeated)
        a_diag = self._kernels._row_squares(self.indptr, self.indices, zval, self.perm.size)   # diag(L L^T)
        terms = np.zeros(1 if absolute_terms else 0)
        why = _takahashi_inplace(self.indptr, self.indices, zval, terms, bounds, self._kernels)
        if why is None:
            bad = int(self._kernels._count_nonfinite(zval))
            if bad:
                why = f"{bad} entries of the selected inverse are not finite"
            else:
                d = zval[self.indptr[:-1]]
                if not (d > 0).all():
                    why = (f"{int((~(d > 0)).sum())} diagonal entries of the inverse come out non-positive "
                           "(not positive definite to working precision)")
        if why:
            raise NumericalError(f"{name}: selected inversion (Takahashi recurrences) failed: {why}")
        self.zval = zval
        # ``sum_ij |Z_ij| (|L| |L^T|)_ij`` (with ``absolute_terms``, else None): the log-det's
        # componentwise condition number (posecrb.linalg.accuracy), one more product per supernode.
        self.absolute_terms = float(terms[0]) if absolute_terms else None
        self.n = self.perm.size
        self.condition_lower_bound = float(np.max(a_diag * zval[self.indptr[:-1]], initial=1.0))
        self.status = _condition_status(self.condition_lower_bound, name)

    def diagonal(self) -> np.ndarray:
        """diag(A^{-1}) in the original ordering."""
        return self.zval[self.indptr[:-1]][self.iperm]

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(A^{-1})[rows, cols] (original ordering); NaN where not in the factor's pattern."""
        a = self.iperm[np.asarray(rows, dtype=np.int64)]
        b = self.iperm[np.asarray(cols, dtype=np.int64)]
        return self._kernels._lookup(self.indptr, self.indices, self.zval, np.maximum(a, b), np.minimum(a, b))


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
