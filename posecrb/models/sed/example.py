"""The thesis' chapter 6 case study on SE(2) (Bertini, sections 6.1-6.3), as a fixture.

Five poses, six directed arcs ``(1,2), (2,1), (3,4), (4,5), (5,4), (5,3)`` forming two connected
components ``{1, 2}`` and ``{3, 4, 5}``, heteroscedastic diagonal covariances of the
left-multiplicative noise (4.3) in (omega, v_x, v_y) coordinates, and anchors ``{1, 3}``
(sec. 6.4, 6.7). Expected: the FIM has exactly ``3 c = 6`` zero eigenvalues (sec. 6.6).

The thesis' poses ``T_i`` (sec. 6.2) are stored as the graph's vertices ``X_i = T_i^{-1}`` so that
the file convention ``X_i^{-1} X_j = T_i T_j^{-1}`` holds (docs/design.md#thesis-example), and each arc's
information is stored in g2o convention such that ``posecrb.models.sed.fim`` recovers exactly
``Omega_ij = Sigma_ij^{-1}`` (``posecrb.models.sed.fim.right_information_from_left``).
Pose ids are the thesis' labels 1..5; internal indices are 0..4.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ...core.errors import UsageError
from ...core.graph import PoseGraph
from ...lie.se import relative_poses, se_compose, se_exp, se_inverse
from ...lie.so import so2_exp
from .fim import right_information_from_left

IDS = (1, 2, 3, 4, 5)
# (theta, t_x, t_y) of the true poses T_i (sec. 6.2; the matrices printed there are these,
# rounded to 4 digits)
POSE_PARAMS = np.array([
    [0.55, -0.6, 0.2],
    [1.05, 0.9, 0.1],
    [-0.75, -0.2, 1.2],
    [0.30, 1.1, 1.6],
    [-0.15, 2.0, 0.9],
])
EDGES = ((1, 2), (2, 1), (3, 4), (4, 5), (5, 4), (5, 3))
# Sigma_ij = diag(sigma_omega^2, sigma_x^2, sigma_y^2), sec. 6.3, in the order of EDGES
SIGMA_DIAG = np.array([
    [0.0060, 0.0010, 0.0080],
    [0.0020, 0.0090, 0.0010],
    [0.0050, 0.0070, 0.0090],
    [0.0070, 0.0060, 0.0100],
    [0.0090, 0.0080, 0.0060],
    [0.0065, 0.0055, 0.0075],
])
ANCHOR_IDS = (1, 3)
COMPONENTS = ((1, 2), (3, 4, 5))
N_ZERO_EIGENVALUES = 6


def _index(ids: npt.ArrayLike) -> np.ndarray:
    return np.asarray(ids, dtype=np.int64) - 1


SRC = _index([e[0] for e in EDGES])
DST = _index([e[1] for e in EDGES])
ANCHORS = [int(i) for i in _index(ANCHOR_IDS)]   # internal indices [0, 2]


def true_poses() -> tuple[np.ndarray, np.ndarray]:
    """The thesis' true poses ``T_i`` as (rotations (5, 2, 2), translations (5, 2))."""
    return so2_exp(POSE_PARAMS[:, 0]), POSE_PARAMS[:, 1:].copy()


def true_estimate() -> tuple[np.ndarray, np.ndarray]:
    """The true poses in the file's convention, ``X_i = T_i^{-1}``: the argument of ``sed_fim``."""
    return se_inverse(*true_poses())


def sigma() -> np.ndarray:
    """(6, 3, 3) covariances Sigma_ij of the left noise, rotation first (sec. 6.3)."""
    return np.einsum("ej,jk->ejk", SIGMA_DIAG, np.eye(3))


def left_information() -> np.ndarray:
    """(6, 3, 3) Omega_ij = Sigma_ij^{-1}."""
    return np.einsum("ej,jk->ejk", 1.0 / SIGMA_DIAG, np.eye(3))


def true_relative() -> tuple[np.ndarray, np.ndarray]:
    """Noise-free measurements ``T_i T_j^{-1} = X_i^{-1} X_j`` (6, 2, 2), (6, 2) in the order of EDGES."""
    return relative_poses(*true_estimate(), SRC, DST)


def _graph(src: np.ndarray, dst: np.ndarray, rot: np.ndarray, trans: np.ndarray,
           omega_left: np.ndarray) -> PoseGraph:

    xr, xt = true_estimate()
    return PoseGraph(
        dim=2, ids=np.asarray(IDS, dtype=np.int64), src=np.asarray(src, np.int64), dst=np.asarray(dst, np.int64),
        rot=rot, trans=trans, info=right_information_from_left(rot, trans, omega_left),
        vertex_rot=xr, vertex_trans=xt, path=None, format="synthetic")


def thesis_graph() -> PoseGraph:
    """The chapter 6 graph with noise-free measurements; vertices are the truth (X_i = T_i^{-1})."""
    r, t = true_relative()
    return _graph(SRC, DST, r, t, left_information())


def sample_graph(rng: np.random.Generator, m: int = 1) -> PoseGraph:
    """``m`` noisy measurements per directed arc, ``H_ij = Exp(xi) T_i T_j^{-1}``, ``xi ~ N(0, Sigma_ij)`` (4.10).

    Parallel edges are stored arc by arc (all ``m`` copies of EDGES[0] first); the FIM at the truth
    is then ``m F_1`` (4.12). Vertices are the truth.
    """
    if m < 1:
        raise UsageError("m must be >= 1")
    k = len(EDGES)
    chol = np.sqrt(SIGMA_DIAG)
    xi = rng.standard_normal((k, m, 3)) * chol[:, None, :]
    r0, t0 = true_relative()
    er, et = se_exp(xi.reshape(k * m, 3))
    rot, trans = se_compose(er, et, np.repeat(r0, m, axis=0), np.repeat(t0, m, axis=0))
    return _graph(np.repeat(SRC, m), np.repeat(DST, m), rot, trans, np.repeat(left_information(), m, axis=0))
