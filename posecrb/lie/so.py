"""Rotation helpers shared by the readers, writers and generators (batched, closed form)."""
from __future__ import annotations

import numpy as np


def rot2(theta: np.ndarray) -> np.ndarray:
    """(..., 2, 2) rotation matrices from angles."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def angle2(rot: np.ndarray) -> np.ndarray:
    return np.arctan2(rot[..., 1, 0], rot[..., 0, 0])


def hat3(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) skew-symmetric matrices [v]_x."""
    x, y, z = np.moveaxis(v, -1, 0)
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, batched, accurate near zero."""
    w = np.asarray(w, float)
    th2 = np.sum(w * w, -1)[..., None, None]
    th = np.sqrt(th2)
    small = th2 < 1e-12
    a = np.where(small, 1 - th2 / 6, np.sin(th) / np.where(small, 1, th))
    b = np.where(small, 0.5 - th2 / 24, (1 - np.cos(th)) / np.where(small, 1, th2))
    k = hat3(w)
    return np.eye(3) + a * k + b * (k @ k)


def project_to_so(m: np.ndarray) -> np.ndarray:
    """Nearest rotation (Frobenius) to each (..., d, d) matrix."""
    u, _, vt = np.linalg.svd(m)
    det = np.linalg.det(u @ vt)
    u[..., :, -1] *= np.where(det < 0, -1.0, 1.0)[..., None]
    return u @ vt
