"""SE(2) / SE(3) in closed form, batched over leading array dimensions (thesis ch. 2.5, 6.2).

Conventions (docs/design.md#lie-groups, thesis sec. 6.2):

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

import numpy as np

from ._series import _coef_a, _coef_b, _coef_c, _coef_c2, _coef_c3
from .so import so2_exp, so2_log, so3_exp, so3_hat, so3_jl, so3_jl_inv, so3_jr, so3_jr_inv, so3_log


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
    return so2_exp(th), t


def se2_log(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    th = so2_log(np.asarray(r, float))
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
    out[..., :3, :3] = so3_hat(xi[..., :3])
    out[..., :3, 3] = xi[..., 3:]
    return out


def se3_vee(x: np.ndarray) -> np.ndarray:
    return np.stack([x[..., 2, 1], x[..., 0, 2], x[..., 1, 0], x[..., 0, 3], x[..., 1, 3], x[..., 2, 3]], -1)


def se3_exp(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xi = np.asarray(xi, float)
    w, v = xi[..., :3], xi[..., 3:]
    return so3_exp(w), np.einsum("...ij,...j->...i", so3_jl(w), v)


def se3_log(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    w = so3_log(r)
    v = np.einsum("...ij,...j->...i", so3_jl_inv(w), np.asarray(t, float))
    return np.concatenate([w, v], -1)


def se3_adjoint(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    r, t = np.asarray(r, float), np.asarray(t, float)
    out = np.zeros(r.shape[:-2] + (6, 6))
    out[..., :3, :3] = r
    out[..., 3:, 3:] = r
    out[..., 3:, :3] = so3_hat(t) @ r
    return out


def _se3_q(rho: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Barfoot's Q(rho, phi): the translation-rotation block of the SE(3) left Jacobian."""
    th = np.linalg.norm(phi, axis=-1)[..., None, None]
    p, r = so3_hat(phi), so3_hat(rho)
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


def relative_poses(rot: np.ndarray, trans: np.ndarray, src: np.ndarray, dst: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free measurements ``X_i^{-1} X_j``: ``(R_i^T R_j, R_i^T (t_j - t_i))`` per edge."""
    ri_t = np.swapaxes(rot[src], -1, -2)
    return ri_t @ rot[dst], np.einsum("mab,mb->ma", ri_t, trans[dst] - trans[src])
