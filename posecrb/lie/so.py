"""SO(2) and SO(3) in closed form, batched over leading dimensions: exp, log, hat, left and right
Jacobians and their inverses, projection onto SO(d), and the one check of matrices that must be
rotations (docs/design.md#lie-groups)."""
from __future__ import annotations

import logging
from typing import Any

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


# ---------------------------------------------------------------- checking rotations
log = logging.getLogger("posecrb")

# Default tolerance of ``check_rotations`` on float input: this many machine epsilons of its type
# (a rotation stored to full precision has |R^T R - I| of a few eps; a chain of products and
# exp/log maps, a few tens).
ROTATION_TOL_EPS = 256
# Deviations above the tolerance and up to this are rounding of a coarser kind (what 3 to 4
# significant digits give, or float32 arithmetic): projected with a warning. Beyond it the
# matrices are not rotations (scaled, sheared, another layout): an error.
PROJECTION_LIMIT = 1e-3


class NotRotations(ValueError):
    """Matrices that must be rotations and are not, beyond projection; ``str(exc)`` says which
    rows and why, ``rows`` lists them (indices along the flattened leading dimensions)."""

    def __init__(self, reason: str, rows: np.ndarray | None = None):
        self.rows = np.zeros(0, dtype=np.int64) if rows is None else np.asarray(rows)
        super().__init__(reason)


def digits_tolerance(digits: int, dim: int) -> float:
    """``check_rotations``' tolerance for rotations read from text with ``digits`` significant
    digits: each entry (at most 1 in magnitude) is off by up to half a unit of its last digit,
    ``0.5 10^(1 - digits)``, and an entry of ``R^T R`` sums ``dim`` products of two entries, so
    ``|R^T R - I| <= dim 10^(1 - digits)`` to first order.

    Examples
    --------
    >>> digits_tolerance(7, 3)
    3e-06
    """
    return float(dim) * 10.0 ** (1 - digits)


def _rows(index: np.ndarray, total: int) -> str:
    shown = ", ".join(str(int(k)) for k in index[:5])
    return f"row{'s' if index.size > 1 else ''} {shown}{', ...' if index.size > 5 else ''} (of {total})"


def check_rotations(rot: Any, *, tol: float | None = None, limit: float = PROJECTION_LIMIT,
                    name: str = "rotations") -> tuple[np.ndarray, int]:
    """``(R, n_projected)``: ``rot`` (..., d, d) as float64 rotation matrices, d = 2 or 3.

    The one check of every matrix that must be a rotation (an ``Estimate``'s poses, a loaded
    ``SolveResult``, the matrix rows of an estimate file). A matrix whose orthonormality error
    ``max |R^T R - I|`` (entrywise) is at most ``tol`` is taken as it is; up to ``limit`` it is
    replaced by the nearest rotation (``so_project``: SVD, determinant fixed), with one warning
    naming how many and the largest deviation; beyond ``limit``, or with a negative determinant
    (a reflection, however orthonormal), ``NotRotations`` names the rows, the deviation and the
    determinant's sign.

    Parameters
    ----------
    rot : array_like
        (..., d, d) real matrices.
    tol : float, optional
        The input's precision: default ``ROTATION_TOL_EPS`` epsilons of its float type (256 eps
        = 5.7e-14 for float64; integers count as float64). For rotations read from text with k
        significant digits pass ``digits_tolerance(k, d)``.
    limit : float
        The largest deviation that is projected (``PROJECTION_LIMIT`` = 1e-3; at least ``tol``).
    name : str
        What the matrices are, for the warning and the error.

    Returns
    -------
    R : numpy.ndarray
        Float64, same shape; the input's values where nothing was projected (a new array only
        when something was).
    n_projected : int

    Raises
    ------
    NotRotations
        Complex, non-numeric or non-finite values, a shape other than (..., 2, 2) or (..., 3, 3),
        a deviation beyond ``limit`` or a reflection.

    Examples
    --------
    >>> r, n = check_rotations(np.eye(2)[None] * (1 + 1e-9))      # slightly off: projected
    >>> n, bool(np.allclose(r, np.eye(2), atol=1e-15))
    (1, True)
    >>> check_rotations(np.diag([1.0, -1.0])[None])
    Traceback (most recent call last):
    ...
    posecrb.lie.so.NotRotations: rotations: row 0 (of 1) is a reflection (determinant -1), not a rotation
    """
    a = np.asarray(rot)
    if np.iscomplexobj(a):
        raise NotRotations(f"{name}: complex values; rotations are real matrices")
    if a.dtype.kind not in "fiu":
        raise NotRotations(f"{name}: values of type {a.dtype} are not real numbers")
    if a.ndim < 2 or a.shape[-1] != a.shape[-2] or a.shape[-1] not in (2, 3):
        raise NotRotations(f"{name}: shape {a.shape} is not (..., d, d) with d = 2 or 3")
    if tol is None:
        tol = ROTATION_TOL_EPS * float(np.finfo(a.dtype if a.dtype.kind == "f" else np.float64).eps)
    d = a.shape[-1]
    flat = a.astype(np.float64, copy=False).reshape(-1, d, d)
    total = flat.shape[0]
    finite = np.isfinite(flat).all(axis=(1, 2))
    if not finite.all():
        raise NotRotations(f"{name}: {_rows(np.flatnonzero(~finite), total)} with non-finite values",
                           np.flatnonzero(~finite))
    deviation = np.abs(np.einsum("kji,kjl->kil", flat, flat) - np.eye(d)).max(axis=(1, 2), initial=0.0)
    det = np.linalg.det(flat) if total else np.zeros(0)
    far = np.flatnonzero(~(deviation <= max(limit, tol)))
    if far.size:
        worst = far[np.argmax(deviation[far])]
        verb = "is not a rotation" if far.size == 1 else "are not rotations"
        raise NotRotations(f"{name}: {_rows(far, total)} {verb}: max |R^T R - I| = {deviation[worst]:.3g} at row "
                           f"{worst} (determinant {det[worst]:.3g}), beyond {max(limit, tol):.3g}, the largest "
                           "deviation that is projected onto the rotations", far)
    reflection = np.flatnonzero(det < 0)
    if reflection.size:
        raise NotRotations(f"{name}: {_rows(reflection, total)} "
                           f"{'is a reflection' if reflection.size == 1 else 'are reflections'} (determinant "
                           f"{det[reflection[0]]:.3g}), not {'a rotation' if reflection.size == 1 else 'rotations'}",
                           reflection)
    off = deviation > tol
    n_off = int(np.count_nonzero(off))
    if n_off:
        flat = flat.copy()
        flat[off] = so_project(flat[off])
        log.warning("%s: %d of %d matrices are rotations only to within %.3g (max |R^T R - I|; tolerance %.3g): "
                    "replaced by the nearest rotations", name, n_off, total, float(deviation.max()), tol)
    return flat.reshape(a.shape), n_off


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
