"""The spanning tree's bound of the paper FIM's inverse diagonal (posecrb.models.paper.tree_inverse).

References: the dense inverse of the FIM built by ``paper_fim`` from the tree's edges alone (the
closed form must equal its diagonal) and the dense inverse of the whole graph's FIM (the closed
form must bound its diagonal from above: the tree's FIM is below the graph's in the Loewner
order). Graphs in 2D and 3D, with information that varies by orders of magnitude from edge to
edge, several anchors, both rotation weights, and both FIM layouts.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from posecrb.core.graph import PoseGraph
from posecrb.linalg.accuracy import logdet_accuracy
from posecrb.linalg.cholesky import cholesky
from posecrb.models.paper.fim import fim_logdet_accuracy, fim_symbolic_choice, paper_fim
from posecrb.models.paper.tree_inverse import spanning_tree, tree_inverse_diagonal

from ..helpers import random_pose_graph
from ..numerics import EPS, MARGIN, spd_condition


def varied_graph(n: int, dim: int, seed: int, loop_closures: int) -> tuple[PoseGraph, np.ndarray, np.ndarray]:
    """A random pose graph whose edges' information spans four orders of magnitude."""
    rng = np.random.default_rng(seed)
    g, rot, trans = random_pose_graph(n, dim, rng, loop_closures=loop_closures, rot_noise=0.05, trans_noise=0.1)
    scale = 10.0 ** rng.uniform(-2.0, 2.0, size=(g.m, 2))
    info = g.info.copy()
    info[:, :dim, :dim] *= scale[:, 0, None, None]
    info[:, dim:, dim:] *= scale[:, 1, None, None]
    return dataclasses.replace(g, info=info), rot, trans


def tree_graph(g: PoseGraph, anchor: int) -> PoseGraph:
    """The graph of the tree's edges only."""
    parent, edge = spanning_tree(g, anchor)
    keep = edge[edge >= 0]
    return dataclasses.replace(g, src=g.src[keep], dst=g.dst[keep], rot=g.rot[keep], trans=g.trans[keep],
                               info=g.info[keep], edge_lines=None)


CASES = [(2, 40, 0, 3), (2, 60, 17, 11), (3, 30, 0, 5), (3, 45, 9, 12)]


@pytest.mark.parametrize(("dim", "n", "anchor", "seed"), CASES)
@pytest.mark.parametrize("rotation_weight", ["eq59", "table2"])
def test_closed_form_is_the_tree_fims_inverse_diagonal(dim, n, anchor, seed, rotation_weight):
    g, rot, trans = varied_graph(n, dim, seed, loop_closures=n // 2)
    tree = paper_fim(tree_graph(g, anchor), rot, trans, anchor, rotation_weight).matrix.toarray()
    reference = np.diag(np.linalg.inv(tree))
    got = tree_inverse_diagonal(g, rot, trans, anchor, rotation_weight)
    # each computed inverse entry is within c n kappa eps of its true value, relative to the largest
    # (Higham ch. 14); the closed form sums positive terms along paths of at most n edges
    tol = MARGIN * n * spd_condition(tree) * EPS * reference.max()
    np.testing.assert_allclose(got, reference, rtol=0, atol=tol)


@pytest.mark.parametrize(("dim", "n", "anchor", "seed"), CASES)
def test_closed_form_bounds_the_graph_fims_inverse_diagonal(dim, n, anchor, seed):
    g, rot, trans = varied_graph(n, dim, seed, loop_closures=n)
    full = paper_fim(g, rot, trans, anchor).matrix.toarray()
    exact = np.diag(np.linalg.inv(full))
    got = tree_inverse_diagonal(g, rot, trans, anchor)
    tol = MARGIN * n * spd_condition(full) * EPS * exact     # the dense reference's own error
    assert np.all(got >= exact - tol)
    assert np.any(got > 1.5 * exact)          # loops add information the tree does not have


def test_tree_avoids_weak_edges_and_keeps_the_strongest_parallel_edge():
    """A direct edge of tiny information loses to a two-edge path of strong ones, and of two
    parallel edges the one of larger tau is the tree's."""
    g, rot, trans = random_pose_graph(4, 2, np.random.default_rng(3), loop_closures=0)
    # edges 0-1, 1-2, 2-3 (odometry), then a weak 0-2 and a parallel 2-3 of more information
    src = np.array([0, 1, 2, 0, 2])
    dst = np.array([1, 2, 3, 2, 3])
    info = np.repeat(g.info[:1], 5, axis=0)
    info[3] *= 1e-6
    info[4] *= 4.0
    h = dataclasses.replace(g, src=src, dst=dst, rot=np.repeat(g.rot[:1], 5, axis=0),
                            trans=np.repeat(g.trans[:1], 5, axis=0), info=info, edge_lines=None)
    parent, edge = spanning_tree(h, 0)
    assert parent.tolist() == [-1, 0, 1, 2]
    assert edge.tolist() == [-1, 0, 1, 4]


@pytest.mark.parametrize("rounds", [None, 1])
@pytest.mark.parametrize(("dim", "n", "anchor", "seed"), CASES)
def test_tree_paths_are_shortest_in_the_edges_variances(dim, n, anchor, seed, rounds, monkeypatch):
    """Every tree path is as short as scipy's Dijkstra says the shortest path is, in the lengths
    1 / tau + 1 / w of the strongest of parallel edges: from the vectorised relaxation and, with
    its rounds capped at one, from the fallback on Dijkstra itself."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    from posecrb.models.paper import tree_inverse

    if rounds is not None:
        monkeypatch.setattr(tree_inverse, "_MAX_ROUNDS", rounds)
    g, _, _ = varied_graph(n, dim, seed, loop_closures=n)
    parent, edge = spanning_tree(g, anchor)
    child = np.flatnonzero(parent >= 0)
    assert child.size == n - 1 and parent[anchor] == -1
    ends = np.sort(np.stack([g.src[edge[child]], g.dst[edge[child]]], axis=1), axis=1)
    assert np.array_equal(ends, np.sort(np.stack([child, parent[child]], axis=1), axis=1))
    length = 1.0 / g.tau + 1.0 / g.rotation_weights
    terms = np.zeros((n, 1))
    terms[child, 0] = length[edge[child]]
    along_tree, _ = tree_inverse._path_sums(terms, parent, anchor)
    # the strongest parallel edge is the graph's only edge between its ends
    lo, hi = np.minimum(g.src, g.dst), np.maximum(g.src, g.dst)
    order = np.argsort(-g.tau, kind="stable")
    _, first = np.unique(lo[order] * n + hi[order], return_index=True)
    kept = order[first]
    shortest = dijkstra(sp.csr_matrix((length[kept], (lo[kept], hi[kept])), shape=(n, n)), directed=False,
                        indices=anchor)
    np.testing.assert_allclose(along_tree[:, 0], shortest, rtol=MARGIN * n * EPS, atol=0)


def test_layouts_map_to_their_rows(monkeypatch):
    """fim_logdet_accuracy permutes the bound to the FIM's layout: the spanning_tree tier's bound
    equals the dense closed form || |L|^T sqrt(z) ||^2 in either layout and bounds the exact sum."""
    from posecrb.linalg import accuracy

    monkeypatch.setattr(accuracy, "EXACT_FIRST_STEPS", -1)    # the tree's tier even on a small factor
    monkeypatch.setattr(accuracy, "TREE_FIRST_FLOPS", 0.0)
    g, rot, trans = varied_graph(50, 3, 4, loop_closures=25)
    for layout in ("blocks", "poses"):
        fim = paper_fim(g, rot, trans, 0, layout=layout)
        z = tree_inverse_diagonal(g, rot, trans, 0)
        if layout == "poses":
            z = np.concatenate([z[:fim.n_free * 3].reshape(-1, 3), z[fim.n_free * 3:].reshape(-1, 3)], axis=1).ravel()
        dense = fim.matrix.toarray()
        assert np.all(z >= np.diag(np.linalg.inv(dense)) * (1 - MARGIN * spd_condition(dense) * EPS))
        factor = cholesky(fim.matrix)
        lower = factor.L().toarray()
        weight = np.abs(lower) @ np.abs(lower).T
        root = np.sqrt(z[factor.P()])
        closed = float(root @ weight @ root)
        got = logdet_accuracy(factor, factor.logdet(), matrix=fim.matrix, tier="spanning_tree", inverse_diagonal=z)
        assert got.tier == "spanning_tree" and got.condition_kind == "upper bound"
        assert got.condition == pytest.approx(closed, rel=MARGIN * dense.shape[0] * EPS)
        exact = logdet_accuracy(factor, factor.logdet(), tier="selected_inversion")
        assert exact.condition <= got.condition
        sym, _ = fim_symbolic_choice(fim)
        f2, ld = sym.factor_logdet(fim.matrix)
        lower2 = np.abs(f2.L().toarray())
        root2 = np.sqrt(z[f2.P()])
        through_model = fim_logdet_accuracy(fim, f2, ld, g, rot, trans)
        assert through_model.tier == "spanning_tree" and through_model.status.ok
        assert through_model.condition == pytest.approx(float(root2 @ (lower2 @ lower2.T) @ root2),
                                                        rel=MARGIN * dense.shape[0] * EPS)


def test_no_closed_form_for_eq64_in_3d_or_a_disconnected_graph():
    g, rot, trans = varied_graph(20, 3, 1, loop_closures=5)
    assert tree_inverse_diagonal(g, rot, trans, 0, variant="eq64") is None
    g2, rot2, trans2 = varied_graph(20, 2, 1, loop_closures=0)
    cut = dataclasses.replace(g2, src=np.delete(g2.src, 9), dst=np.delete(g2.dst, 9), rot=np.delete(g2.rot, 9, 0),
                              trans=np.delete(g2.trans, 9, 0), info=np.delete(g2.info, 9, 0), edge_lines=None)
    assert spanning_tree(cut, 0) is None
    assert tree_inverse_diagonal(cut, rot2, trans2, 0) is None


def test_an_edge_without_information_gives_no_bound():
    """A tree edge whose information underflows has infinite variance: the tier cannot prove
    anything and says so when forced, as it does when the caller has no bound at all."""
    g, rot, trans = random_pose_graph(6, 2, np.random.default_rng(2), loop_closures=0)
    info = g.info.copy()
    info[2] *= 1e-310
    z = tree_inverse_diagonal(dataclasses.replace(g, info=info), rot, trans, 0)
    assert np.isinf(z).any() and not np.isnan(z).any()
    fim = paper_fim(g, rot, trans, 0)
    factor = cholesky(fim.matrix)
    for bound in (z, lambda: None):
        got = logdet_accuracy(factor, factor.logdet(), tier="spanning_tree", inverse_diagonal=bound)
        assert got.status.state == "unavailable" and "spanning_tree tier" in got.status.reason
        assert got.error_bound == np.inf
