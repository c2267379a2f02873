"""g2o's chi-square and the Mahalanobis distance against per-edge / dense references."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posecrb.models.paper.crlb import crlb_blocks
from posecrb.models.paper.fim import paper_fim
from posecrb.sim.random_graphs import random_graph
from posecrb.verification.distance import paper_delta, pose_mahalanobis, squared_mahalanobis
from posecrb.verification.g2o_cost import g2o_chi2

from ..numerics import EPS


def _graph(dim: int, seed: int = 3, n: int = 10):
    return random_graph(np.random.default_rng(seed), n, n + 8, dim, id_gaps=True, scale=4.0)


def _perturbed(g, rng, size=0.2):
    rot = g.vertex_rot.copy()
    if g.dim == 2:
        a = size * rng.standard_normal(g.n)
        c, s = np.cos(a), np.sin(a)
        rot = rot @ np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    else:
        rot = rot @ Rotation.from_rotvec(size * rng.standard_normal((g.n, 3))).as_matrix()
    return rot, g.vertex_trans + size * rng.standard_normal(g.vertex_trans.shape)


def _g2o_reference(g, rot, trans) -> float:
    """chi2 edge by edge, as g2o's EdgeSE2 / EdgeSE3 compute it, with 4x4 homogeneous matrices."""
    d = g.dim
    total = 0.0
    for k in range(g.m):
        def h(r, t):
            m = np.eye(d + 1)
            m[:d, :d], m[:d, d] = r, t
            return m
        xi, xj = h(rot[g.src[k]], trans[g.src[k]]), h(rot[g.dst[k]], trans[g.dst[k]])
        delta = np.linalg.inv(h(g.rot[k], g.trans[k])) @ np.linalg.inv(xi) @ xj
        if d == 2:
            e = np.array([delta[0, 2], delta[1, 2], np.arctan2(delta[1, 0], delta[0, 0])])
        else:
            q = Rotation.from_matrix(delta[:3, :3]).as_quat()     # (x, y, z, w)
            q = -q if q[3] < 0 else q
            e = np.concatenate([delta[:3, 3], q[:3]])
        total += e @ g.info[k] @ e
    return total


@pytest.mark.parametrize("dim", [2, 3])
def test_g2o_chi2_matches_the_edge_by_edge_definition(dim):
    g = _graph(dim)
    rot, trans = _perturbed(g, np.random.default_rng(1))
    ref = _g2o_reference(g, rot, trans)
    # a sum of m positive terms, each a few products of O(1) quantities: rounding ~ m q^2 eps relative
    assert g2o_chi2(g, rot, trans) == pytest.approx(ref, rel=100 * g.m * g.q ** 2 * EPS)
    assert g2o_chi2(g, g.vertex_rot, g.vertex_trans) == pytest.approx(_g2o_reference(g, g.vertex_rot, g.vertex_trans),
                                                                      rel=100 * g.m * g.q ** 2 * EPS, abs=1e-20)


@pytest.mark.parametrize("dim", [2, 3])
def test_delta_and_mahalanobis_against_dense_references(dim):
    g = _graph(dim, seed=5)
    rng = np.random.default_rng(2)
    opt_rot, opt_trans = g.vertex_rot, g.vertex_trans
    rot, trans = _perturbed(g, rng, 0.05)
    anchor = 3
    delta = paper_delta(rot, trans, opt_rot, opt_trans, anchor)
    # reference: gauge by 4x4 matrices, rotation difference by scipy's log map
    d = g.dim
    def h(r, t):
        m = np.eye(d + 1)
        m[:d, :d], m[:d, d] = r, t
        return m
    a_est = np.linalg.inv(h(rot[anchor], trans[anchor]))
    a_opt = np.linalg.inv(h(opt_rot[anchor], opt_trans[anchor]))
    ref = np.zeros((g.n, g.q))
    for i in range(g.n):
        e, o = a_est @ h(rot[i], trans[i]), a_opt @ h(opt_rot[i], opt_trans[i])
        ref[i, :d] = e[:d, d] - o[:d, d]
        rel = o[:d, :d].T @ e[:d, :d]
        if d == 2:
            ref[i, 2] = np.arctan2(rel[1, 0], rel[0, 0])
        else:
            ref[i, 3:] = np.sqrt(2.0) * Rotation.from_matrix(rel).as_rotvec()
    np.testing.assert_allclose(delta, ref, atol=1e-12)
    assert np.all(delta[anchor] == 0)
    fim = paper_fim(g, opt_rot, opt_trans, anchor=anchor)
    dense = fim.matrix.toarray()
    free = [i for i in range(g.n) if i != anchor]
    # the blocks layout: all free translations, then all free rotations
    v = np.concatenate([ref[free, :d].ravel(), ref[free, d:].ravel()])
    expected = v @ dense @ v
    cond = np.linalg.cond(dense)
    assert squared_mahalanobis(fim, g, delta) == pytest.approx(expected, rel=100 * cond * EPS)
    blocks, accuracy, _ = crlb_blocks(fim, g)
    assert accuracy is not None and accuracy.status.ok
    ids = fim.pose_ids
    values = pose_mahalanobis(ids, blocks, g, delta)
    assert ids.size == g.n - 1 and int(g.ids[anchor]) not in ids
    inv = np.linalg.inv(dense)
    for pid, val in zip(ids, values):
        i = int(np.searchsorted(g.ids, pid))
        k = free.index(i)
        rows = np.concatenate([k * d + np.arange(d), len(free) * d + k * g.rot_dim + np.arange(g.rot_dim)])
        block = inv[np.ix_(rows, rows)]
        assert val == pytest.approx(ref[i] @ np.linalg.solve(block, ref[i]), rel=100 * cond * EPS)
