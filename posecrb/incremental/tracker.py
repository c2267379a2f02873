"""Log-determinants of growing sums of rank-one terms, tracked step by step on one factor.

A *family* is one matrix of the timeline (the translation Laplacian, the rotation Laplacian, the
``ub`` matrix, the FIM), written as a sum of terms ``U U^T`` of sparse rank-r blocks, each with
the step at which it enters (``-1``: present from the start). Families whose matrices share one
sparsity pattern form a *group*: one symbolic analysis, one elimination tree, and their factors
updated together by ``posecrb.incremental._kernels.path_updates`` (one traversal of the tree paths
for all of them).

Every family also has a closed-form part: ``closed[t]`` is what step t adds to the log-det of the
full-size matrix's future part (``posecrb.incremental.compute``), so that the prefix's log-det after
step t is ``log det(full-size matrix) - sum_{s > t} closed[s]``.

Checkpoints: at chosen steps every family is factored from scratch (CHOLMOD, the group's
analysis) and compared with the tracked value; the tracked factors then restart from the fresh
ones, so rounding never accumulates past one segment. The *tolerance* bounds the rounding of both
sides of the comparison:

* the pivots of the fresh factorizations, from their conditioning: the pivot ``l_jj^2`` is
  computed as ``a_jj`` minus the ``c_j`` squared entries of row j, so its relative error is about
  ``c_j eps a_jj / l_jj^2`` and the log-determinant's about ``eps sum_j c_j a_jj / l_jj^2`` (an
  estimate, taken ``TOLERANCE_MARGIN`` times);
* every sum the two sides are made of, each by a rigorous bound on its rounding error (taken
  ``SUM_MARGIN`` times, for the rounding of the bounds' own evaluation): the N-term sum of the
  fresh factor's ``log l_jj^2`` (in an order CHOLMOD's wrapper chooses: ``(N - 1) u sum |terms|``
  for any order, plus the logarithms' own rounding), the suffix sums of the closed forms and the
  segment's running sums of increments and closed forms (recursive summation:
  ``u sum_k |partial sum_k|``, Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed.,
  section 4.2), and the subtractions between them. On a long chain these sums, not the
  factorization, dominate: their rounding grows with the number of terms, about ``n u`` times the
  values compared.

A segment whose drift exceeds the tolerance is recomputed in halves from its starting factor (down
to single steps, whose rows are the fresh values themselves); the segments double while the drift
stays under a quarter of it.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..core.errors import InternalError, NotPositiveDefinite
from ..core.status import OK, Status
from ..linalg.cholesky import SymbolicCholesky

# The drift tolerance is this many times the rounding level of a fresh factorization (an estimate
# from the pivots' conditioning), plus SUM_MARGIN times the rounding bounds of the sums compared
# (rigorous; the margin covers their own evaluation in floating point) (module docstring).
TOLERANCE_MARGIN = 16.0
SUM_MARGIN = 2.0
# Rank-one updates applied in one traversal of the elimination tree (columns of the work array).
BATCH = 16
# Vectors per kernel call (signals are handled between calls, and a call of this many is short).
CALL = 2048
# The first segment holds about 1/FIRST_SEGMENTS of the updates of the range (then 1/2, then the rest
# while the drift stays small: three checkpoints after the start).
FIRST_SEGMENTS = 4
_EPS = float(np.finfo(float).eps)
_U = 0.5 * _EPS                      # unit roundoff: |fl(a + b) - (a + b)| <= u |a + b|


@dataclass(frozen=True, eq=False)
class Parts:
    """Terms ``U_k U_k^T`` of one family on ``rows[k]`` (K, P) (-1: no row, e.g. the anchor's), with
    ``U`` (K, P, r); ``enter`` (K,) the step at which each enters (-1: from the start) and ``rank``
    (K,) the processing position of its edge (``Schedule.order``), which orders a step's terms."""

    rows: np.ndarray
    U: np.ndarray
    enter: np.ndarray
    rank: np.ndarray


@dataclass(eq=False)
class Family:
    """One matrix: its term sets and ``closed`` (n,), the closed-form log-det each step adds to the
    full-size matrix's future part."""

    name: str
    parts: list[Parts]
    closed: np.ndarray


@dataclass(eq=False)
class Tracked:
    """Tracking one family over a range of steps: ``values`` (n,) the prefix log-det after each step
    of the range (NaN outside it), ``increments`` per term set (K,) each term's sequential
    increment (0 outside the range and for terms present from the start), ``status``,
    ``checkpoints`` (the steps factored from scratch), ``max_drift`` (largest |tracked - fresh| at
    an accepted checkpoint) and ``tolerance`` (the largest tolerance it was held to)."""

    values: np.ndarray
    increments: list[np.ndarray]
    status: Status = OK
    checkpoints: list[int] = field(default_factory=list)
    max_drift: float = 0.0
    tolerance: float = 0.0


def drift_tolerance(level: np.ndarray, rounding: np.ndarray) -> np.ndarray:
    """Per family: the largest |tracked - fresh| accepted at a checkpoint: ``TOLERANCE_MARGIN`` times
    the rounding ``level`` of the factorizations plus ``SUM_MARGIN`` times ``rounding``, the bound on
    the rounding of the sums compared (module docstring)."""
    return TOLERANCE_MARGIN * level + SUM_MARGIN * rounding


def recursive_sum_error(partial: np.ndarray) -> np.ndarray:
    """Bound on the rounding error of each partial sum of a recursive (left to right) summation
    along the last axis, from the computed partial sums ``partial`` themselves:
    ``|s^_k - s_k| <= u sum_{i <= k} |s^_i|`` (Higham, *Accuracy and Stability of Numerical
    Algorithms*, 2nd ed., section 4.2; ``numpy.cumsum`` sums recursively)."""
    return _U * np.cumsum(np.abs(partial), axis=-1)


def _suffix(closed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``out[..., t] = sum_{s > t} closed[..., s]`` and the bound on its rounding error."""
    total = np.cumsum(closed[..., ::-1], axis=-1)            # recursive, from the last step back
    error = recursive_sum_error(total)[..., ::-1]
    pad = np.zeros(closed.shape[:-1] + (1,))
    return (np.concatenate([total[..., ::-1][..., 1:], pad], axis=-1),
            np.concatenate([error[..., 1:], pad], axis=-1))


def _logdet_sum_error(two_log_pivots: np.ndarray) -> float:
    """Bound on the rounding error of a log-determinant summed from its N terms ``log l_jj^2`` in
    any order, ``(N - 1) u sum |terms|`` (Higham, section 4.2), plus ``2 u |term|`` per term for
    the logarithm's own rounding (within one unit in the last place)."""
    return float((two_log_pivots.size + 1) * _U * np.sum(np.abs(two_log_pivots)))


class Group:
    """Families sharing one pattern of ``size`` rows; ``pose_of_row`` (size,) maps rows to poses
    (0..n_poses-1) for the pose-level ordering; ``n`` is the number of steps (poses)."""

    def __init__(self, families: list[Family], size: int, pose_of_row: np.ndarray, n_poses: int, n: int):
        self.families = families
        self.size = size
        self.n = n
        self._pattern(np.asarray(pose_of_row, dtype=np.int64), n_poses)
        self._vectors()

    # ------------------------------------------------------------------ pattern and analysis
    def _pattern(self, pose_of_row: np.ndarray, n_poses: int) -> None:
        from ..linalg.ordering import expand_permutation, pose_permutation  # noqa: PLC0415 -- lazy: start-up time

        size = self.size
        # every entry any term of any family can touch, and the diagonal: each family's matrix
        # lists all of them (zeros where it has nothing), so all have the analysed pattern
        rows, cols = [np.arange(size)], [np.arange(size)]
        self._slots: list[list[tuple[int, int, np.ndarray]]] = []
        at = size
        for fam in self.families:
            slots = []
            for pt in fam.parts:
                p = pt.rows.shape[1]
                r = np.repeat(pt.rows, p, axis=1).ravel()
                c = np.tile(pt.rows, (1, p)).ravel()
                ok = (r >= 0) & (c >= 0)
                rows.append(r[ok])
                cols.append(c[ok])
                slots.append((at, at + int(ok.sum()), ok))
                at += int(ok.sum())
            self._slots.append(slots)
        self._rows, self._cols = np.concatenate(rows), np.concatenate(cols)
        pattern = self._csc(np.ones(at))
        # Nested dissection of the pose graph: the updates walk elimination-tree paths, whose cost
        # is the factor's column counts along them (on city10000 0.62x of AMD's).
        coo = pattern.tocoo()
        pose_adj = sp.csc_matrix((coo.data, (pose_of_row[coo.row], pose_of_row[coo.col])), shape=(n_poses, n_poses))
        try:
            pose_perm = pose_permutation(pose_adj, "metis")
        except Exception:  # pragma: no cover - CHOLMOD built without METIS
            pose_perm = pose_permutation(pose_adj, "amd")
        self.symbolic = SymbolicCholesky(pattern, mode="simplicial",
                                         permutation=expand_permutation(pose_perm, pose_of_row))

    def _csc(self, values: np.ndarray) -> sp.csc_matrix:
        """The group's pattern with ``values`` at the entries ``(self._rows, self._cols)`` (duplicates
        summed, zeros kept: always the same structure)."""
        return sp.coo_matrix((values, (self._rows, self._cols)), shape=(self.size, self.size)).tocsc()

    def _structure(self, low: sp.csc_matrix, perm: np.ndarray) -> None:
        """The factor's pattern (zeros stay entries), its elimination tree and the kernel's rows."""
        size = self.size
        self.lindptr = low.indptr.astype(np.int64)
        self.lindices = low.indices.astype(np.int64)
        if np.any(self.lindices[self.lindptr[:-1]] != np.arange(size)):  # pragma: no cover - CHOLMOD's L
            raise InternalError("Cholesky factor without its diagonal first in every column")
        has_sub = np.diff(self.lindptr) > 1
        self.parent = np.full(size, -1, dtype=np.int64)
        self.parent[has_sub] = self.lindices[self.lindptr[:-1][has_sub] + 1]
        self.perm = perm
        self.iperm = np.empty_like(perm)
        self.iperm[perm] = np.arange(size)
        self.rowcount = np.bincount(self.lindices, minlength=size)
        self.k_rows = np.where(self.v_rows >= 0, self.iperm[np.maximum(self.v_rows, 0)], -1)

    def matrix(self, k: int, step: int) -> sp.csc_matrix:
        """Family k's full-size matrix after ``step``, on the group's pattern (terms not yet entered
        are explicit zeros, so every matrix has the analysed pattern)."""
        values = np.zeros(self._rows.size)
        for pt, (a, b, ok) in zip(self.families[k].parts, self._slots[k], strict=True):
            live = (pt.enter <= step).astype(float)
            block = np.einsum("kar,kbr->kab", pt.U, pt.U) * live[:, None, None]
            values[a:b] = block.ravel()[ok]
        return self._csc(values)

    # ------------------------------------------------------------------ update vectors
    def _vectors(self) -> None:
        """Every column of every entering term as one kernel vector, in processing order."""
        rows, vals, fam, step, rank, ident = [], [], [], [], [], []
        self.p = max([pt.rows.shape[1] for f in self.families for pt in f.parts] + [1])
        for k, f in enumerate(self.families):
            for s, pt in enumerate(f.parts):
                kk, p, r = pt.U.shape
                rr = np.full((kk, r, self.p), -1, dtype=np.int64)
                rr[:, :, :p] = pt.rows[:, None, :]
                vv = np.zeros((kk, r, self.p))
                vv[:, :, :p] = np.transpose(pt.U, (0, 2, 1))
                rr = np.where(vv != 0.0, rr, -1)
                keep = (rr >= 0).any(axis=2) & (pt.enter >= 0)[:, None]
                nk = int(keep.sum())
                rows.append(rr[keep])
                vals.append(vv[keep])
                fam.append(np.full(nk, k, dtype=np.int64))
                step.append(np.broadcast_to(pt.enter[:, None], (kk, r))[keep])
                rank.append(np.broadcast_to(pt.rank[:, None], (kk, r))[keep])
                term = np.broadcast_to(np.arange(kk)[:, None], (kk, r))[keep]
                ident.append(np.stack([np.full(nk, s, dtype=np.int64), term], axis=1))
        v_rows = np.concatenate(rows) if rows else np.zeros((0, self.p), dtype=np.int64)
        order = np.lexsort((np.concatenate(rank), np.concatenate(step))) if rows else np.zeros(0, dtype=np.int64)
        self.v_rows = np.ascontiguousarray(v_rows[order])
        self.v_vals = np.ascontiguousarray((np.concatenate(vals) if rows else np.zeros((0, self.p)))[order])
        self.v_fam = (np.concatenate(fam) if rows else np.zeros(0, dtype=np.int64))[order]
        self.v_step = (np.concatenate(step) if rows else np.zeros(0, dtype=np.int64))[order]
        self.v_id = (np.concatenate(ident) if rows else np.zeros((0, 2), dtype=np.int64))[order]
        self.v_start = np.searchsorted(self.v_step, np.arange(self.n + 1))   # step s: v_start[s]:v_start[s+1]

    # ------------------------------------------------------------------ factors
    def _fresh(self, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[Status]]:
        """Every family's full-size matrix after ``step`` factored from scratch: lval (nnz, F),
        log-dets (F,), the rounding levels of their pivots (F,) and the rounding bounds of their sums
        (F,) (NaN where the factorization failed), and statuses. The first factorization also gives
        the factor's structure."""
        nf = len(self.families)
        factors: list[sp.csc_matrix | None] = [None] * nf
        logdets = np.full(nf, np.nan)
        levels = np.full(nf, np.nan)
        sum_errors = np.full(nf, np.nan)
        statuses = [OK] * nf
        diags = []
        for k, fam in enumerate(self.families):
            a = self.matrix(k, step)
            diags.append(a.diagonal())
            try:
                f, ld = self.symbolic.factor_logdet(a, name=fam.name)
            except NotPositiveDefinite as exc:
                statuses[k] = Status.unavailable(
                    f"{fam.name} after step {step}: the factorization from scratch breaks down in double "
                    f"precision ({exc.reason})")
                continue
            low = sp.csc_matrix(f.L())
            low.sort_indices()
            if not hasattr(self, "lindptr"):
                self._structure(low, np.asarray(f.P(), dtype=np.int64))
            elif not (np.array_equal(low.indptr, self.lindptr) and np.array_equal(low.indices, self.lindices)):
                raise InternalError(f"{fam.name}: the factor's pattern differs from the analysed one")
            factors[k] = low
            logdets[k] = ld
        if not hasattr(self, "lindptr"):      # every factorization failed: the structure of the identity's
            eye = self._csc(np.concatenate([np.ones(self.size), np.zeros(self._rows.size - self.size)]))
            f = self.symbolic.factor(eye, name="pattern")
            low = sp.csc_matrix(f.L())
            low.sort_indices()
            self._structure(low, np.asarray(f.P(), dtype=np.int64))
        lval = np.zeros((self.lindices.size, nf))
        for k, low in enumerate(factors):
            if low is None:
                lval[self.lindptr[:-1], k] = 1.0           # a placeholder; the family is unavailable
                continue
            lval[:, k] = low.data
            d = low.data[self.lindptr[:-1]]
            levels[k] = _EPS * float(np.sum(self.rowcount * diags[k][self.perm] / (d * d)))
            sum_errors[k] = _logdet_sum_error(2.0 * np.log(d))
        return lval, logdets, levels, sum_errors, statuses

    # ------------------------------------------------------------------ tracking
    def track(self, first: int, last: int) -> list[Tracked]:
        """Prefix log-dets of every family after each step ``first..last`` (1 <= first <= last): the
        factors start fresh after step ``first - 1`` and restart fresh at every checkpoint."""
        from ._kernels import path_updates  # noqa: PLC0415 -- lazy: numba

        nf, n = len(self.families), self.n
        closed = np.array([fam.closed for fam in self.families]).reshape(nf, n)
        before, before_err = _suffix(closed)
        values = np.full((nf, n), np.nan)
        inc = np.zeros(self.v_rows.shape[0])
        checkpoints: list[int] = []
        max_drift, tol_max = np.zeros(nf), np.zeros(nf)

        c = first - 1
        lval, ld, level, ld_err, statuses = self._fresh(c)
        base = ld - before[:, c] if c > 0 else np.zeros(nf)        # one pose: the empty matrix, 0
        # rounding bound of base (0 is exact; the start factor's own rounding is in ``level``)
        base_err = self._fresh_error(ld, ld_err, before[:, c], before_err[:, c]) if c > 0 else np.zeros(nf)
        checkpoints.append(c)
        counts = self.v_start[1:]                                  # vectors entered up to each step
        budget = max(1, -(-int(counts[last] - counts[c]) // FIRST_SEGMENTS))
        mark = np.zeros(self.size, dtype=np.int64)
        work = np.zeros((BATCH, self.size))
        span = last                                                # longest segment, in steps
        while c < last:
            c2 = int(np.searchsorted(counts, counts[c] + budget, side="left"))
            c2 = min(max(c2, c + 1), last, c + span)
            lo, hi = int(self.v_start[c + 1]), int(self.v_start[c2 + 1])
            saved = lval.copy()
            seg = self._run(path_updates, lval, lo, hi, mark, work)
            run, run_err = self._running(seg, lo, hi, c, c2, base, closed)
            lval2, ld2, level2, ld_err2, st2 = self._fresh(c2)
            fresh = ld2 - before[:, c2]
            fresh_err = self._fresh_error(ld2, ld_err2, before[:, c2], before_err[:, c2])
            tol = drift_tolerance(np.fmax(level2, level), base_err + run_err + fresh_err)
            drift = np.abs(run[:, -1] - fresh)
            bad = np.isfinite(fresh) & ~(drift <= tol)
            if bad.any() and c2 > c + 1:
                lval[:] = saved                    # recompute the segment in halves
                budget = max(1, budget // 2)
                span = max(1, (c2 - c) // 2)
                continue
            values[:, c + 1: c2 + 1] = run
            inc[lo:hi] = seg
            for kb in np.flatnonzero(bad).tolist():
                # one step and still beyond the tolerance: its row is the fresh value, but the
                # increments of its updates (the loop-closure gains) are not verified
                if statuses[kb].ok:
                    statuses[kb] = Status.warning(
                        f"{self.families[kb].name}: drift {drift[kb]:.3g} above the tolerance {tol[kb]:.3g} within "
                        f"step {c2} (rows are factorizations from scratch there; its loop-closure gains are "
                        "not verified)")
            ok = np.isfinite(fresh)
            values[ok, c2] = fresh[ok]
            base = np.where(ok, fresh, run[:, -1])   # a failed factorization: keep the tracked factor
            base_err = np.where(ok, fresh_err, base_err + run_err)
            lval[:, ok] = lval2[:, ok]
            max_drift[ok] = np.maximum(max_drift[ok], drift[ok])
            tol_max[ok] = np.maximum(tol_max[ok], tol[ok])
            level = np.where(np.isfinite(level2), level2, level)
            statuses = [st2[k] if statuses[k].ok else statuses[k] for k in range(nf)]
            checkpoints.append(c2)
            if np.all(drift[ok] <= 0.25 * tol[ok]):
                budget *= 2
                span = 2 * span
            c = c2
        out = []
        for k in range(nf):
            per_set = []
            for s, pt in enumerate(self.families[k].parts):
                sel = (self.v_fam == k) & (self.v_id[:, 0] == s)
                arr = np.zeros(pt.U.shape[0])
                np.add.at(arr, self.v_id[sel, 1], inc[sel])
                per_set.append(arr)
            out.append(Tracked(values=values[k], increments=per_set, status=statuses[k],
                               checkpoints=list(checkpoints), max_drift=float(max_drift[k]),
                               tolerance=float(tol_max[k])))
        return out

    @staticmethod
    def _fresh_error(ld: np.ndarray, ld_err: np.ndarray, before: np.ndarray, before_err: np.ndarray) -> np.ndarray:
        """Rounding bound of a fresh prefix value ``ld - before``: of the log-det's sum, of the
        closed forms' suffix sum and of the subtraction."""
        return ld_err + before_err + _U * (np.abs(ld) + np.abs(before))

    def _running(self, seg: np.ndarray, lo: int, hi: int, c: int, c2: int, base: np.ndarray,
                 closed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tracked prefix values after steps ``c + 1..c2`` (F, c2 - c): ``base`` plus the running
        sum of each step's increments ``seg`` (of vectors ``lo:hi``) and closed forms; and the
        rounding bound of the last: the per-step sums of k increments (``(k - 1) u sum |x|``), the
        additions of the closed forms, the running sum and the addition of ``base``."""
        nf, steps = len(self.families), c2 - c
        where = self.v_fam[lo:hi] * steps + (self.v_step[lo:hi] - (c + 1))
        per = np.bincount(where, weights=seg, minlength=nf * steps).reshape(nf, steps)
        count = np.bincount(where, minlength=nf * steps).reshape(nf, steps)
        size = np.bincount(where, weights=np.abs(seg), minlength=nf * steps).reshape(nf, steps)
        terms = per + closed[:, c + 1: c2 + 1]
        partial = np.cumsum(terms, axis=1)
        run = base[:, None] + partial
        error = (_U * np.sum(np.maximum(count - 1, 0) * size + np.abs(terms), axis=1)
                 + recursive_sum_error(partial)[:, -1] + _U * np.abs(run[:, -1]))
        return run, error

    def _run(self, kernel: Callable[..., np.ndarray], lval: np.ndarray, lo: int, hi: int, mark: np.ndarray,
             work: np.ndarray) -> np.ndarray:
        """The kernel over vectors ``lo:hi`` in batches of ``BATCH`` consecutive ones (a batch may span
        steps: each vector's increment is its sequential one whatever the batching), ``CALL`` vectors
        per call so that Python sees a signal (Ctrl-C, SIGTERM) within a fraction of a second."""
        out = np.zeros(hi - lo)
        for a in range(lo, hi, CALL):
            b = min(a + CALL, hi)
            bptr = np.append(np.arange(0, b - a, BATCH), b - a).astype(np.int64)
            out[a - lo: b - lo] = kernel(self.lindptr, self.lindices, lval, self.parent, self.k_rows[a:b],
                                         self.v_vals[a:b], self.v_fam[a:b], bptr, mark, work)
        return out
