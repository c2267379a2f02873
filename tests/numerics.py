"""Tolerances derived from the conditioning of the quantity under test.

Every comparison of two floating-point evaluations (the code under test and an independent
dense reference) allows the sum of both evaluations' rounding errors, bounded by standard
backward-error results, times a stated safety ``MARGIN`` for the constants those results
leave open. Never a number read off one machine's output.
"""
from __future__ import annotations

import numpy as np

EPS = float(np.finfo(float).eps)
# Safety factor on the textbook constants (they hold up to a modest factor, and both the
# tested code and the reference contribute an error of that size).
MARGIN = 10.0


def spd_condition(a: np.ndarray) -> float:
    """2-norm condition number of a symmetric positive definite matrix."""
    ev = np.linalg.eigvalsh((a + a.T) / 2)
    assert ev[0] > 0, "not positive definite"
    return float(ev[-1] / ev[0])


def inverse_entry_atol(a: np.ndarray, margin: float = MARGIN) -> float:
    """Absolute tolerance on any entry of ``inv(a)`` computed two ways (Cholesky/LU based):
    each computed inverse satisfies ``||X - A^{-1}||_2 <= c n kappa(A) eps ||A^{-1}||_2``
    (Higham, Accuracy and Stability, ch. 14), and an entry is at most the 2-norm."""
    n = a.shape[0]
    ev = np.linalg.eigvalsh((a + a.T) / 2)
    return margin * n * (ev[-1] / ev[0]) * EPS / ev[0]


def trace_inverse_rtol(a: np.ndarray, margin: float = MARGIN) -> float:
    """Relative tolerance on ``trace(inv(a))``: n entries, each within ``inverse_entry_atol``,
    and ``trace(A^{-1}) >= ||A^{-1}||_2``."""
    n = a.shape[0]
    ev = np.linalg.eigvalsh((a + a.T) / 2)
    return margin * n * n * (ev[-1] / ev[0]) * EPS * (1.0 / ev[0]) / np.sum(1.0 / ev)


def logdet_atol(a: np.ndarray, margin: float = MARGIN) -> float:
    """Absolute tolerance on ``log det(a)`` of an SPD matrix: a backward error ``||E|| <= c n eps ||A||``
    moves it by at most ``trace(A^{-1} E) <= n ||A^{-1}|| ||E|| = c n^2 kappa(A) eps``."""
    n = a.shape[0]
    return margin * n * n * spd_condition(a) * EPS


def sum_atol(terms: np.ndarray, margin: float = MARGIN) -> float:
    """Absolute tolerance on a floating-point sum of ``terms`` in any order: ``(k - 1) eps sum |t|``."""
    t = np.abs(np.asarray(terms, dtype=float))
    return margin * max(t.size, 1) * EPS * float(t.sum())


def psd_sum_tolerance(mat: np.ndarray, terms_per_entry: int, margin: float = MARGIN) -> np.ndarray:
    """Entrywise tolerance for a matrix assembled as a sum of positive semidefinite terms (a
    Fisher information ``sum_e J_e^T W_e J_e``, a Laplacian) in any order: by Cauchy-Schwarz the
    terms of entry (a, b) have ``sum |T_ab| <= sqrt(F_aa F_bb)``, so two summation orders differ
    by at most ``2 (k - 1) eps sqrt(F_aa F_bb)`` with k terms per entry."""
    d = np.sqrt(np.abs(np.diag(mat)))
    return margin * 2 * max(terms_per_entry, 1) * EPS * np.outer(d, d)


def assert_within(got: np.ndarray, ref: np.ndarray, tol: np.ndarray | float, what: str = "") -> None:
    """``|got - ref| <= tol`` entrywise, with the worst offender in the message."""
    err = np.abs(np.asarray(got, float) - np.asarray(ref, float))
    tol = np.broadcast_to(np.asarray(tol, float), err.shape)
    bad = err > tol
    if bad.any():
        k = np.unravel_index(np.argmax(np.where(bad, err / np.where(tol > 0, tol, 1e-300), 0)), err.shape)
        raise AssertionError(f"{what}: {bad.sum()} entries outside the tolerance; worst at {k}: "
                             f"|{np.asarray(got)[k]!r} - {np.asarray(ref)[k]!r}| = {err[k]:.3g} > {tol[k]:.3g}")


def suboptimality_bound(res, n: int, d: int) -> float:
    """Certified bound on ``objective - F*`` of a solve (SE-Sync's dual certificate): with
    ``Lambda = SymBlockDiag(Q Y^T Y)``, ``trace(Lambda) = f(Y)`` (the relaxation value) and for any
    feasible Z of the SDP ``tr(Q Z) = tr((Q - Lambda) Z) + tr(Lambda) >= n d lambda_min(Q - Lambda)
    + f(Y)``, so ``F* >= f(Y) + n d min(lambda_min, 0)``."""
    return max(res.duality_gap, 0.0) + n * d * max(-res.lambda_min, 0.0)


def objective_atol(kappa: np.ndarray, d: int, objective: float, margin: float = MARGIN) -> float:
    """Rounding of an SE-Sync objective evaluated as ``sum kappa (|R_i|^2 + |R_j|^2 - 2 tr(R_j^T R_i R~))
    + tau |r|^2``: each rotation term cancels entries of size ~2d, so the sum carries
    ``eps (4 d sum kappa + objective)`` (this is the reference form SE-Sync itself uses)."""
    return margin * EPS * (4 * d * float(np.sum(kappa)) + abs(objective))


def pinv_entry_atol(a: np.ndarray, nullity: int, margin: float = MARGIN) -> float:
    """``inverse_entry_atol`` for the pseudo-inverse of a PSD matrix with a known ``nullity``: the
    condition number of its range, ``lambda_max / lambda_min+``."""
    ev = np.linalg.eigvalsh((a + a.T) / 2)
    pos = ev[nullity]
    assert pos > 0
    return margin * a.shape[0] * (ev[-1] / pos) * EPS / pos


def pinv_trace_rtol(a: np.ndarray, nullity: int, margin: float = MARGIN) -> float:
    """Relative tolerance on ``trace(pinv(a))`` (``trace_inverse_rtol`` on the range)."""
    ev = np.linalg.eigvalsh((a + a.T) / 2)[nullity:]
    return margin * a.shape[0] * len(ev) * (ev[-1] / ev[0]) * EPS * (1.0 / ev[0]) / np.sum(1.0 / ev)
