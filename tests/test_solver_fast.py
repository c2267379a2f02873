"""The solver's speed-motivated code paths against independent references.

CHOLMOD's factorization kind (simplicial/supernodal, chosen by the pose-level fill) must not
change what a factor solves; the references are dense numpy matrices built from their
definitions (tests/test_sesync_geometry.py) and closed forms.
"""
from __future__ import annotations

import numpy as np
import pytest

import posecrb.solver.problem as problem_module
from posecrb.solver.chordal import chordal_rotations
from posecrb.solver.problem import Problem

from .helpers import random_pose_graph
from .numerics import EPS, MARGIN
from .test_sesync_geometry import dense_Q


def test_pose_fill_of_a_chain_is_its_closed_form():
    """A path graph's reduced Laplacian is tridiagonal; minimum degree eliminates an end pose each
    time (no fill), so the LDL' columns hold 2 entries except the last (1):
    sum c^2 / sum c = (4 (k - 1) + 1) / (2 (k - 1) + 1) for k = n - 1 rows."""
    n = 30
    g, _, _ = random_pose_graph(n, 2, np.random.default_rng(0), loop_closures=0)
    k = n - 1
    assert Problem.from_graph(g).pose_fill() == pytest.approx((4 * (k - 1) + 1) / (2 * (k - 1) + 1), rel=1e-15)


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
