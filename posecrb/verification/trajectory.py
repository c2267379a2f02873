"""Trajectory errors between two estimates of the same poses: ATE after a rigid alignment and RPE
between consecutive poses (docs/design.md#trajectory-errors).

The formulas are evo's (Grupp, https://github.com/MichaelGrupp/evo), restated: the ATE is the RMSE
of the position differences after the rigid motion (rotation and translation, no scale, det +1;
Umeyama 1991 / Horn 1987) that best fits the estimate's positions onto the reference's, and the
RMSE of the angles of ``R_ref,i^T R_align R_i``; the RPE compares the relative motions
``X_i^{-1} X_{i+1}`` of consecutive poses (in id order), so it needs no alignment.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ALIGNMENT = "rigid"     # the alignment of the ATE, as the JSON names it


def rotation_angles(r: np.ndarray) -> np.ndarray:
    """Rotation angles in radians of (k, d, d) rotations, robust at 0 and pi: atan2(sin, cos)."""
    d = r.shape[-1]
    skew = r - np.swapaxes(r, -1, -2)
    sin = np.sqrt(np.einsum("kab,kab->k", skew, skew)) / (2.0 * np.sqrt(2.0))
    cos = (np.trace(r, axis1=1, axis2=2) - (d - 2)) / 2.0
    return np.arctan2(sin, cos)


def align(trans: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid (R, t) minimising sum ||R p_i + t - q_i||^2 (Horn / Umeyama, no scale, det R = +1)."""
    mp, mq = trans.mean(0), ref.mean(0)
    cov = (ref - mq).T @ (trans - mp)
    u, _, vt = np.linalg.svd(cov)
    s = np.eye(trans.shape[1])
    s[-1, -1] = np.sign(np.linalg.det(u @ vt)) or 1.0
    rot = u @ s @ vt
    return rot, mq - rot @ mp


@dataclass(frozen=True)
class TrajectoryError:
    """ATE (after the rigid alignment) and RPE (consecutive poses) of an estimate against a reference."""

    ate_trans: float      # RMSE of the aligned positions' differences (the file's length unit)
    ate_rot_deg: float    # RMSE of the aligned orientations' angles (degrees)
    rpe_trans: float      # RMSE over consecutive poses of the relative-translation error
    rpe_rot_deg: float    # RMSE over consecutive poses of the relative-rotation angle (degrees)


def trajectory_error(rot: np.ndarray, trans: np.ndarray, ref_rot: np.ndarray, ref_trans: np.ndarray
                     ) -> TrajectoryError:
    """ATE after rigid alignment and RPE (delta = 1 pose, in id order) of an estimate against a reference.

    ``rot`` (n, d, d), ``trans`` (n, d): the estimate; ``ref_rot``, ``ref_trans``: the reference,
    row k the same pose. The RPE of a single pose is 0."""
    ra, ta = align(trans, ref_trans)
    pos = trans @ ra.T + ta
    ate_t = float(np.sqrt(np.mean(np.sum((pos - ref_trans) ** 2, axis=1))))
    rel = np.swapaxes(ref_rot, 1, 2) @ (ra[None] @ rot)
    ate_r = float(np.degrees(np.sqrt(np.mean(rotation_angles(rel) ** 2))))
    if rot.shape[0] < 2:
        return TrajectoryError(ate_t, ate_r, 0.0, 0.0)
    r_est = np.swapaxes(rot[:-1], 1, 2) @ rot[1:]
    t_est = np.einsum("kba,kb->ka", rot[:-1], trans[1:] - trans[:-1])
    r_ref = np.swapaxes(ref_rot[:-1], 1, 2) @ ref_rot[1:]
    t_ref = np.einsum("kba,kb->ka", ref_rot[:-1], ref_trans[1:] - ref_trans[:-1])
    err_r = np.swapaxes(r_ref, 1, 2) @ r_est
    err_t = np.einsum("kba,kb->ka", r_ref, t_est - t_ref)
    rpe_t = float(np.sqrt(np.mean(np.sum(err_t ** 2, axis=1))))
    rpe_r = float(np.degrees(np.sqrt(np.mean(rotation_angles(err_r) ** 2))))
    return TrajectoryError(ate_t, ate_r, rpe_t, rpe_r)
