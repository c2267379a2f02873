"""SE(2) / SE(3) in closed form, batched over leading array dimensions (thesis ch. 2.5, 6.2).

Conventions (DESIGN.md section 5, thesis sec. 6.2):

* Lie algebra coordinates put the rotation first: SE(2) ``xi = (omega, v_x, v_y)``,
  SE(3) ``xi = (omega_1, omega_2, omega_3, v_1, v_2, v_3)``;
  ``hat(xi) = [[hat(omega), v], [0, 0]]``.
* A pose is the pair ``(R, t)`` of the homogeneous matrix ``[[R, t], [0, 1]]``.
* ``Exp(xi) = (Exp(omega), Jl_so(omega) v)`` (thesis 2.5, "Left and right Jacobians").
* ``adjoint(R, t)`` is the matrix of ``Ad_T(X) = T X T^{-1}`` (2.7, 2.11):
  SE(2) ``[[1, 0], [(t_y, -t_x)^T, R]]``, SE(3) ``[[R, 0], [hat(t) R, R]]``.
* Right Jacobian in the standard sense ``Exp(xi + d) = Exp(xi) Exp(Jr(xi) d) + O(|d|^2)``,
  so ``Log(Exp(xi) Exp(eta)) = xi + Jr^{-1}(xi) eta + O(|eta|^2)`` (the expansion used for
  the Jacobians (4.7)); ``Jr(xi) = Jl(-xi)``.

Coefficients with a cancellation switch to Taylor series at small angles, so every function
is accurate to ~1e-15 (relative) at and near the identity; ``so3_log`` is robust up to and
including angle pi.
"""
from __future__ import annotations

import math

import numpy as np

from .so import angle2, exp_so3, hat3, rot2

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


def _series_or(th: np.ndarray, coeffs: list[float], closed, below: float = _SERIES) -> np.ndarray:
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


# ---------------------------------------------------------------- SO(3)
def so3_log(r: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vector of (..., 3, 3) rotations, angle in [0, pi]; robust near 0 and pi."""
    r = np.asarray(r, float)
    axial = 0.5 * np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                            r[..., 1, 0] - r[..., 0, 1]], -1)
    s = np.linalg.norm(axial, axis=-1)
    c = 0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1)
    th = np.arctan2(s, c)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = axial / _coef_a(th)[..., None]
    # Near pi, sin(th) ~ 0 and the axial part loses the axis; recover it from the symmetric
    # part R + R^T - 2c I = 2 (1 - c) a a^T instead.
    near_pi = c < -0.9
    if np.any(near_pi):
        rs, cs, ths, axs = r[near_pi], c[near_pi], th[near_pi], axial[near_pi]
        aat = (rs + np.swapaxes(rs, -1, -2) - 2 * cs[:, None, None] * np.eye(3)) / (2 * (1 - cs))[:, None, None]
        k = np.argmax(np.diagonal(aat, axis1=-2, axis2=-1), -1)
        col = np.take_along_axis(aat, k[:, None, None].repeat(3, 1), -1)[..., 0]
        a = col / np.linalg.norm(col, axis=-1, keepdims=True)
        sign = np.where(np.sum(a * axs, -1) < 0, -1.0, 1.0)
        out[near_pi] = (sign * ths)[:, None] * a
    return out


def so3_jl(w: np.ndarray) -> np.ndarray:
    """Left Jacobian of SO(3): I + b hat(w) + c hat(w)^2."""
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    k = hat3(w)
    return np.eye(3) + _coef_b(th) * k + _coef_c(th) * (k @ k)


def so3_jr(w: np.ndarray) -> np.ndarray:
    return so3_jl(-np.asarray(w, float))


def so3_jl_inv(w: np.ndarray) -> np.ndarray:
    """Inverse left Jacobian of SO(3): I - hat(w)/2 + e hat(w)^2 (valid for angle < 2 pi)."""
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    k = hat3(w)
    return np.eye(3) - 0.5 * k + _coef_e(th) * (k @ k)


def so3_jr_inv(w: np.ndarray) -> np.ndarray:
    return so3_jl_inv(-np.asarray(w, float))


# ---------------------------------------------------------------- SE(2): xi = (omega, vx, vy)
def se2_hat(xi: np.ndarray) -> np.ndarray:
    xi = np.asarray(xi, float)
    w, x, y = np.moveaxis(xi, -1, 0)
    o = np.zeros_like(w)
    return np.stack([np.stack([o, -w, x], -1), np.stack([w, o, y], -1), np.stack([o, o, o], -1)], -2)


def se2_vee(x: np.ndarray) -> np.ndarray:
    return np.stack([x[..., 1, 0], x[..., 0, 2], x[..., 1, 2]], -1)


def _se2_v(th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """V(th) = [[A, -B], [B, A]] with A = sin/th, B = (1 - cos)/th (thesis sec. 6.2)."""
    return _coef_a(th), th * _coef_b(th)


def se2_exp(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xi = np.asarray(xi, float)
    th, v = xi[..., 0], xi[..., 1:]
    a, b = _se2_v(th)
    t = np.stack([a * v[..., 0] - b * v[..., 1], b * v[..., 0] + a * v[..., 1]], -1)
    return rot2(th), t


def se2_log(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    th = angle2(np.asarray(r, float))
    a, b = _se2_v(th)
    den = a * a + b * b
    t = np.asarray(t, float)
    v = np.stack([(a * t[..., 0] + b * t[..., 1]) / den, (-b * t[..., 0] + a * t[..., 1]) / den], -1)
    return np.concatenate([th[..., None], v], -1)


def se2_adjoint(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    r, t = np.asarray(r, float), np.asarray(t, float)
    out = np.zeros(r.shape[:-2] + (3, 3))
    out[..., 0, 0] = 1.0
    out[..., 1, 0] = t[..., 1]
    out[..., 2, 0] = -t[..., 0]
    out[..., 1:, 1:] = r
    return out


def _se2_jr_parts(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jr(xi) = [[1, 0], [b, M]]: returns the column b (..., 2) and M (..., 2, 2)."""
    xi = np.asarray(xi, float)
    th, p1, p2 = xi[..., 0], xi[..., 1], xi[..., 2]
    a = _coef_a(th)
    bb = th * _coef_b(th)          # (1 - cos)/th
    cc = th * _coef_c(th)          # (th - sin)/th^2
    dd = _coef_b(th)               # (1 - cos)/th^2
    col = np.stack([p1 * cc - p2 * dd, p1 * dd + p2 * cc], -1)
    m = np.stack([np.stack([a, bb], -1), np.stack([-bb, a], -1)], -2)
    return col, m


def se2_jr(xi: np.ndarray) -> np.ndarray:
    col, m = _se2_jr_parts(xi)
    out = np.zeros(col.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1.0
    out[..., 1:, 0] = col
    out[..., 1:, 1:] = m
    return out


def se2_jr_inv(xi: np.ndarray) -> np.ndarray:
    col, m = _se2_jr_parts(xi)
    # M = [[a, b], [-b, a]] is a scaled rotation: M^{-1} = M^T / (a^2 + b^2).
    den = (m[..., 0, 0] ** 2 + m[..., 0, 1] ** 2)[..., None, None]
    minv = np.swapaxes(m, -1, -2) / den
    out = np.zeros(col.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1.0
    out[..., 1:, 0] = -np.einsum("...ij,...j->...i", minv, col)
    out[..., 1:, 1:] = minv
    return out


# ---------------------------------------------------------------- SE(3): xi = (omega, v)
def se3_hat(xi: np.ndarray) -> np.ndarray:
    xi = np.asarray(xi, float)
    out = np.zeros(xi.shape[:-1] + (4, 4))
    out[..., :3, :3] = hat3(xi[..., :3])
    out[..., :3, 3] = xi[..., 3:]
    return out


def se3_vee(x: np.ndarray) -> np.ndarray:
    return np.stack([x[..., 2, 1], x[..., 0, 2], x[..., 1, 0], x[..., 0, 3], x[..., 1, 3], x[..., 2, 3]], -1)


def se3_exp(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xi = np.asarray(xi, float)
    w, v = xi[..., :3], xi[..., 3:]
    return exp_so3(w), np.einsum("...ij,...j->...i", so3_jl(w), v)


def se3_log(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    w = so3_log(r)
    v = np.einsum("...ij,...j->...i", so3_jl_inv(w), np.asarray(t, float))
    return np.concatenate([w, v], -1)


def se3_adjoint(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    r, t = np.asarray(r, float), np.asarray(t, float)
    out = np.zeros(r.shape[:-2] + (6, 6))
    out[..., :3, :3] = r
    out[..., 3:, 3:] = r
    out[..., 3:, :3] = hat3(t) @ r
    return out


def _se3_q(rho: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Barfoot's Q(rho, phi): the translation-rotation block of the SE(3) left Jacobian."""
    th = np.linalg.norm(phi, axis=-1)[..., None, None]
    p, r = hat3(phi), hat3(rho)
    pr, rp = p @ r, r @ p
    prp = pr @ p
    return (0.5 * r + _coef_c(th) * (pr + rp + prp)
            + _coef_c2(th) * (p @ pr + rp @ p - 3 * prp)
            + _coef_c3(th) * (prp @ p + p @ prp))


def se3_jr(xi: np.ndarray) -> np.ndarray:
    """Jr(omega, v) = Jl(-omega, -v) = [[Jr_so3, 0], [Q(-v, -omega), Jr_so3]]."""
    xi = np.asarray(xi, float)
    j = so3_jr(xi[..., :3])
    out = np.zeros(xi.shape[:-1] + (6, 6))
    out[..., :3, :3] = j
    out[..., 3:, 3:] = j
    out[..., 3:, :3] = _se3_q(-xi[..., 3:], -xi[..., :3])
    return out


def se3_jr_inv(xi: np.ndarray) -> np.ndarray:
    xi = np.asarray(xi, float)
    ji = so3_jr_inv(xi[..., :3])
    out = np.zeros(xi.shape[:-1] + (6, 6))
    out[..., :3, :3] = ji
    out[..., 3:, 3:] = ji
    out[..., 3:, :3] = -ji @ _se3_q(-xi[..., 3:], -xi[..., :3]) @ ji
    return out


# ---------------------------------------------------------------- dimension dispatch
def se_hat(xi: np.ndarray) -> np.ndarray:
    return se2_hat(xi) if np.shape(xi)[-1] == 3 else se3_hat(xi)


def se_vee(x: np.ndarray) -> np.ndarray:
    return se2_vee(x) if np.shape(x)[-1] == 3 else se3_vee(x)


def se_exp(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return se2_exp(xi) if np.shape(xi)[-1] == 3 else se3_exp(xi)


def se_log(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    return se2_log(r, t) if np.shape(r)[-1] == 2 else se3_log(r, t)


def se_adjoint(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    return se2_adjoint(r, t) if np.shape(r)[-1] == 2 else se3_adjoint(r, t)


def se_jr(xi: np.ndarray) -> np.ndarray:
    return se2_jr(xi) if np.shape(xi)[-1] == 3 else se3_jr(xi)


def se_jr_inv(xi: np.ndarray) -> np.ndarray:
    return se2_jr_inv(xi) if np.shape(xi)[-1] == 3 else se3_jr_inv(xi)


def se_inverse(r: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rt = np.swapaxes(np.asarray(r, float), -1, -2)
    return rt, -np.einsum("...ij,...j->...i", rt, np.asarray(t, float))


def se_compose(r1: np.ndarray, t1: np.ndarray, r2: np.ndarray, t2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R1, t1)(R2, t2) = (R1 R2, R1 t2 + t1)."""
    return r1 @ r2, np.einsum("...ij,...j->...i", r1, t2) + t1


def to_homogeneous(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    r, t = np.asarray(r, float), np.asarray(t, float)
    d = r.shape[-1]
    out = np.zeros(r.shape[:-2] + (d + 1, d + 1))
    out[..., :d, :d] = r
    out[..., :d, d] = t
    out[..., d, d] = 1.0
    return out


def from_homogeneous(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = x.shape[-1] - 1
    return np.array(x[..., :d, :d], float), np.array(x[..., :d, d], float)
