"""Riemannian geometry of the relaxed problem vs independent references.

References: dense numpy data matrices built from their definitions (SE-Sync section 4.1),
finite differences along the retraction, and a direct least-squares solve for translations.
"""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.solver.problem import Problem
from posecrb.solver.relaxed import RelaxedProblem
from posecrb.solver.stiefel import project, random_point, remove_vertical, retract

from ..helpers import random_pose_graph
from .references import dense_Q


@pytest.mark.parametrize("dim", [2, 3])
def test_Q_product_and_objective_match_dense(dim):
    rng = np.random.default_rng(10 + dim)
    g, _, _ = random_pose_graph(12, dim, rng, rot_noise=0.3, trans_noise=0.5)
    p = Problem.from_graph(g)
    Q = dense_Q(g)
    Z = random_point(g.n, dim, dim + 2, rng)
    Zf = Z.reshape(-1, dim + 2)
    np.testing.assert_allclose(p.Q_product(Zf), Q @ Zf, rtol=1e-9, atol=1e-9 * np.abs(Q).max())
    assert p.objective(Zf) == pytest.approx(np.trace(Zf.T @ Q @ Zf), rel=1e-10)


@pytest.mark.parametrize("dim", [2, 3])
def test_gradient_and_hessian_vs_finite_differences(dim):
    rng = np.random.default_rng(20 + dim)
    g, _, _ = random_pose_graph(10, dim, rng, rot_noise=0.2, trans_noise=0.3)
    p = Problem.from_graph(g)
    model = RelaxedProblem(p)
    r = dim + 1
    Z = random_point(g.n, dim, r, rng)
    s = model.evaluate(Z)
    V = project(Z, rng.standard_normal(Z.shape))
    V /= np.linalg.norm(V)
    h = 1e-5
    fp = model.evaluate(retract(Z, h * V)).f
    fm = model.evaluate(retract(Z, -h * V)).f
    # directional derivative
    assert (fp - fm) / (2 * h) == pytest.approx(np.sum(s.grad * V), rel=1e-6)
    # second derivative along the (second-order) polar retraction = <V, Hess V>
    HV = model.hvp(s, V)
    h2 = 1e-4
    fpp = model.evaluate(retract(Z, h2 * V)).f
    fmm = model.evaluate(retract(Z, -h2 * V)).f
    assert (fpp - 2 * s.f + fmm) / h2 ** 2 == pytest.approx(np.sum(V * HV), rel=1e-4)
    # Hessian as the derivative of the gradient field (projected back to T_Z)
    gp = model.evaluate(retract(Z, h * V)).grad
    gm = model.evaluate(retract(Z, -h * V)).grad
    fd = project(Z, (gp - gm) / (2 * h))
    np.testing.assert_allclose(fd, HV, rtol=0, atol=1e-5 * np.abs(HV).max())
    # symmetry of the Hessian
    W = project(Z, rng.standard_normal(Z.shape))
    assert np.sum(W * model.hvp(s, V)) == pytest.approx(np.sum(V * model.hvp(s, W)), rel=1e-9)


def test_retraction_and_projection():
    rng = np.random.default_rng(3)
    Z = random_point(7, 3, 5, rng)
    ZZt = Z @ np.swapaxes(Z, 1, 2)
    np.testing.assert_allclose(ZZt, np.broadcast_to(np.eye(3), ZZt.shape), atol=1e-12)
    V = project(Z, rng.standard_normal(Z.shape))
    sym = V @ np.swapaxes(Z, 1, 2)
    np.testing.assert_allclose(sym + np.swapaxes(sym, 1, 2), 0, atol=1e-12)
    Y = retract(Z, V)
    np.testing.assert_allclose(Y @ np.swapaxes(Y, 1, 2), np.broadcast_to(np.eye(3), ZZt.shape), atol=1e-12)
    H = remove_vertical(Z, V)
    for _ in range(3):
        A = rng.standard_normal((5, 5))
        assert abs(np.sum(H * (Z @ (A - A.T)))) < 1e-10


def test_translations_match_least_squares():
    rng = np.random.default_rng(5)
    g, _, _ = random_pose_graph(9, 3, rng, rot_noise=0.1, trans_noise=0.2)
    p = Problem.from_graph(g)
    Z = random_point(g.n, 3, 3, rng)   # blocks act as "rotations" R_i = Z_i^T
    T = p.translations(Z.reshape(-1, 3))
    # dense least squares with t_0 = 0: rows sqrt(tau)(t_j - t_i) = sqrt(tau) R_i t~
    n, d = g.n, 3
    A = np.zeros((g.m * d, (n - 1) * d))
    b = np.zeros(g.m * d)
    for e in range(g.m):
        i, j = g.src[e], g.dst[e]
        w = np.sqrt(g.tau[e])
        rows = slice(e * d, e * d + d)
        if j > 0:
            A[rows, (j - 1) * d:(j - 1) * d + d] += w * np.eye(d)
        if i > 0:
            A[rows, (i - 1) * d:(i - 1) * d + d] -= w * np.eye(d)
        b[rows] = w * Z[i].T @ g.trans[e]
    x = np.linalg.lstsq(A, b, rcond=None)[0].reshape(n - 1, d)
    np.testing.assert_allclose(T[1:], x, atol=1e-10)
    np.testing.assert_allclose(T[0], 0)


@pytest.mark.parametrize("d,r", [(2, 2), (2, 3), (3, 4), (3, 5)])
def test_block_kernels_match_per_block_products(d, r):
    """The component-major block operations against a plain loop of d x r matrix products."""
    from posecrb.solver.stiefel import hessian_blocks, sym_block_diag_product, to_components

    rng = np.random.default_rng(10 * d + r)
    n = 7
    Z = random_point(n, d, r, rng)
    W, V = rng.standard_normal((n, d, r)), rng.standard_normal((n, d, r))
    L = rng.standard_normal((n, d, d))
    lam = L + np.swapaxes(L, 1, 2)
    for i in range(n):
        S = 0.5 * (W[i] @ Z[i].T + Z[i] @ W[i].T)
        np.testing.assert_allclose(sym_block_diag_product(W, Z)[i], S, rtol=0, atol=1e-14 * r)
        np.testing.assert_allclose(project(Z, W)[i], W[i] - S @ Z[i], rtol=0, atol=1e-14 * r * d)
        np.testing.assert_allclose(project(Z, W, scale=0.5)[i], 0.5 * (W[i] - S @ Z[i]), rtol=0, atol=1e-14 * r * d)
        G = W[i] - lam[i] @ V[i]
        SG = 0.5 * (G @ Z[i].T + Z[i] @ G.T)
        want = 2.0 * (G - SG @ Z[i])
        got = hessian_blocks(to_components(Z), to_components(lam), V, W)[i]
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * r * d * max(1.0, np.abs(lam).max()))
