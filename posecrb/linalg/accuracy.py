"""How many digits of a computed log-determinant or inverse can be trusted (docs/design.md#statuses).

``logdet_accuracy``: a first-order bound on the rounding error of a Cholesky log-determinant,
from the componentwise backward error of the assembly and of the factorization and the exact
entries of the inverse on the factor's pattern (selected inversion). ``onenorm_inverse``: Hager's
and Higham's estimate of ``||A^{-1}||_1`` (LAPACK's xLACON), used for condition estimates.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.status import OK, Status

# A log-det whose error bound exceeds this fraction of max(1, |log det|) carries a warning: the
# 6 significant digits the tables print, and the relative tolerance of `posecrb regress`.
LOGDET_WARN = 1e-6


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

    a sum over the factor's pattern only, where selected inversion gives ``A^{-1}`` exactly.
    ``condition = error_bound / gamma`` is the log-det's componentwise condition number; it is
    invariant under diagonal scaling (equilibration changes neither) and large where information
    of very different magnitudes is summed on the same pose (the digits lost there are lost when
    A is assembled, before any factorization). ``status``: a warning above ``LOGDET_WARN * max(1,
    |log det|)``, unavailable when the bound reaches ``max(1, |log det|)`` (no correct digit).
    """

    condition: float
    error_bound: float
    status: Status = OK

    def as_json(self) -> dict:
        return {"condition": self.condition, "error_bound": self.error_bound, **self.status.as_json()}


def logdet_accuracy(factor: Any, logdet: float, name: str = "matrix") -> LogdetAccuracy:
    """``LogdetAccuracy`` of ``logdet`` computed from ``factor`` (a Cholesky factor; None for an empty
    matrix): the bound reads the factor only, never the matrix itself. One
    selected inversion that also sums ``|Z| (|L| |L^T|)`` supernode by supernode (dense products
    of the blocks it forms anyway, never the product ``|L| |L^T|`` itself), about twice the flops
    of the factorization, no other factorization."""
    from ..core.errors import NumericalError  # noqa: PLC0415
    from .selinv import SelectedInverse  # noqa: PLC0415 -- import cycle: selinv builds on cholesky

    if factor is None or factor.P().size == 0:
        return LogdetAccuracy(0.0, 0.0)
    eps = float(np.finfo(float).eps)
    try:
        sel = SelectedInverse(factor, name, absolute_terms=True)
    except NumericalError as exc:
        return LogdetAccuracy(float("inf"), float("inf"), Status.unavailable(
            f"the {name} is numerically singular: {exc}", "check the information matrices"))
    total = sel.absolute_terms
    assert total is not None   # requested with absolute_terms=True
    cmax = int(np.diff(sel.indptr).max())
    bound = (cmax + 2) * eps * total
    scale = max(1.0, abs(logdet))
    if not np.isfinite(bound) or bound >= scale:
        status = Status.unavailable(
            f"the {name} is numerically singular: its log-det {logdet:.6g} may be off by {bound:.2g} or more "
            "(no correct digit): information of very different magnitudes is summed on the same poses",
            "the information spans more orders of magnitude than double precision resolves; check the "
            "information matrices")
    elif bound > LOGDET_WARN * scale:
        status = Status.warning(
            f"the {name} is ill-conditioned: its log-det may be off by up to about {bound:.1g} (rounding of "
            "information of very different magnitudes summed on the same poses)",
            "treat the digits beyond that as uncertain")
    else:
        status = OK
    return LogdetAccuracy(float(total), float(bound), status)


__all__ = ["LOGDET_WARN", "LogdetAccuracy", "logdet_accuracy", "onenorm_inverse"]
