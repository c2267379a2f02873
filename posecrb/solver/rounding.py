"""Rounding a relaxed solution to SO(d)^n and recovering translations (SE-Sync Algorithm 2)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .problem import Problem
from .stiefel import nearest_rotations


def round_rotations(Z: np.ndarray) -> np.ndarray:
    """(n, d, d) rotations from Z (n, d, r): top-d principal subspace of Y, majority
    determinant sign, then the nearest rotation per block.

    With ``Y = U S V^T`` (r x dn) SE-Sync keeps ``S_d V_d^T``; in the row layout that is
    ``Z U_d`` with ``U_d`` the top-d eigenvectors of the r x r Gram matrix ``Z^T Z``.
    """
    n, d, r = Z.shape
    Zf = Z.reshape(n * d, r)
    _, U = np.linalg.eigh(Zf.T @ Zf)
    B = (Zf @ U[:, ::-1][:, :d]).reshape(n, d, d)      # blocks ~ R_i^T
    if np.count_nonzero(np.linalg.det(B) > 0) < n / 2:
        B[:, :, -1] *= -1.0                              # reflect: det -> +
    return np.ascontiguousarray(np.swapaxes(nearest_rotations(B), 1, 2))


def recover_translations(problem: Problem, rot: np.ndarray) -> np.ndarray:
    """Optimal translations t(R) (n, d) for fixed rotations (t_0 = 0)."""
    n, d = problem.n, problem.d
    Z = np.ascontiguousarray(np.swapaxes(rot, 1, 2)).reshape(n * d, d)
    return problem.translations(Z)


def se_objective(problem: Problem, rot: np.ndarray, trans: np.ndarray) -> float:
    """F(R, t) = sum kappa (||R_i||^2 + ||R_j||^2 - 2 tr(R_j^T R_i R~)) + tau ||t_j - t_i - R_i t~||^2,
    SE-Sync's data-matrix objective, summed edge by edge as
    ``kappa ||R_j - R_i R~||_F^2 + kappa tr(R_i (I - R~ R~^T) R_i^T)`` (the second term only on
    edges whose R~ is not orthogonal; see problem.py). Equal to
    ``sum kappa ||R_j - R_i R~||_F^2 + tau ||...||^2`` for orthogonal measurements."""
    s, t = problem.src, problem.dst
    rr = rot[t] - rot[s] @ problem.rot
    tr = trans[t] - trans[s] - np.einsum("eab,eb->ea", rot[s], problem.trans)
    f = float(np.dot(problem.kappa, np.einsum("eab,eab->e", rr, rr))
              + np.dot(problem.tau, np.einsum("ea,ea->e", tr, tr)))
    # Z_i = R_i^T in the row layout of problem.py
    return f + problem.defect_term(np.swapaxes(rot[s[problem.defect_edges]], 1, 2))


def anchor_estimate(rot: np.ndarray, trans: np.ndarray, anchor: int) -> tuple[np.ndarray, np.ndarray]:
    """Apply the gauge X_i <- X_a^{-1} X_i so that pose ``anchor`` is the identity (F is invariant)."""
    Ra = rot[anchor]
    rot2 = Ra.T @ rot
    trans2 = (trans - trans[anchor]) @ Ra
    rot2[anchor] = np.eye(rot.shape[1])
    trans2[anchor] = 0.0
    return rot2, trans2


@dataclass(frozen=True)
class Rounding:
    """The estimate rounded from a staircase level's point: its objective F, rotations (n, d, d) and
    translations (n, d) (pose 0 at the origin), and the level and rank it comes from."""

    level: int
    rank: int
    objective: float
    rot: np.ndarray
    trans: np.ndarray


def round_point(problem: Problem, Z: np.ndarray, level: int, rank: int) -> Rounding:
    """The rounding of a relaxed point Z (n, d, r): rotations, their optimal translations, F there."""
    rot = round_rotations(Z)
    trans = recover_translations(problem, rot)
    return Rounding(level, rank, se_objective(problem, rot, trans), rot, trans)


def pose_objective(problem: Problem, rot: np.ndarray, trans: np.ndarray | None = None) -> float:
    """SE-Sync's objective F at poses given as rotations (n, d, d) and translations (n, d).

    With ``trans=None`` the translations are eliminated: ``F*(R) = min_t F(R, t)``, at the optimal
    translations :func:`recover_translations` (what ``posecrb solve`` reports as ``objective`` at its
    rotations). Given translations are used as they are (F is invariant under a common rigid
    motion of the poses, so any anchoring will do).
    """
    rot = np.asarray(rot, dtype=float)
    trans = recover_translations(problem, rot) if trans is None else np.asarray(trans, dtype=float)
    return se_objective(problem, rot, trans)
