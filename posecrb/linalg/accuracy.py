"""How many digits of a computed log-determinant or inverse can be trusted (docs/design.md#statuses).

``logdet_accuracy``: a first-order bound on the rounding error of a Cholesky log-determinant,
from the componentwise backward error of the assembly and of the factorization and the entries of
the inverse on the factor's pattern, in three tiers (docs/decisions/logdet-accuracy-tiers.md): an
upper bound of those entries from an upper bound of the inverse's diagonal that the caller knows
(the covariance of a spanning tree's FIM: ``"spanning_tree"``), one from a certified lower bound of
the smallest eigenvalue of the diagonally scaled matrix (Lanczos and one inertia check:
``"lambda_min"``), and their exact values (selected inversion: ``"selected_inversion"``) where
neither proves the printed digits.
``onenorm_inverse``: Hager's and Higham's estimate of ``||A^{-1}||_1`` (LAPACK's xLACON), used
for condition estimates.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.errors import UsageError
from ..core.status import OK, Status

# A log-det whose error bound exceeds this fraction of max(1, |log det|) carries a warning: the
# 6 significant digits the tables print, and the relative tolerance of `posecrb regress`.
LOGDET_WARN = 1e-6

# The tiers of ``logdet_accuracy`` ("auto": the first that proves the printed digits).
TIERS = ("auto", "spanning_tree", "lambda_min", "selected_inversion")

EPS = float(np.finfo(float).eps)

# "auto" goes straight to the selected inversion when it takes at most this many steps of its
# Python loop (``posecrb.linalg.selinv.inversion_steps``): then it costs no more than the Lanczos
# iterations and the second factorization of the lambda_min tier, and gives the exact sum.
EXACT_FIRST_STEPS = 500

# "auto" tries the spanning_tree tier before the lambda_min tier when the log-det's factorization
# takes at least this many flops: the lambda_min tier's cost is about one more factorization, the
# spanning tree's a pass over L and over the edges plus one round of a dozen numpy calls per edge
# of its longest shortest path (thousands on a long trajectory: ais2klinik's 2,686), which at this
# size costs less than the factorization. Below it the lambda_min tier runs first (a few solves
# and a small factorization), and the spanning tree only where it cannot prove the digits.
TREE_FIRST_FLOPS = 1e8

# The lambda_min tier's Lanczos run: relative residual and restarts. A run to 0.1 takes 2-4 solves
# on the SE-Sync files, and its mu (below theta + 2 r, within 20% of the Ritz value) gives bounds
# 1-8% above a run to 1e-2 (one to three solves more), far inside the margin to the printed digits
# wherever the tier proves them at all. Its Ritz value also decides whether the tier can prove them
# (a Ritz value is a lower bound of the largest eigenvalue, so a bound from it that fails the
# threshold fails it with any later value too): where it cannot (the 3D grid of 21,952 poses), the
# selected inversion follows after a few solves only. The largest eigenvalues of the scaled inverse
# are the anchored graph's global modes, often a cluster within a percent of each other (the SE(d)
# FIM of a 3D grid: 31,950 and 31,769), and a run may stop on the second of them: ``_MU_MARGIN``
# covers such clusters, and the retry below what it does not.
_LANCZOS_TOL = 0.1
_LANCZOS_RESTARTS = 4
# mu is taken this much below the Lanczos estimate; after a failed inertia check (a top eigenvalue
# the Krylov space had not yet seen) once more, this many times lower, but under ``tier="auto"``
# no lower than where the bound just proves the printed digits: a looser bound, which may still
# prove them, for one more factorization in that rare case only.
_MU_MARGIN = 1.05
_MU_RETRY = 8.0


def onenorm_inverse(solve: Callable[[np.ndarray], np.ndarray], n: int) -> float:
    """Hager's / Higham's (LAPACK xLACON) estimate of ``||B||_1`` for a symmetric B given by
    ``solve`` (x -> B x); deterministic, a handful of products."""
    if n == 0:
        return 0.0
    x = np.full(n, 1.0 / n)
    est = 0.0
    last = -1
    for _ in range(5):
        y = solve(x)
        new = float(np.abs(y).sum())
        if new <= est:
            break
        est = new
        z = solve(np.where(y >= 0, 1.0, -1.0))
        j = int(np.argmax(np.abs(z)))
        if j == last or np.abs(z[j]) <= z @ x:
            break
        x = np.zeros(n)
        x[j] = 1.0
        last = j
    # Higham's extra test vector guards against the estimate being fooled by cancellation.
    alt = (-1.0) ** np.arange(n) * (1.0 + np.arange(n) / max(n - 1, 1))
    est2 = 2.0 * float(np.abs(solve(alt)).sum()) / (3.0 * n)
    return max(est, est2)


@dataclass(frozen=True)
class LogdetAccuracy:
    """How far a Cholesky log-determinant ``log det A = 2 sum log diag L`` can be trusted.

    The computed factor is the exact factor of ``A + dA`` with ``|dA| <= gamma |L| |L^T|``
    entrywise, ``gamma = (c + 2) eps`` for factor columns of at most ``c`` entries (Higham, Accuracy
    and Stability of Numerical Algorithms, Th. 10.3; the assembly of A adds rounding of the same
    form). To first order ``log det(A + dA) - log det A = tr(A^{-1} dA)``, so

        |error| <= gamma * sum_ij |(A^{-1})_ij| (|L| |L^T|)_ij = ``error_bound``,

    a sum over the factor's pattern only. ``condition = error_bound / gamma`` is the log-det's
    componentwise condition number; it is invariant under diagonal scaling (equilibration changes
    neither) and large where information of very different magnitudes is summed on the same pose
    (the digits lost there are lost when A is assembled, before any factorization).

    ``tier`` names how the sum was bounded: ``"selected_inversion"`` takes the entries of
    ``A^{-1}`` on the pattern exactly (``condition_kind`` ``"exact"``); ``"spanning_tree"`` bounds
    them by ``|(A^{-1})_ij| <= sqrt(z_i z_j)``, ``z`` an upper bound of ``diag(A^{-1})`` (the
    inverse of a spanning tree's FIM, which is below A in the Loewner order); ``"lambda_min"`` bounds
    them by ``|(A^{-1})_ij| <= 1 / (lambda sqrt(A_ii A_jj))``, ``lambda`` a certified lower bound of
    the smallest eigenvalue of ``D^{-1/2} A D^{-1/2}`` (``D = diag A``); in both, ``condition`` is an
    upper bound of the exact sum (``condition_kind`` ``"upper bound"``) and ``error_bound`` stays an
    upper bound of the error. ``status``: a warning above ``LOGDET_WARN * max(1, |log det|)``,
    unavailable when the bound reaches ``max(1, |log det|)`` (no correct digit).
    """

    condition: float
    error_bound: float
    status: Status = OK
    tier: str = "selected_inversion"
    condition_kind: str = "exact"

    def as_json(self) -> dict:
        return {"condition": self.condition, "error_bound": self.error_bound, "tier": self.tier,
                "condition_kind": self.condition_kind, **self.status.as_json()}


def logdet_accuracy(factor: Any, logdet: float, name: str = "matrix", *, matrix: Any = None,
                    tier: str = "auto", overwrite_factor: bool = False,
                    inverse_diagonal: np.ndarray | Callable[[], np.ndarray | None] | None = None,
                    ) -> LogdetAccuracy:
    """``LogdetAccuracy`` of ``logdet`` computed from ``factor`` (a Cholesky factor of ``matrix``;
    None for an empty matrix).

    ``inverse_diagonal``: an upper bound of ``diag(A^{-1})`` in the caller's ordering, such as the
    diagonal of ``B^{-1}`` for a matrix ``B <= A`` in the Loewner order
    (``posecrb.models.paper.tree_inverse``: a spanning tree's FIM), or a function that computes it
    (None where it has none), called only when the tier runs; it gives the ``"spanning_tree"``
    tier, ``|| |L|^T sqrt(z) ||^2`` (z permuted to the factor's order): one pass over L, no solve
    and no factorization.

    ``tier="auto"``: the ``"selected_inversion"`` tier when the inversion takes at most
    ``EXACT_FIRST_STEPS`` steps (then it costs no more than the others and gives the exact sum).
    Otherwise the ``"spanning_tree"`` tier first when the factorization takes at least
    ``TREE_FIRST_FLOPS`` (below that the ``"lambda_min"`` tier can cost less than the tree's
    shortest paths), kept when it proves ``LOGDET_WARN``. Then, with ``matrix`` (the sparse matrix
    ``factor`` factors, in the caller's ordering), the ``"lambda_min"`` tier: a Lanczos run on the
    scaled inverse (a few dozen solves with ``factor``), one pass over the factor and one more
    factorization with its symbolic analysis (``posecrb.linalg.cholesky.refactor``: the inertia
    check that certifies the eigenvalue); it is kept when it proves ``LOGDET_WARN``, and skipped
    before the factorization when even the eigenvalue's estimate could not. Then the
    ``"spanning_tree"`` tier if it has not run. Otherwise the ``"selected_inversion"`` tier: one
    selected inversion that also sums ``|Z| (|L| |L^T|)`` supernode by supernode, about twice the
    flops of the factorization. A status other than ok therefore always comes from the exact sum,
    with the same bound and message as that tier alone. ``tier="spanning_tree"``,
    ``"lambda_min"`` or ``"selected_inversion"`` takes that tier only (a bound that cannot be
    certified is infinite, and unavailable with that reason). ``overwrite_factor``: the caller has
    no further use for ``factor``'s values, so the inertia check refactors it in place (its
    ordering stays) instead of a copy.

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> from posecrb.linalg.cholesky import cholesky
    >>> a = sp.csc_matrix(sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], shape=(50, 50)))
    >>> f = cholesky(a)
    >>> exact = logdet_accuracy(f, f.logdet(), matrix=a, tier="selected_inversion")
    >>> cheap = logdet_accuracy(f, f.logdet(), matrix=a, tier="lambda_min")
    >>> (exact.condition_kind, cheap.condition_kind, exact.error_bound <= cheap.error_bound)
    ('exact', 'upper bound', True)
    """
    if tier not in TIERS:
        raise UsageError(f"tier must be one of {', '.join(TIERS)}, got {tier!r}")
    if factor is None or factor.P().size == 0:
        return LogdetAccuracy(0.0, 0.0)
    if tier == "spanning_tree" and inverse_diagonal is None:
        raise UsageError("the spanning_tree tier needs an upper bound of the inverse's diagonal (inverse_diagonal=...)")
    if tier == "lambda_min" and matrix is None:
        raise UsageError("the lambda_min tier needs the factored matrix (matrix=...)")
    lower = _lower(factor)
    if tier == "auto" and (matrix is not None or inverse_diagonal is not None):
        from .selinv import inversion_steps, supernode_bounds  # noqa: PLC0415 -- import cycle: selinv builds on cholesky

        indptr = lower.indptr.astype(np.int64)
        if inversion_steps(indptr, supernode_bounds(indptr, lower.indices)) <= EXACT_FIRST_STEPS:
            tier = "selected_inversion"
    tree_tier = inverse_diagonal is not None and tier in ("auto", "spanning_tree")
    if tree_tier and (tier == "spanning_tree" or factorization_flops(lower) >= TREE_FIRST_FLOPS):
        tree_tier = False
        z, why = _diagonal_bound(inverse_diagonal, lower.shape[0])
        if z is None:
            if tier == "spanning_tree":
                return _not_certified(name, why, tier="spanning_tree")
        else:
            # |L| in L's own array (a fresh one costs its page faults, a third of the tier on the
            # 3D files); the next tiers take L again
            tree = _spanning_tree_tier(factor, lower, z, logdet, name, tier == "auto", in_place=True)
            if tree is not None:
                return tree
            lower = _lower(factor)
    if tier in ("auto", "lambda_min") and matrix is not None:
        from .threads import controller  # noqa: PLC0415 -- loaded with the factor's module

        # every BLAS at one thread: solves and vector products too small for threads to pay, which
        # only spin and stall under load (posecrb.linalg.threads)
        with controller().limit(limits=1, user_api="blas"):
            cheap = _lambda_min_tier(factor, lower, matrix, logdet, name, tier == "auto", overwrite_factor)
        if cheap is not None:
            return cheap
    if tree_tier:
        z, _ = _diagonal_bound(inverse_diagonal, lower.shape[0])
        tree = None if z is None else _spanning_tree_tier(factor, lower, z, logdet, name, True)
        if tree is not None:
            return tree
    return _selected_inversion_tier(factor, lower, logdet, name)


def factorization_flops(lower: Any) -> float:
    """The flops of the numeric factorization that produced ``lower`` (CSC): ``sum_j c_j^2`` over
    its columns' counts (to leading order)."""
    counts = np.diff(lower.indptr).astype(float)
    return float(counts @ counts)


def _lower(factor: Any) -> Any:
    """The factor's L as CSC with sorted rows (CHOLMOD's copy of its supernodal factor)."""
    import scipy.sparse as sp  # noqa: PLC0415 -- the factor's module has loaded it already

    lower = factor.L()
    if not sp.isspmatrix_csc(lower):  # pragma: no cover - CHOLMOD returns CSC
        lower = sp.csc_matrix(lower)
    lower.sort_indices()
    return lower


def _gamma(lower: Any) -> float:
    """``(c + 2) eps`` for factor columns of at most ``c`` entries (``LogdetAccuracy``)."""
    return (int(np.diff(lower.indptr).max()) + 2) * EPS


def _status(bound: float, logdet: float, name: str) -> Status:
    """The status of a log-det whose rounding error is at most ``bound`` (``LogdetAccuracy``)."""
    scale = max(1.0, abs(logdet))
    if not np.isfinite(bound) or bound >= scale:
        return Status.unavailable(
            f"the {name} is numerically singular: its log-det {logdet:.6g} may be off by {bound:.2g} or more "
            "(no correct digit): information of very different magnitudes is summed on the same poses",
            "the information spans more orders of magnitude than double precision resolves; check the "
            "information matrices")
    if bound > LOGDET_WARN * scale:
        return Status.warning(
            f"the {name} is ill-conditioned: its log-det may be off by up to about {bound:.1g} (rounding of "
            "information of very different magnitudes summed on the same poses)",
            "treat the digits beyond that as uncertain")
    return OK


def _selected_inversion_tier(factor: Any, lower: Any, logdet: float, name: str) -> LogdetAccuracy:
    """The exact sum ``sum_ij |Z_ij| (|L| |L^T|)_ij`` from one selected inversion
    (``posecrb.linalg.selinv.SelectedInverse`` with ``absolute_terms``): the bound reads the factor
    only, never the matrix itself."""
    from ..core.errors import NumericalError  # noqa: PLC0415
    from .selinv import SelectedInverse  # noqa: PLC0415 -- import cycle: selinv builds on cholesky

    try:
        sel = SelectedInverse(factor, name, absolute_terms=True, lower=lower)
    except NumericalError as exc:
        return LogdetAccuracy(float("inf"), float("inf"), Status.unavailable(
            f"the {name} is numerically singular: {exc}", "check the information matrices"))
    total = sel.absolute_terms
    assert total is not None   # requested with absolute_terms=True
    bound = _gamma(lower) * total
    return LogdetAccuracy(float(total), float(bound), _status(bound, logdet, name))


def _diagonal_bound(inverse_diagonal: Any, n: int) -> tuple[np.ndarray | None, str]:
    """``logdet_accuracy``'s ``inverse_diagonal`` as an array (its function called), or None and
    why it cannot bound the diagonal of a positive definite inverse."""
    if callable(inverse_diagonal):
        inverse_diagonal = inverse_diagonal()
    if inverse_diagonal is None:
        return None, "the caller has no bound of the inverse's diagonal"
    z = np.asarray(inverse_diagonal, dtype=float)
    if z.shape != (n,):
        raise UsageError(f"inverse_diagonal has {z.size} entries for a matrix of {n} rows")
    if not np.all(z > 0):     # a diagonal of a positive definite inverse is positive: not a bound
        return None, "a bound of the inverse's diagonal is not positive"
    if not np.all(np.isfinite(z)):
        return None, "an edge of the tree carries no information"
    return z, ""


def _spanning_tree_tier(factor: Any, lower: Any, z: np.ndarray, logdet: float, name: str,
                        only_if_ok: bool, in_place: bool = False) -> LogdetAccuracy | None:
    """The bound from ``z >= diag(A^{-1})`` (``_diagonal_bound``'s): with ``Z = A^{-1}`` positive
    definite, ``|Z_ij| <= sqrt(Z_ii Z_jj) <= sqrt(z_i z_j)``, so the exact sum is at most
    ``sum_ij sqrt(z_i z_j) (|L| |L^T|)_ij = || |L|^T sqrt(z) ||^2`` (z in the caller's order,
    permuted to the factor's; the pattern of ``|L| |L^T|`` lies in the factor's). ``only_if_ok``:
    None instead of a bound that does not prove ``LOGDET_WARN``. ``in_place``: ``lower``'s values
    become their magnitudes."""
    import scipy.sparse as sp  # noqa: PLC0415 -- the factor's module has loaded it already

    perm = np.asarray(factor.P(), dtype=np.int64)
    magnitudes = np.abs(lower.data, out=lower.data if in_place else None)
    col = sp.csr_matrix((magnitudes, lower.indices, lower.indptr), shape=lower.shape[::-1]) @ np.sqrt(z[perm])
    with np.errstate(over="ignore"):
        condition = float(col @ col)
    bound = _gamma(lower) * condition
    if not np.isfinite(bound):
        return None if only_if_ok else _not_certified(name, "its bound overflows", tier="spanning_tree")
    if only_if_ok and not bound <= LOGDET_WARN * max(1.0, abs(logdet)):
        return None
    return LogdetAccuracy(condition, bound, _status(bound, logdet, name), tier="spanning_tree",
                          condition_kind="upper bound")


def _lambda_min_tier(factor: Any, lower: Any, matrix: Any, logdet: float, name: str,
                     only_if_ok: bool, in_place: bool = False) -> LogdetAccuracy | None:
    """The bound from a certified lower bound ``lam`` of ``lambda_min(D^{-1/2} A D^{-1/2})``.

    With ``Z = A^{-1}`` (both in the factor's ordering), ``|Z_ij| <= sqrt(Z_ii Z_jj)`` (Z is positive
    definite) and ``A_ii Z_ii <= 1 / lam``, so the exact sum is at most
    ``sum_ij s_i s_j (|L| |L^T|)_ij / lam = || |L|^T s ||^2 / lam`` with ``s = diag(A)^{-1/2}`` (the
    pattern of ``|L| |L^T|`` lies in the factor's, a closed pattern): one pass over L.

    ``lam``: the largest eigenvalue ``theta`` of ``D^{1/2} A^{-1} D^{1/2}`` by Lanczos (solves with
    the factor) gives ``mu = 1 / ((theta + 2 r) _MU_MARGIN)``, r the Ritz pair's residual (once
    lower when the check below fails, ``_MU_RETRY``); the factorization of ``A - mu D`` with the
    factor's symbolic analysis then succeeds only if no eigenvalue of the scaled matrix lies below
    mu, up to that factorization's own backward error (``|E| <= gamma |L'| |L'^T|``, whose scaled
    2-norm is at most ``gamma (1 + gamma)`` times the longest row of the pattern, plus the rounding
    of ``A_ii - mu A_ii``), so ``lam = mu - delta``.

    ``only_if_ok``: return None instead of a bound that does not prove ``LOGDET_WARN`` (and skip the
    factorization when the Lanczos estimate alone shows it would not). None too when the inertia
    check fails with ``only_if_ok``; without it that is an infinite bound, unavailable.
    ``in_place``: the inertia check overwrites the factor's values (``lower`` and the ordering stay,
    which is all the selected inversion reads)."""
    import scipy.sparse as sp  # noqa: PLC0415 -- the factor's module has loaded it already

    from ..core.errors import NotPositiveDefinite  # noqa: PLC0415
    from .cholesky import refactor  # noqa: PLC0415 -- the factor's module has loaded it already
    from .lanczos import largest_eigenpair  # noqa: PLC0415

    perm = np.asarray(factor.P(), dtype=np.int64)
    d = np.asarray(matrix.diagonal(), dtype=float)
    if not (np.all(np.isfinite(d)) and np.all(d > 0)):
        return None if only_if_ok else _not_certified(name, "a diagonal entry is not positive and finite")
    gamma = _gamma(lower)
    # || |L|^T s ||^2: column k's sum of |L_ik| s_i, one sparse product (|L|^T is |L|'s CSC read as CSR)
    s = 1.0 / np.sqrt(d[perm])
    col = sp.csr_matrix((np.abs(lower.data), lower.indices, lower.indptr), shape=lower.shape[::-1]) @ s
    scaled_sum = float(col @ col)
    limit = LOGDET_WARN * max(1.0, abs(logdet))
    root = np.sqrt(d)

    def scaled_inverse(v: np.ndarray) -> np.ndarray:
        return root * factor.solve_A(root * v)

    ritz = largest_eigenpair(scaled_inverse, np.ones(d.size), tol=_LANCZOS_TOL, max_restarts=_LANCZOS_RESTARTS)
    if only_if_ok and not gamma * scaled_sum * ritz.value <= limit:
        return None      # even lambda_min = 1 / theta would not prove the printed digits
    rows = np.bincount(lower.indices, minlength=d.size) + np.diff(lower.indptr) - 1   # pattern of L + L^T
    delta = gamma * (1.0 + gamma) * float(rows.max()) + 2.0 * EPS
    mu = 1.0 / ((ritz.value + 2.0 * ritz.residual) * _MU_MARGIN)
    # the smallest mu whose bound still proves the digits (only_if_ok's retry goes no lower than
    # needed: from mu / _MU_RETRY up to it)
    proving = gamma * scaled_sum / limit + delta if only_if_ok else 0.0
    shift = _diagonal_shift(matrix)
    for attempt in range(2):
        lam = mu - delta
        if not (np.isfinite(lam) and lam > 0 and gamma * scaled_sum / lam <= (limit if only_if_ok else np.inf)):
            # (also the retry's looser bound when it could no longer prove the digits)
            return None if only_if_ok else _not_certified(name, f"its estimate {mu:.3g} is below the rounding level")
        try:
            # (a pattern within the analysed one: CHOLMOD takes any subset, so a pruned zero is harmless)
            refactor(factor, shift(mu * d), name, in_place=in_place)
            break
        except NotPositiveDefinite:
            if attempt:
                return None if only_if_ok else _not_certified(name, f"the inertia check at {mu:.3g} failed")
            mu = max(mu / _MU_RETRY, min(mu, proving * (1.0 + 1e-9)))
    condition = scaled_sum / lam
    bound = gamma * condition
    if only_if_ok and not bound <= limit:
        return None
    return LogdetAccuracy(condition, bound, _status(bound, logdet, name), tier="lambda_min",
                          condition_kind="upper bound")


def _diagonal_shift(matrix: Any) -> Callable[[np.ndarray], Any]:
    """``shift(v)``: ``matrix - diag(v)`` as CSC; for a matrix in canonical CSC form the result keeps
    its index arrays (the factor's analysis then permutes it by one gather of the data,
    ``posecrb.linalg.cholesky.PermutedFactor.permuted``), else through scipy's subtraction."""
    import scipy.sparse as sp  # noqa: PLC0415 -- the factor's module has loaded it already

    def subtract(v: np.ndarray) -> Any:
        return sp.csc_matrix(matrix - sp.diags(v, format="csc"))

    if not (sp.isspmatrix_csc(matrix) and matrix.has_canonical_format and matrix.dtype == np.float64):
        return subtract
    n = matrix.shape[0]
    cols = np.repeat(np.arange(n), np.diff(matrix.indptr))
    diagonal = np.flatnonzero(matrix.indices == cols)   # canonical: at most one entry per column
    if diagonal.size != n:                              # a diagonal entry not stored
        return subtract

    def shift(v: np.ndarray) -> Any:
        data = matrix.data.copy()
        data[diagonal] -= v
        return sp.csc_matrix((data, matrix.indices, matrix.indptr), shape=matrix.shape)

    return shift


def _not_certified(name: str, why: str, tier: str = "lambda_min") -> LogdetAccuracy:
    what = "smallest scaled eigenvalue" if tier == "lambda_min" else "inverse's diagonal"
    return LogdetAccuracy(float("inf"), float("inf"), Status.unavailable(
        f"the {name}'s {what} could not be certified ({why}): its log-det's accuracy "
        f"is not bounded by the {tier} tier", "use the selected_inversion tier"),
        tier=tier, condition_kind="upper bound")


__all__ = [
    "LOGDET_WARN", "TIERS", "TREE_FIRST_FLOPS", "LogdetAccuracy", "factorization_flops", "logdet_accuracy",
    "onenorm_inverse",
]
