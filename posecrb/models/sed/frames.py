"""World- and body-frame coordinates of the sed model (the thesis's, on SE(d)^n), GTSAM's and g2o's convention.

The sed model (``posecrb.models.sed.fim``, thesis 4.5-4.6) perturbs ``T_i = X_i^{-1}`` on the right,
``T_i Exp(delta_i)``, with ``delta_i = (omega, v)`` rotation first. For the file's pose
``X_i = (R_i, t_i)`` (body to world) that is ``X_i -> Exp(-delta_i) X_i``: a perturbation
about the **world** origin, so a pose's block carries lever-arm terms (rotation
uncertainty times the pose's distance from the origin). posecrb calls these coordinates
``frame="world"``; they are the thesis' quantities and the default.

GTSAM and g2o retract on the right, ``X_i -> X_i Exp(xi_i)``: a perturbation in the pose's
own **body** frame (``frame="body"``), in GTSAM's tangent order: Pose2 ``(x, y, theta)``,
Pose3 ``(rx, ry, rz, x, y, z)`` (rotation first). Since ``X^{-1} Exp(-delta) X =
Exp(-Ad_{X^{-1}} delta)`` (thesis 2.7, the adjoint)::

    Exp(-delta) X_i = X_i Exp(xi_i),   xi_i = B_i delta_i,   B_i = -P Ad_{X_i^{-1}},

with ``Ad`` in rotation-first coordinates (``posecrb.lie.se.se_adjoint``) and ``P`` the
reordering rotation-first -> GTSAM order (2D ``(omega, vx, vy) -> (vx, vy, omega)``, 3D the
identity). ``B_i^{-1} = -Ad_{X_i} P^T``. The map is linear and block diagonal, so

* covariances (any bound's per-pose block, anchored 5.1 or quotient 5.5):
  ``C_body,i = B_i C_world,i B_i^T``;
* information: with ``M = blkdiag(B_i)``, ``F_world = M^T F_body M``, hence
  ``F_body = M^{-T} F_world M^{-1}`` (same sparsity pattern, pose-major).

``det B_i = +-1`` (``Ad`` of a rigid motion has unit determinant), so log-determinants of
the FIM with any set of poses removed, ranks and nullities are the same in both frames;
traces are not. The anchored bound fixes the anchor pose itself (``delta_a = 0`` iff
``xi_a = 0``), which is the gauge GTSAM's marginals have when the anchor is known exactly.
The quotient bound (5.5) mapped to body coordinates is the covariance of the same
gauge-fixed error (the one of minimum norm in world coordinates) expressed in body
coordinates; it is a generalised inverse of ``F_body`` but not its Moore-Penrose inverse.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from ...core.choices import FRAMES
from ...core.errors import InternalError, UsageError
from ...core.graph import PoseGraph
from ...lie.se import se_adjoint, se_inverse
from .crlb import SedCrlb, sed_crlb


def check_frame(frame: str) -> str:
    if frame not in FRAMES:
        raise UsageError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    return frame


def gtsam_order(dim: int) -> np.ndarray:
    """Index array ``perm`` with ``xi_gtsam[k] = xi_rotation_first[perm[k]]`` (the matrix P)."""
    if dim == 2:
        return np.array([1, 2, 0])
    if dim == 3:
        return np.arange(6)
    raise UsageError(f"dimension must be 2 or 3, got {dim}")


def coordinate_names(dim: int, frame: str = "world") -> list[str]:
    """Names of a pose's coordinates in ``frame`` (world: the thesis' rotation-first Lie algebra
    coordinates; body: GTSAM's Pose2/Pose3 tangent coordinates)."""
    check_frame(frame)
    if frame == "world":
        return ["omega", "vx", "vy"] if dim == 2 else ["omega1", "omega2", "omega3", "v1", "v2", "v3"]
    return ["x", "y", "theta"] if dim == 2 else ["rx", "ry", "rz", "x", "y", "z"]


def coordinates_description(dim: int, frame: str = "world") -> str:
    """One sentence saying what the coordinates of ``frame`` mean (the JSON ``coordinates_description``).

    ``frame="mixed"`` describes the paper model's coordinates (``posecrb.models.paper.fim``), which are neither.
    """
    if frame == "mixed":
        return ("paper model: translation x_i -> x_i + dx in the world frame, rotation R_i -> R_i Exp(.) in the "
                "body frame (" + ("angle" if dim == 2 else "along G_k / sqrt(2)") + "); translation first")
    check_frame(frame)
    if frame == "world":
        return ("world frame: X_i -> Exp(-delta) X_i (thesis model T_i = X_i^-1 perturbed as T_i Exp(delta)), "
                "perturbation about the world origin, Lie algebra coordinates rotation first "
                + ("(omega, vx, vy)" if dim == 2 else "(omega1..3, v1..3)"))
    return ("body frame: X_i -> X_i Exp(xi) (GTSAM's and g2o's retraction), GTSAM's tangent order "
            + ("Pose2 (x, y, theta)" if dim == 2 else "Pose3 (rotation rx, ry, rz; translation x, y, z)"))


def body_map(rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """(n, q, q) matrices ``B_i = -P Ad_{X_i^{-1}}``: body coordinates ``xi_i = B_i delta_i`` of a world one."""
    ad = se_adjoint(*se_inverse(rot, trans))
    return -ad[:, gtsam_order(np.shape(rot)[-1]), :]


def world_map(rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """(n, q, q) matrices ``B_i^{-1} = -Ad_{X_i} P^T``: world coordinates ``delta_i`` of a body one."""
    ad = se_adjoint(np.asarray(rot, float), np.asarray(trans, float))
    return -ad[:, :, gtsam_order(np.shape(rot)[-1])]


def _maps(rot: np.ndarray, trans: np.ndarray, to: str) -> np.ndarray:
    """The per-pose map taking coordinates INTO frame ``to`` (from the other one)."""
    return body_map(rot, trans) if check_frame(to) == "body" else world_map(rot, trans)


def convert_covariance_blocks(blocks: np.ndarray, rot: np.ndarray, trans: np.ndarray, to: str) -> np.ndarray:
    """Per-pose covariance blocks (n, q, q) from the other frame into ``to``: ``A_i C_i A_i^T``.

    ``rot`` (n, d, d), ``trans`` (n, d) are the poses X_i (file convention) the blocks belong to;
    ``A_i = B_i`` into "body", ``B_i^{-1}`` into "world" (module docstring).
    """
    a = _maps(rot, trans, to)
    out = a @ np.asarray(blocks, float) @ np.swapaxes(a, 1, 2)
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def _block_diagonal(blocks: np.ndarray) -> sp.bsr_matrix:
    n, q, _ = blocks.shape
    return sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(n * q, n * q))


def convert_information(matrix: sp.spmatrix, rot: np.ndarray, trans: np.ndarray, to: str) -> sp.csc_matrix:
    """A pose-major information matrix (n q, n q) from the other frame into ``to``, sparse.

    Into "body": ``M^{-T} F M^{-1}``; into "world": ``M^T F M`` with ``M = blkdiag(B_i)``
    (module docstring). The block pattern is unchanged; the result is symmetrised.
    """
    n = np.shape(rot)[0]
    q = matrix.shape[0] // n if n else 0
    if matrix.shape != (n * q, n * q) or (n and q not in (3, 6)):
        raise UsageError(f"information matrix of shape {matrix.shape} does not match {n} poses")
    # coordinates in the source frame are W^{-1}-images: x_src = W x_to with W the inverse map
    w = _block_diagonal(_maps(rot, trans, "world" if to == "body" else "body"))
    out = (w.T @ sp.csc_matrix(matrix) @ w).tocsc()
    return ((out + out.T) * 0.5).tocsc()


def sed_crlb_in_frame(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, frame: str = "world", *,
                     anchors: Sequence[int] | None = None, quotient: bool = False,
                     per_pose: bool | Sequence[int] = False, **sed_options: Any) -> SedCrlb:
    """``posecrb.models.sed.crlb.sed_crlb`` with traces and per-pose blocks in ``frame`` ("world" or "body").

    "world" is ``sed_crlb`` unchanged. "body" converts every per-pose block (5.1 / 5.5) with
    ``B_i C_i B_i^T`` (module docstring); the trace (hence ``mse_bound``) is the sum of the
    converted blocks' traces, so all blocks are computed whatever ``per_pose`` asks for.
    ``sed_options`` go to ``sed_crlb`` (``fim``, ``indefinite``, ``information``).
    """

    if check_frame(frame) == "world":
        return sed_crlb(graph, rot, trans, anchors=anchors, quotient=quotient, per_pose=per_pose, **sed_options)
    if per_pose is True:
        want: np.ndarray | None = np.arange(graph.n)
    elif per_pose is False or per_pose is None:
        want = None
    else:
        want = np.unique(np.asarray(list(per_pose), dtype=np.int64))
        if want.size and (want[0] < 0 or want[-1] >= graph.n):
            raise UsageError(f"pose index out of range 0..{graph.n - 1}")
    res = sed_crlb(graph, rot, trans, anchors=anchors, quotient=quotient, per_pose=True, **sed_options)
    if res.per_pose is None:  # per_pose=True asks for every block
        raise InternalError("sed_crlb returned no per-pose blocks")
    keys = np.fromiter(res.per_pose.keys(), np.int64, res.n)
    if not np.array_equal(keys, np.arange(res.n)):  # the stacking below relies on pose order
        raise InternalError("sed_crlb returned per-pose blocks out of pose order")
    blocks = np.stack(list(res.per_pose.values())) if res.n else np.zeros((0, res.q, res.q))
    body = convert_covariance_blocks(blocks, rot, trans, "body")
    trace = float(np.trace(body, axis1=1, axis2=2).sum())
    n_err = res.n - (len(res.anchors) if res.kind == "anchored" else res.components)
    per = None if want is None else dict(zip(want.tolist(), body[want]))
    return replace(res, frame="body", trace_crlb=trace, mse_bound=trace / n_err if n_err > 0 else float("nan"),
                   per_pose=per)
