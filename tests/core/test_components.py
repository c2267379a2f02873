"""Connected components by numpy (posecrb.core.graph.connected_components) against scipy's
``scipy.sparse.csgraph.connected_components`` on random graphs: sparse and dense, disconnected,
with isolated vertices, self-loops and parallel edges, and adversarial vertex orders."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components as scipy_components

from posecrb.core.graph import PoseGraph, connected_components

from ..helpers import make_random_graph


def _reference(n: int, src: np.ndarray, dst: np.ndarray) -> tuple[int, np.ndarray]:
    adj = sp.coo_matrix((np.ones(src.size), (src, dst)), shape=(n, n)).tocsr()
    return scipy_components(adj, directed=False)


def _check(n: int, src: np.ndarray, dst: np.ndarray) -> None:
    count, labels = connected_components(n, src, dst)
    want_count, want_labels = _reference(n, src, dst)
    assert count == want_count
    # Same numbering, not just the same partition: both number components by their smallest vertex.
    np.testing.assert_array_equal(labels, want_labels)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize(("n", "ratio"), [(1, 0.0), (2, 0.5), (10, 0.3), (50, 0.5), (300, 0.8), (300, 1.5),
                                          (2000, 0.45), (2000, 3.0)])
def test_random_graphs_match_scipy(seed, n, ratio):
    rng = np.random.default_rng(1000 * seed + n)
    m = int(ratio * n)
    src, dst = rng.integers(0, n, m), rng.integers(0, n, m)   # self-loops, parallel edges, isolated vertices
    _check(n, src, dst)


@pytest.mark.parametrize("seed", range(5))
def test_paths_and_stars_in_every_vertex_order(seed):
    """Long paths in random order take the most hooking rounds; stars hooked from leaves and centre."""
    rng = np.random.default_rng(seed)
    n = 3000
    perm = rng.permutation(n)
    _check(n, perm[:-1], perm[1:])                          # one path through all vertices, shuffled ids
    _check(n, perm[1:], perm[:-1])                          # the same, edges reversed
    _check(n, np.arange(n - 1)[::-1], np.arange(1, n)[::-1])  # a path listed from the end
    _check(n, np.full(n - 1, perm[0]), perm[1:])            # a star whose centre is a random vertex
    half = n // 2                                           # two shuffled paths and an isolated vertex
    _check(n + 1, np.r_[perm[: half - 1], perm[half:-1]], np.r_[perm[1:half], perm[half + 1:]])


def test_no_vertices_and_no_edges():
    count, labels = connected_components(0, np.zeros(0, int), np.zeros(0, int))
    assert count == 0 and labels.shape == (0,)
    count, labels = connected_components(4, np.zeros(0, int), np.zeros(0, int))
    assert count == 4
    np.testing.assert_array_equal(labels, np.arange(4))


def test_pose_graph_components_and_summaries():
    rng = np.random.default_rng(3)
    a = make_random_graph(rng, n=9, extra=4)
    b = make_random_graph(rng, n=5, extra=2)
    # Two graphs side by side, interleaved internal indices, plus two isolated poses.
    n = a.n + b.n + 2
    order = rng.permutation(n)
    ia, ib = order[: a.n], order[a.n: a.n + b.n]
    src = np.r_[ia[a.src], ib[b.src]]
    dst = np.r_[ia[a.dst], ib[b.dst]]
    m = src.size
    g = PoseGraph(dim=2, ids=np.arange(n) * 3, src=src, dst=dst, rot=np.tile(np.eye(2), (m, 1, 1)),
                  trans=np.zeros((m, 2)), info=np.tile(np.eye(3), (m, 1, 1)))
    want_count, want_labels = _reference(n, src, dst)
    assert g.n_components == want_count == 4
    np.testing.assert_array_equal(g.component_labels, want_labels)
    assert [c.size for c in g.component_summaries()] == [9, 5, 1, 1]
