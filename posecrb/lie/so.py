"""SO(2) and SO(3) in closed form, batched over leading dimensions: exp, log, hat, left and right
Jacobians and their inverses, projection onto SO(d) (docs/design.md#lie-groups)."""
from __future__ import annotations

import numpy as np

from ._series import _coef_a, _coef_b, _coef_c, _coef_e


def so2_exp(theta: np.ndarray) -> np.ndarray:
    """(..., 2, 2) rotation matrices from angles."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def so2_log(rot: np.ndarray) -> np.ndarray:
    return np.arctan2(rot[..., 1, 0], rot[..., 0, 0])


def so3_hat(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) skew-symmetric matrices [v]_x."""
    x, y, z = np.moveaxis(v, -1, 0)
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, batched, accurate near zero."""
    w = np.asarray(w, float)
    th2 = np.sum(w * w, -1)[..., None, None]
    th = np.sqrt(th2)
    small = th2 < 1e-12
    a = np.where(small, 1 - th2 / 6, np.sin(th) / np.where(small, 1, th))
    b = np.where(small, 0.5 - th2 / 24, (1 - np.cos(th)) / np.where(small, 1, th2))
    k = so3_hat(w)
    return np.eye(3) + a * k + b * (k @ k)


def so_project(m: np.ndarray) -> np.ndarray:
    """Nearest rotation (Frobenius) to each (..., d, d) matrix."""
    u, _, vt = np.linalg.svd(m)
    det = np.linalg.det(u @ vt)
    u[..., :, -1] *= np.where(det < 0, -1.0, 1.0)[..., None]
    return u @ vt


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
    k = so3_hat(w)
    return np.eye(3) + _coef_b(th) * k + _coef_c(th) * (k @ k)


def so3_jr(w: np.ndarray) -> np.ndarray:
    return so3_jl(-np.asarray(w, float))


def so3_jl_inv(w: np.ndarray) -> np.ndarray:
    """Inverse left Jacobian of SO(3): I - hat(w)/2 + e hat(w)^2 (valid for angle < 2 pi)."""
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    k = so3_hat(w)
    return np.eye(3) - 0.5 * k + _coef_e(th) * (k @ k)


def so3_jr_inv(w: np.ndarray) -> np.ndarray:
    return so3_jl_inv(-np.asarray(w, float))
