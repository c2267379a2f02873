"""Series-or-closed-form coefficients shared by SO(3) and SE(d) (private): below theta = _SERIES the
closed forms lose digits to cancellation, so a truncated Taylor series is used there.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

# ---------------------------------------------------------------- scalar coefficients
# Coefficients of the closed forms as functions of the angle th. Those with an inherent
# cancellation (c, c2, c3, e) switch to their Taylor series in th^2 below _SERIES (1.5 for
# c2, c3), where the truncated series is exact to ~1e-17 and the closed form loses digits.
_SERIES = 0.5


_FACT = [math.factorial(k) for k in range(40)]


# th^{2k} coefficients:
_C_SERIES = [(-1) ** k / _FACT[2 * k + 3] for k in range(9)]              # (th - sin)/th^3


_C2_SERIES = [(-1) ** k / _FACT[2 * k] for k in range(2, 15)]            # (th^2 + 2cos - 2)/(2 th^4)


_C3_SERIES = [(-1) ** k * (k - 1) / _FACT[2 * k + 1] for k in range(2, 15)]  # (2th - 3sin + th cos)/(2 th^5)


# (1 - (th/2) cot(th/2))/th^2 = -sum_{n>=1} (-1)^n B_{2n} th^{2n-2} / (2n)!, Bernoulli numbers B_{2n}:
_BERNOULLI = [1 / 6, -1 / 30, 1 / 42, -1 / 30, 5 / 66, -691 / 2730, 7 / 6, -3617 / 510, 43867 / 798]


_E_SERIES = [-((-1) ** n) * _BERNOULLI[n - 1] / _FACT[2 * n] for n in range(1, 10)]


def _poly(t2: np.ndarray, coeffs: list[float]) -> np.ndarray:
    out = np.zeros_like(t2) + coeffs[-1]
    for c in reversed(coeffs[:-1]):
        out = out * t2 + c
    return out


def _coef_a(th: np.ndarray) -> np.ndarray:
    """sin(th)/th (no cancellation: numpy's sinc is accurate everywhere, including 0)."""
    return np.sinc(np.asarray(th, float) / np.pi)


def _coef_b(th: np.ndarray) -> np.ndarray:
    """(1 - cos th)/th^2 = (1/2) (sin(th/2)/(th/2))^2, written without cancellation."""
    s = np.sinc(np.asarray(th, float) / (2 * np.pi))
    return 0.5 * s * s


def _series_or(th: np.ndarray, coeffs: list[float], closed: Callable[[np.ndarray], np.ndarray],
               below: float = _SERIES) -> np.ndarray:
    th = np.asarray(th, float)
    small = np.abs(th) < below
    ts = np.where(small, 1.0, th)
    with np.errstate(all="ignore"):
        c = closed(ts)
    return np.where(small, _poly(th * th, coeffs), c)


def _coef_c(th: np.ndarray) -> np.ndarray:
    """(th - sin th)/th^3."""
    return _series_or(th, _C_SERIES, lambda t: (t - np.sin(t)) / t ** 3)


def _coef_c2(th: np.ndarray) -> np.ndarray:
    """(th^2 + 2 cos th - 2)/(2 th^4)."""
    return _series_or(th, _C2_SERIES, lambda t: (t * t + 2 * np.cos(t) - 2) / (2 * t ** 4), 1.5)


def _coef_c3(th: np.ndarray) -> np.ndarray:
    """(2 th - 3 sin th + th cos th)/(2 th^5)."""
    return _series_or(th, _C3_SERIES, lambda t: (2 * t - 3 * np.sin(t) + t * np.cos(t)) / (2 * t ** 5), 1.5)


def _coef_e(th: np.ndarray) -> np.ndarray:
    """(1 - (th/2) cot(th/2))/th^2, the hat(w)^2 coefficient of Jl^{-1} on SO(3); finite up to pi."""
    return _series_or(th, _E_SERIES, lambda t: (1 - (t / 2) / np.tan(t / 2)) / (t * t))
