"""The swap search that polishes fiedler-relax's rounded set (``polish_fiedler``), against brute force.

References are independent of the code under test: ``lambda_2`` from numpy's dense ``eigvalsh`` of
a Laplacian written out edge by edge (tests/selection/references.py ``dense_value``), and the best K-subset
by enumerating every one (<= 12 candidates). Tolerances: a dense symmetric eigenvalue is exact to
a few ``eps * ||L||``; both sides of every comparison carry such an error, so comparisons allow
``1e-10 * lambda_max(L)`` (a margin of ~1e5 over ``eps``).
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from posecrb.selection import (
    FiedlerObjective,
    polish_fiedler,
    select_edges,
    split_edges,
)

from .references import chain_graph, dense_value, precisions, rot_weight


def dense_lambda(g, kept) -> tuple[float, float]:
    """(lambda_2, lambda_max) of the rotation-weighted Laplacian of the edges ``kept``, dense."""
    w = rot_weight(precisions(g.info, g.dim)[1], g.dim)
    lap = np.zeros((g.n, g.n))
    for e in np.asarray(kept, dtype=int):
        i, j = g.src[e], g.dst[e]
        lap[i, i] += w[e]
        lap[j, j] += w[e]
        lap[i, j] -= w[e]
        lap[j, i] -= w[e]
    ev = np.linalg.eigvalsh(lap)
    return float(ev[1]), float(ev[-1])


def tol(g) -> float:
    """1e-10 lambda_max of the full graph's Laplacian (bounds every subset's)."""
    return 1e-10 * dense_lambda(g, np.arange(g.m))[1]


def setup(seed: int, dim: int, n: int = 8, extra: int = 11):
    rng = np.random.default_rng(seed)
    g = chain_graph(rng, n=n, extra=extra, dim=dim)
    split = split_edges(g)
    obj = FiedlerObjective(g, rot_weight(precisions(g.info, dim)[1], dim))
    base = np.zeros(g.m)
    base[split.fixed] = 1.0
    return rng, g, split, obj, base


def best_subset(g, fixed, cand, k) -> float:
    return max(dense_lambda(g, np.r_[fixed, s])[0] for s in itertools.combinations(cand.tolist(), k))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(4))
def test_polish_never_lowers_lambda2_and_keeps_budget_and_fixed_edges(dim, seed):
    """From random K-subsets: K distinct candidates come back, the fixed edges are untouched, the
    dense lambda_2 of the result is >= that of the start, and the search's own value is the
    dense lambda_2 of what it returns."""
    rng, g, split, obj, base = setup(seed, dim)
    cand = split.candidates
    t = tol(g)
    for k in (1, 2, 4, 6, cand.size - 1):
        for _ in range(3):
            pick = rng.choice(cand.size, k, replace=False)
            base_before = base.copy()
            pos, state, stats = polish_fiedler(obj, base, cand, pick, max_solves=40, width=4)
            assert np.array_equal(base, base_before)                  # the caller's weights untouched
            assert pos.size == k and np.unique(pos).size == k
            assert pos.min() >= 0 and pos.max() < cand.size
            before = dense_lambda(g, np.r_[split.fixed, cand[pick]])[0]
            after = dense_lambda(g, np.r_[split.fixed, cand[pos]])[0]
            assert after >= before - t
            assert state.value == pytest.approx(after, abs=t)
            assert stats.value_before == pytest.approx(before, abs=t)
            assert stats.solves <= 40
            assert stats.swaps >= stats.moves
            assert np.array_equal(state.x[split.fixed], np.ones(split.fixed.size))
            assert np.count_nonzero(state.x[cand]) == k


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_supergradient_bound_that_ranks_and_prunes_swaps_holds_for_every_subset(dim, seed):
    """What the search relies on (its pruning, its "no-ascent" stop, the bound at the returned set):
    for the computed unit Fiedler vector v of a set S and g_e = w_e (v_i - v_j)^2, every K-subset
    S' has lambda_2(S') <= R(v) + g(S' minus S) - g(S minus S'), checked against dense eigvalsh for
    all of them; and R(v) + (the K largest g) - g(S) bounds the best K-subset."""
    rng, g, split, obj, base = setup(10 + seed, dim, extra=10)
    cand = split.candidates
    t = tol(g)
    for k in (1, 3, 5):
        pick = rng.choice(cand.size, k, replace=False)
        x = base.copy()
        x[cand[pick]] = 1.0
        state = obj.evaluate(x)
        gr = obj.gradient(state, cand)
        inside = np.zeros(cand.size, dtype=bool)
        inside[pick] = True
        best = -np.inf
        for s in itertools.combinations(range(cand.size), k):
            other = np.zeros(cand.size, dtype=bool)
            other[list(s)] = True
            lam = dense_lambda(g, np.r_[split.fixed, cand[other]])[0]
            assert lam <= state.value + gr[other & ~inside].sum() - gr[inside & ~other].sum() + t
            best = max(best, lam)
        assert best <= state.value + np.sort(gr)[::-1][:k].sum() - gr[inside].sum() + t


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", range(3))
def test_polished_relaxation_against_exhaustive_search(dim, seed):
    """select_edges(fiedler, relax): the polished answer is at least the rounded one (polish=0), at
    most the best K-subset, its value the dense lambda_2 of its edges, and its upper bound (now
    also the bound at the returned set) still >= the best K-subset."""
    rng, g, split, obj, base = setup(20 + seed, dim, n=8, extra=12)
    cand = split.candidates
    assert cand.size == 12
    t = tol(g)
    reached = 0
    for k in (1, 2, 3, 4, 6):
        opt = best_subset(g, split.fixed, cand, k)
        rounded = select_edges(g, k, objective="fiedler", method="relax", polish=0, max_iter=20)
        polished = select_edges(g, k, objective="fiedler", method="relax", max_iter=20)
        for res in (rounded, polished):
            kept = np.r_[split.fixed, res.selected_edges]
            assert res.selected_edges.size == k and np.isin(res.selected_edges, cand).all()
            assert np.array_equal(res.kept_edges, np.union1d(split.fixed, res.selected_edges))
            assert res.value == pytest.approx(dense_value("fiedler", g, kept), abs=t)
            assert res.value <= opt + t
            assert res.upper_bound >= opt - t
            assert 0.0 <= res.certified_ratio <= 1.0
            assert res.stats["bound_at_selection"] >= opt - t
        assert polished.value >= rounded.value - t
        reached += polished.value >= opt - t
    # a local search from the rounded set: on graphs this small it finds the optimum at least once
    assert reached >= 1


def test_polish_is_deterministic_and_zero_solves_is_the_identity():
    _, g, split, obj, base = setup(3, 2)
    cand = split.candidates
    pick = np.array([0, 3, 5])
    a = polish_fiedler(obj, base, cand, pick, max_solves=30)
    b = polish_fiedler(obj, base, cand, pick, max_solves=30)
    assert np.array_equal(a[0], b[0]) and a[1].value == b[1].value
    pos, state, stats = polish_fiedler(obj, base, cand, pick, max_solves=0)
    assert np.array_equal(pos, np.sort(pick)) and stats.solves == 0 and stats.moves == 0


def test_polish_on_the_sparse_eigensolver_path():
    """Above the dense size the eigensolves are shift-invert Lanczos warm-started at the previous
    Fiedler vector: the result must still be what dense eigvalsh says it is, and no worse than
    the start."""
    rng = np.random.default_rng(5)
    g = chain_graph(rng, n=360, extra=200, dim=2)
    split = split_edges(g)
    obj = FiedlerObjective(g, rot_weight(precisions(g.info, 2)[1], 2))
    assert obj._block is not None
    base = np.zeros(g.m)
    base[split.fixed] = 1.0
    cand = split.candidates
    pick = rng.choice(cand.size, 20, replace=False)
    pos, state, stats = polish_fiedler(obj, base, cand, pick, max_solves=15)
    t = tol(g)
    before = dense_lambda(g, np.r_[split.fixed, cand[pick]])[0]
    after = dense_lambda(g, np.r_[split.fixed, cand[pos]])[0]
    assert after >= before - t
    assert state.value == pytest.approx(after, abs=t)
    assert stats.moves >= 1          # premise: from a random set some exchange helps
