"""Small synthetic pose graphs with known ground truth (for tests and benchmarks of the solver).

Edges are an odometry chain plus random loop closures; each measurement is the true
relative pose ``X_i^{-1} X_j`` perturbed by isotropic noise (rotation: exp of a Gaussian
tangent vector; translation: Gaussian), with information matrices encoding the given
(tau, kappa) in the SE-Sync convention (docs/design.md#noise-model).
"""
from __future__ import annotations

import numpy as np

from posecrb.core.graph import PoseGraph
from posecrb.lie.so import so2_exp, so3_exp


def random_rotations(n: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    if dim == 2:
        return so2_exp(rng.uniform(-np.pi, np.pi, n))
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    from posecrb.io.rotations import quat_to_rot

    return quat_to_rot(q)


def _small_rotations(m: int, dim: int, sigma: float, rng: np.random.Generator) -> np.ndarray:
    if dim == 2:
        return so2_exp(sigma * rng.standard_normal(m))
    return so3_exp(sigma * rng.standard_normal((m, 3)))


def random_pose_graph(n: int, dim: int, rng: np.random.Generator, *, loop_closures: int | None = None,
                      rot_noise: float = 0.0, trans_noise: float = 0.0, tau: float = 10.0,
                      kappa: float = 50.0, step: float = 1.0) -> tuple[PoseGraph, np.ndarray, np.ndarray]:
    """(graph, true rotations (n, d, d), true translations (n, d)); vertices hold the truth."""
    rot = random_rotations(n, dim, rng)
    trans = np.cumsum(step * rng.standard_normal((n, dim)), axis=0)
    k = n if loop_closures is None else loop_closures
    src = np.arange(n - 1)
    dst = np.arange(1, n)
    if k > 0 and n > 2:
        a = rng.integers(0, n, size=4 * k)
        b = rng.integers(0, n, size=4 * k)
        keep = a != b
        a, b = a[keep][:k], b[keep][:k]
        src = np.concatenate([src, np.minimum(a, b)])
        dst = np.concatenate([dst, np.maximum(a, b)])
    m = src.shape[0]
    rel_rot = np.swapaxes(rot[src], 1, 2) @ rot[dst] @ _small_rotations(m, dim, rot_noise, rng)
    rel_t = np.einsum("eba,eb->ea", rot[src], trans[dst] - trans[src]) + trans_noise * rng.standard_normal((m, dim))
    q = 3 if dim == 2 else 6
    info = np.zeros((m, q, q))
    info[:, :dim, :dim] = tau * np.eye(dim)
    info[:, dim:, dim:] = (kappa if dim == 2 else 2.0 * kappa) * np.eye(q - dim)
    graph = PoseGraph(dim=dim, ids=np.arange(n), src=src, dst=dst, rot=rel_rot, trans=rel_t, info=info,
                      vertex_rot=rot, vertex_trans=trans, format="synthetic")
    return graph, rot, trans
