"""Noise model: information matrices -> isotropic (tau, kappa), rotation weights.

docs/design.md#noise-model. tau is the isotropic Gaussian translation precision
(1/delta^2 of the paper's eq. 3) and kappa the Langevin concentration of eq. 5,
both with SE-Sync's conventions:

* 2D: ``tau = 2 / trace(inv(I_tt))``, ``kappa = I_thth``;
* 3D: ``tau = 3 / trace(inv(I_tt))``, ``kappa = 3 / (2 trace(inv(I_RR)))``.
"""
from __future__ import annotations

from fractions import Fraction
from math import factorial

import numpy as np
import numpy.typing as npt

from .choices import ROTATION_WEIGHTS
from .errors import UsageError

# Table II of the paper is reproduced by w = TABLE2_FIT * kappa^2 (an empirical fit
# measured on the published lower bounds, NOT eq. 59; with eq. 64 as printed it also
# reproduces the printed FIM column); see docs/design.md#rotation-weights.
TABLE2_FIT = 0.5515



def isotropic_precisions(info: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(tau, kappa) per edge from (m, q, q) information matrices, SE-Sync's rule."""
    info = np.asarray(info, dtype=float)
    if dim == 2:
        a, b, c = info[:, 0, 0], info[:, 0, 1], info[:, 1, 1]
        # trace(inv([[a, b], [b, c]])) = (a + c) / (a c - b^2)
        tau = 2.0 * (a * c - b * b) / (a + c)
        kappa = info[:, 2, 2].copy()
        return tau, kappa
    if dim == 3:
        tr_cov_t = np.trace(np.linalg.inv(info[:, :3, :3]), axis1=1, axis2=2)
        tr_cov_r = np.trace(np.linalg.inv(info[:, 3:, 3:]), axis1=1, axis2=2)
        return 3.0 / tr_cov_t, 3.0 / (2.0 * tr_cov_r)
    raise UsageError(f"dimension must be 2 or 3, got {dim}")


def _asymptotic_coefficients(v: int, terms: int) -> list[Fraction]:
    """c_k with I_v(x) e^{-x} sqrt(2 pi x) ~ sum_k c_k x^{-k} (Abramowitz-Stegun 9.7.1)."""
    out, prod = [], Fraction(1)
    for k in range(terms):
        if k > 0:
            prod *= Fraction(4 * v * v - (2 * k - 1) ** 2)
        out.append((-1) ** k * prod / (factorial(k) * 8 ** k))
    return out


_TERMS = 30


_A = [_asymptotic_coefficients(v, _TERMS) for v in range(3)]


# Exact rational coefficients of the two differences; computing them as series
# avoids the catastrophic cancellation of I_1 - I_2 and I_0 - I_1 at large x.
_D12 = np.array([float(a - b) for a, b in zip(_A[1], _A[2])])


_D01 = np.array([float(a - b) for a, b in zip(_A[0], _A[1])])


_ASYMPTOTIC_FROM = 30.0  # x = 2 kappa; truncation error of 30 terms there is < 1e-20


def _power_series_differences(terms: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients in powers of t = x / 2 of I_1 - I_2 and I_0 - I_1, from
    ``I_v(x) = sum_k t^(2k+v) / (k! (k+v)!)`` (Abramowitz-Stegun 9.6.10)."""
    d12, d01 = np.zeros(2 * terms + 3), np.zeros(2 * terms + 3)
    for k in range(terms):
        d12[2 * k + 1] += 1.0 / (factorial(k) * factorial(k + 1))
        d12[2 * k + 2] -= 1.0 / (factorial(k) * factorial(k + 2))
        d01[2 * k] += 1.0 / factorial(k) ** 2
        d01[2 * k + 1] -= 1.0 / (factorial(k) * factorial(k + 1))
    return d12, d01


# Below this kappa, omega comes from the power series of the Bessel functions (no scipy.special:
# start-up time for files with weak rotations). Their terms fall by t^2 <= 2.5e-3 per k, so 8 terms
# leave a truncation error below 1e-20 relative; the leading terms (1 and t) do not cancel.
_SERIES_BELOW = 0.05
_S12, _S01 = _power_series_differences(8)
# The same coefficients from the highest power down, for numpy.polyval's Horner scheme (the
# operations of numpy.polynomial's polyval in the same order, without importing numpy.polynomial
# and its six modules, which the CLI otherwise defers: docs/decisions/fixed-costs.md).
_S12_DESCENDING, _S01_DESCENDING = _S12[::-1].copy(), _S01[::-1].copy()


# Terms of the continued fraction of ``_bessel_ratios``: at x < 30 its tail below the first 40
# terms no longer changes a double, so 64 leave a wide margin.
_FRACTION_TERMS = 64


def _bessel_ratios(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(I_1 / I_0, I_2 / I_1)`` at ``x > 0`` by Gauss' continued fraction ``r_v = 1 / (2 (v + 1) / x
    + r_{v+1})``, evaluated backwards from ``r = 0`` (Abramowitz-Stegun 9.1.73; stable, every term
    positive). numpy only: scipy.special's import is a sizeable part of a 3D command's start-up
    (docs/decisions/fixed-costs.md); the two agree to within their own error (1e-14 relative in
    omega, against mpmath)."""
    r = np.zeros_like(x)
    r1 = r
    for j in range(_FRACTION_TERMS, 0, -1):
        r = 1.0 / (2.0 * j / x + r)
        if j == 2:
            r1 = r
    return r, r1


def omega(kappa: np.ndarray | float) -> np.ndarray:
    """omega(kappa) of eq. (59), evaluated stably.

    Eq. (59) is ``kappa^2 (2I0 - I1 - 2I2 + I3) / (2I0 - 2I1)`` at ``x = 2 kappa``.
    With the recurrences ``I0 - I2 = (2/x) I1`` and ``I1 - I3 = (4/x) I2`` it
    simplifies exactly to ``kappa (I1 - I2) / (I0 - I1)``. kappa below 0.05: the
    power series of both differences. Up to x = 30: the ratios ``r_v = I_{v+1} / I_v``
    by their continued fraction (``_bessel_ratios``), ``omega = kappa r_0 (1 - r_1) /
    (1 - r_0)``. Large x:
    the asymptotic series of both differences, whose leading terms cancel
    analytically, so omega is accurate to ~1 ulp from kappa = 1e-8 to 1e8 and
    ``omega / 3 -> kappa`` as kappa grows.
    """
    k = np.asarray(kappa, dtype=float)
    x = 2.0 * k
    out = np.empty_like(x)
    series = k < _SERIES_BELOW
    bessel = ~series & (x < _ASYMPTOTIC_FROM)
    asymptotic = ~(series | bessel)     # also NaN, which stays NaN
    if series.any():
        ks = k[series]
        out[series] = ks * np.polyval(_S12_DESCENDING, ks) / np.polyval(_S01_DESCENDING, ks)
    if bessel.any():
        r0, r1 = _bessel_ratios(x[bessel])
        out[bessel] = k[bessel] * r0 * (1.0 - r1) / (1.0 - r0)
    if asymptotic.any():
        powers = x[asymptotic][:, None] ** -np.arange(_TERMS)[None, :]
        out[asymptotic] = k[asymptotic] * (powers @ _D12) / (powers @ _D01)
    return out if out.ndim else out[()]


def rotation_weights(kappa: np.ndarray, dim: int, rule: str = "eq59") -> np.ndarray:
    """Edge weight of the rotation Laplacian L_w in the paper's tangent coordinates.

    2D: ``w = 2 kappa`` (eq. 39-41). 3D: ``w = omega(kappa) / 3`` (eq. 58-63,
    coordinates along ``E_k = G_k / sqrt 2``). ``rule="table2"`` uses the
    empirical fit ``w = 0.5515 kappa^2`` that reproduces the paper's printed
    Table II (3D only; 2D is unchanged because Table I follows eq. 41).
    """
    kappa = np.asarray(kappa, dtype=float)
    if rule not in ROTATION_WEIGHTS:
        raise UsageError(f"unknown rotation weight {rule!r}; choose from {ROTATION_WEIGHTS}")
    if dim == 2:
        return 2.0 * kappa
    if rule == "table2":
        return TABLE2_FIT * kappa * kappa
    return omega(kappa) / 3.0


def precisions_from_sigma(sigma: float) -> tuple[float, float]:
    """(tau, kappa) of a noise level ``sigma``: translation precision ``1 / sigma^2`` and the
    Langevin concentration ``1 / (2 sigma^2)``, whose small-angle rotation noise has per-axis
    variance ``1 / (2 kappa) = sigma^2`` (eq. 5; ``posecrb datasets synth --noise``)."""
    return 1.0 / sigma ** 2, 1.0 / (2.0 * sigma ** 2)


def isotropic_information(tau: npt.ArrayLike, kappa: npt.ArrayLike, dim: int) -> np.ndarray:
    """(m, q, q) g2o-order information matrices that SE-Sync's rule maps back to (tau, kappa).

    Inverse of ``isotropic_precisions`` (docs/design.md#noise-model): 2D
    ``diag(tau, tau, kappa)``; 3D ``diag(tau I3, 2 kappa I3)`` (because
    ``kappa = 3 / (2 tr(inv I_RR))``). With these, SE-Sync's objective
    ``sum kappa ||R_j - R_i R~||_F^2 + tau ||t_j - t_i - R_i t~||^2`` is twice the
    negative log-likelihood of eq. (80), so a solve is the MLE of that model.
    """
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    kappa = np.atleast_1d(np.asarray(kappa, dtype=float))
    tau, kappa = np.broadcast_arrays(tau, kappa)
    m = tau.shape[0]
    if dim == 2:
        diag = np.stack([tau, tau, kappa], axis=1)
    elif dim == 3:
        diag = np.concatenate([np.repeat(tau[:, None], 3, 1), np.repeat(2.0 * kappa[:, None], 3, 1)], axis=1)
    else:
        raise UsageError(f"dimension must be 2 or 3, got {dim}")
    q = diag.shape[1]
    info = np.zeros((m, q, q))
    info[:, np.arange(q), np.arange(q)] = diag
    return info
