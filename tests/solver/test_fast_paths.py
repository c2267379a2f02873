"""The solver's speed-motivated code paths against independent references.

CHOLMOD's factorization kind (simplicial/supernodal, chosen by the pose-level fill) must not
change what a factor solves; the references are dense numpy matrices built from their
definitions (tests/solver/references.py) and closed forms.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import posecrb.solver.problem as problem_module
from posecrb.solver.chordal import chordal_rotations
from posecrb.solver.problem import Problem
from posecrb.solver.stiefel import random_point

from ..helpers import random_pose_graph
from ..numerics import EPS, MARGIN
from .references import dense_Q


def test_pose_fill_of_a_chain_is_its_closed_form():
    """A path graph's reduced Laplacian is tridiagonal; minimum degree eliminates an end pose each
    time (no fill), so the LDL' columns hold 2 entries except the last (1):
    sum c^2 / sum c = (4 (k - 1) + 1) / (2 (k - 1) + 1) for k = n - 1 rows."""
    n = 30
    g, _, _ = random_pose_graph(n, 2, np.random.default_rng(0), loop_closures=0)
    k = n - 1
    assert Problem.from_graph(g).pose_fill() == pytest.approx((4 * (k - 1) + 1) / (2 * (k - 1) + 1), rel=1e-15)



def test_translation_laplacian_refactored_simplicial_between_the_switches():
    """A 3D lattice of 512 poses has fill ~49: CHOLMOD factors L(W^tau) supernodal (its switch is
    40), and reading the fill pads that factor. The solver keeps a simplicial factor of L(W^tau)
    with exactly the entries of CHOLMOD's own simplicial factorization, and its translations equal
    the dense solve of L p = -V Z."""
    from posecrb.linalg.cholesky import SymbolicCholesky
    from posecrb.sim.generators import grid

    g = grid(3, 8, noise=True, rng=np.random.default_rng(3))
    p = Problem.from_graph(g)
    assert problem_module.CHOLMOD_SUPERNODAL_SWITCH <= p.pose_fill() < problem_module.SIMPLICIAL_MAX_FLOPS_PER_ENTRY
    fresh = SymbolicCholesky(p.Lred, mode="simplicial").factor(p.Lred)
    assert p.Lfactor.LD().nnz == fresh.LD().nnz
    Z = random_point(g.n, 3, 4, np.random.default_rng(4)).reshape(g.n * 3, 4)
    L = p.Lred.toarray()
    want = np.linalg.solve(L, -(p.Vred @ Z))
    cond = np.linalg.cond(L)
    np.testing.assert_allclose(p.translations(Z)[1:], want, rtol=0, atol=MARGIN * cond * EPS * np.abs(want).max())

@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("threshold", [0.0, np.inf], ids=["supernodal", "simplicial"])
def test_factor_mode_solves_match_dense(dim, threshold, monkeypatch):
    """(Q + s I)^{-1} W through either factorization kind equals the dense solve; the chordal
    rotations equal the dense least-squares ones."""
    monkeypatch.setattr(problem_module, "SIMPLICIAL_MAX_FLOPS_PER_ENTRY", threshold)
    rng = np.random.default_rng(40 + dim)
    g, _, _ = random_pose_graph(25, dim, rng, loop_closures=30, rot_noise=0.2, trans_noise=0.3)
    p = Problem.from_graph(g)
    assert p.factor_mode(dim + 1) == ("simplicial" if threshold == np.inf else "supernodal")
    Q = dense_Q(g)
    s = 1e-2 * np.abs(Q).max()
    A = Q + s * np.eye(Q.shape[0])
    W = rng.standard_normal((Q.shape[0], dim + 1))
    want = np.linalg.solve(A, W)
    got = p.schur_solve(p.factor_full(None, s, name="test"), W)
    cond = np.linalg.cond(A)
    np.testing.assert_allclose(got, want, rtol=0, atol=MARGIN * cond * EPS * np.abs(want).max())
    # Chordal relaxation: minimise tr(Z^T L Z) with Z_0 = I, dense.
    n, d = g.n, dim
    L = p.conlap.toarray()
    Lrr, Lra = L[d:, d:], L[d:, :d]
    Z = np.vstack([np.eye(d), -np.linalg.solve(Lrr, Lra)]).reshape(n, d, d)
    U, _, Vt = np.linalg.svd(Z)
    D = np.ones((n, d))
    D[:, -1] = np.sign(np.linalg.det(U @ Vt))
    R = np.swapaxes((U * D[:, None, :]) @ Vt, 1, 2)
    np.testing.assert_allclose(chordal_rotations(p), R, rtol=0, atol=MARGIN * np.linalg.cond(Lrr) * EPS)


def svd_nearest_rotation(m: np.ndarray) -> np.ndarray:
    """Nearest rotation to one d x d matrix: U diag(1, .., det(U V^T)) V^T (Umeyama), block by block."""
    u, _, vt = np.linalg.svd(m)
    D = np.eye(m.shape[0])
    D[-1, -1] = np.sign(np.linalg.det(u @ vt))
    return u @ D @ vt


@pytest.mark.parametrize("dim", [2, 3])
def test_nearest_rotations_match_svd_per_block(dim):
    """Near-rotations, noisy and reflected blocks at scales 1e-3..1e3, plus nearly singular ones
    (the SVD fall-back). Tolerance: O(d^2 eps) backward error of either computation times the
    nearest rotation's condition number sigma_1 / (sigma_{d-1} + sigma_d), with sigma_{d-1} - sigma_d
    when det M < 0 (Umeyama's sign flip); reflected blocks get distinct singular values so it is finite."""
    from posecrb.sim.generators import uniform_rotations
    from posecrb.solver.stiefel import nearest_rotations

    rng = np.random.default_rng(7 + dim)
    k = 400
    R = uniform_rotations(k, dim, rng)
    noise = np.repeat([1e-6, 0.1, 0.5, 3.0], k // 4)[:, None, None]
    M = (R + noise * rng.standard_normal(R.shape)) * 10.0 ** rng.uniform(-3, 3, (k, 1, 1))
    spread = np.diag([3.0, 2.0, 1.0][:dim - 1] + [-0.5])                # det < 0, distinct singular values
    M[:5] = R[:5] @ spread @ uniform_rotations(5, dim, rng)
    M[5:10, :, -1] = 1e-12 * M[5:10, :, 0]                        # nearly singular
    got = nearest_rotations(M)
    for i in range(k):
        s = np.linalg.svd(M[i], compute_uv=False)
        gap = s[-2] - s[-1] if np.linalg.det(M[i]) < 0 else s[-2] + s[-1]
        tol = MARGIN * dim * dim * EPS * s[0] / gap
        np.testing.assert_allclose(got[i], svd_nearest_rotation(M[i]), rtol=0, atol=tol)
    np.testing.assert_allclose(got @ np.swapaxes(got, 1, 2), np.broadcast_to(np.eye(dim), got.shape),
                               rtol=0, atol=MARGIN * dim * EPS)
    assert np.all(np.linalg.det(got) > 0)


@pytest.mark.parametrize("d,r", [(2, 2), (2, 3), (2, 4), (3, 3), (3, 4), (3, 5)])
def test_retraction_matches_eigh(d, r):
    """The polar retraction (closed form in 2D, Newton's iteration in 3D) against (A A^T)^{-1/2} A
    from numpy's eigh, block by block, for tangent steps from tiny to large
    (A A^T = I + W W^T: condition <= 1 + |W|^2)."""
    from posecrb.solver.stiefel import project, retract

    rng = np.random.default_rng(10 * d + r)
    n = 300
    Z = random_point(n, d, r, rng)
    W = project(Z, rng.standard_normal((n, d, r))) * 10.0 ** rng.uniform(-8, 2, (n, 1, 1))
    got = retract(Z, W)
    for i in range(n):
        A = Z[i] + W[i]
        s, U = np.linalg.eigh(A @ A.T)
        want = U @ np.diag(s ** -0.5) @ U.T @ A
        cond = s[-1] / s[0]
        np.testing.assert_allclose(got[i], want, rtol=0, atol=MARGIN * d * r * cond * EPS)
    np.testing.assert_allclose(got @ np.swapaxes(got, 1, 2), np.broadcast_to(np.eye(d), (n, d, d)),
                               rtol=0, atol=MARGIN * d * r * EPS)


@pytest.mark.parametrize("dim", [2, 3])
def test_defect_constant_is_the_defect_term_on_the_manifold(dim):
    """With non-orthogonal R~ (SE-Sync's unnormalised quaternions), the per-edge defect sum
    kappa tr(Z_i^T (I - R~ R~^T) Z_i) at random points of St(d, r)^n equals the constant."""
    rng = np.random.default_rng(60 + dim)
    g, _, _ = random_pose_graph(30, dim, rng, loop_closures=20, rot_noise=0.1)
    g = dataclasses.replace(g, rot=g.rot * (1.0 + 1e-3 * rng.standard_normal((g.m, 1, 1))))   # not orthogonal
    p = Problem.from_graph(g)
    assert p.defect_edges.size == g.m
    terms = p.kappa * np.abs(np.trace(p.defect, axis1=1, axis2=2))
    for r in (dim, dim + 2):
        Z = random_point(g.n, dim, r, rng)
        direct = p.defect_term(Z[p.src[p.defect_edges]])
        # each edge's trace to O(d r eps) relative to kappa |E| r (|Z_i| entries <= 1)
        atol = MARGIN * dim * r * EPS * float(np.sum(p.kappa * np.abs(p.defect).sum(axis=(1, 2))))
        assert p.defect_constant() == pytest.approx(direct, rel=0, abs=atol)
        assert abs(p.defect_constant()) > 100 * atol and terms.sum() > 0
