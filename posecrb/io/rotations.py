"""File encodings of rotations: unit quaternions (g2o's qx qy qz qw) and TORO's Euler angles <-> rotation
matrices. Not group operations (those are in posecrb.lie).
"""
from __future__ import annotations

import numpy as np


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """(..., 3, 3) from unit quaternions (x, y, z, w) (g2o order)."""
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def rot_to_quat(r: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) with w >= 0, robust for every rotation."""
    r = np.asarray(r, float)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    # Pick the numerically largest of 4w^2, 4x^2, 4y^2, 4z^2 per rotation.
    cands = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    k = np.argmax(cands, -1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(cands, k[..., None], -1)[..., 0], 1e-300))
    q = np.empty(r.shape[:-2] + (4,))
    d10, d01 = r[..., 1, 0], r[..., 0, 1]
    d20, d02 = r[..., 2, 0], r[..., 0, 2]
    d21, d12 = r[..., 2, 1], r[..., 1, 2]
    opts = [
        np.stack([(d21 - d12) / s, (d02 - d20) / s, (d10 - d01) / s, s / 4], -1),
        np.stack([s / 4, (d01 + d10) / s, (d02 + d20) / s, (d21 - d12) / s], -1),
        np.stack([(d01 + d10) / s, s / 4, (d12 + d21) / s, (d02 - d20) / s], -1),
        np.stack([(d02 + d20) / s, (d12 + d21) / s, s / 4, (d10 - d01) / s], -1),
    ]
    for i, o in enumerate(opts):
        q[k == i] = o[k == i]
    q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def euler_to_rot(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) (TORO's convention)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp_ = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.stack([
        np.stack([cy * cp, cy * sp_ * sr - sy * cr, cy * sp_ * cr + sy * sr], -1),
        np.stack([sy * cp, sy * sp_ * sr + cy * cr, sy * sp_ * cr - cy * sr], -1),
        np.stack([-sp_, cp * sr, cp * cr], -1),
    ], -2)


def rot_to_euler(r: np.ndarray) -> np.ndarray:
    """(..., 3) angles (roll, pitch, yaw) with R = Rz(yaw) Ry(pitch) Rx(roll) (TORO's convention),
    the inverse of ``euler_to_rot``.

    Yaw comes from the first column; roll and pitch from M = Rz(-yaw) R = Ry(pitch) Rx(roll),
    whose entries (cos, sin pairs of unit size) keep every angle well conditioned up to the
    gimbal lock (pitch = +-pi/2, where roll and yaw are no longer separate and yaw = 0 is chosen
    by atan2(0, 0)); asin(-r20) would lose half the digits of pitch there.
    """
    r = np.asarray(r, float)
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    cy, sy = np.cos(yaw), np.sin(yaw)
    m00 = cy * r[..., 0, 0] + sy * r[..., 1, 0]
    m11 = -sy * r[..., 0, 1] + cy * r[..., 1, 1]
    m12 = -sy * r[..., 0, 2] + cy * r[..., 1, 2]
    roll = np.arctan2(-m12, m11)
    pitch = np.arctan2(-r[..., 2, 0], m00)
    return np.stack([roll, pitch, yaw], -1)
