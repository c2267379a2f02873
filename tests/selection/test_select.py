"""Measurement selection (posecrb.selection.select) against independent dense references and brute force.

References: dense Laplacians and Fisher information matrices assembled here edge by edge (the
FIM's per-edge Jacobians written out from the residuals and checked against the finite-difference
Fisher information of tests/models/test_fim.py), log-dets by numpy's Cholesky, lambda_2 by numpy's
eigvalsh, exhaustive search over every K-subset, and scipy's SLSQP for the relaxation's optimum.
"""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from posecrb.core.errors import DisconnectedGraph, ParseError, UsageError
from posecrb.selection import (
    DisconnectedFixedSet,
    fim_objective,
    frank_wolfe,
    madow,
    parse_budget,
    pruned_graph,
    select_edges,
    split_edges,
    tree_objective,
)
from posecrb.selection.relaxation import project_capped_simplex, projected_gradient
from posecrb.sim.generators import grid
from posecrb.solver.estimate import from_vertices

from ..helpers import dense_model_fisher, random_rotations
from .references import (
    Exhaustive,
    chain_graph,
    chol_logdet,
    dense_fim_terms,
    dense_laplacian_terms,
    dense_value,
    precisions,
    rot_weight,
)


# ----------------------------------------------------------------------------- the references themselves
@pytest.mark.parametrize("dim", [2, 3])
def test_dense_fim_reference_is_the_finite_difference_fisher_information(dim):
    g = chain_graph(np.random.default_rng(5), n=5, extra=3, dim=dim)
    ours = dense_fim_terms(g, g.vertex_rot, g.vertex_trans).sum(0)
    fd = dense_model_fisher(g, g.vertex_rot, g.vertex_trans, 0)
    assert np.allclose(ours, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_objectives_match_dense_values_on_random_subsets(dim):
    rng = np.random.default_rng(11 + dim)
    g = chain_graph(rng, n=8, extra=9, dim=dim)
    ref = from_vertices(g)
    tree, fim = tree_objective(g), fim_objective(g, ref.rot, ref.trans)
    for _ in range(4):
        x = (rng.random(g.m) < 0.5).astype(float)
        x[:g.n - 1] = 1.0
        kept = np.flatnonzero(x)
        assert tree.value(x) == pytest.approx(dense_value("tree", g, kept), rel=1e-11)
        assert fim.value(x) == pytest.approx(dense_value("fim", g, kept), rel=1e-10)


def test_fiedler_value_by_lanczos_on_a_large_graph_matches_eigvalsh():
    from posecrb.selection import FiedlerObjective

    rng = np.random.default_rng(6)
    g = chain_graph(rng, n=420, extra=300, dim=2)
    obj = FiedlerObjective(g, rot_weight(precisions(g.info, 2)[1], 2))
    assert obj._block is not None            # the sparse path: Lanczos on the pseudo-inverse
    x = (rng.random(g.m) < 0.6).astype(float)
    x[:g.n - 1] = 1.0
    ref = dense_value("fiedler", g, np.flatnonzero(x))
    st = obj.evaluate(x)
    assert st.value == pytest.approx(ref, rel=1e-9)
    assert st.value >= ref * (1 - 1e-12)     # a Rayleigh quotient never undershoots lambda_2


def test_fiedler_value_raises_when_lanczos_does_not_converge(monkeypatch):
    """An unconverged eigensolve is an error naming its residual, never a value."""
    import posecrb.selection.objectives as objectives
    from posecrb.core.errors import NumericalError

    g = chain_graph(np.random.default_rng(6), n=420, extra=300, dim=2)
    obj = objectives.FiedlerObjective(g, rot_weight(precisions(g.info, 2)[1], 2))
    monkeypatch.setattr(objectives, "_EIG_TOL", 1e-300)
    monkeypatch.setattr(objectives, "_EIG_RESTARTS", 2)
    with pytest.raises(NumericalError, match="did not converge"):
        obj.evaluate(np.ones(g.m))


def test_tree_objective_merges_proportional_weights_exactly():
    g = chain_graph(np.random.default_rng(2), dim=3, uniform=True)
    obj = tree_objective(g)
    assert len(obj.blocks) == 1
    x = np.ones(g.m)
    assert obj.value(x) == pytest.approx(dense_value("tree", g, np.arange(g.m)), rel=1e-12)


def test_tree_value_equals_bounds_lb_on_the_pruned_graph():
    from posecrb.models.paper.bounds import compute_bounds

    g = chain_graph(np.random.default_rng(4), n=9, extra=10, dim=3)
    res = select_edges(g, 4)
    assert res.value == pytest.approx(compute_bounds(pruned_graph(g, res.kept_edges)).lb, rel=1e-12)


# ----------------------------------------------------------------------------- brute force
CASES = [(dim, objective, seed) for dim in (2, 3) for objective in ("tree", "fim", "fiedler") for seed in (0, 1)]


@pytest.mark.parametrize("dim,objective,seed", CASES)
def test_greedy_and_relaxation_against_exhaustive_search(dim, objective, seed):
    """<= 12 candidates: greedy is the exact greedy (replayed by brute force), keeps (1 - 1/e) of
    the optimal gain (log-det objectives: monotone submodular), every upper bound is >= the
    optimum, and every reported value is the dense value of the reported edges. lambda_2 is not
    submodular: there the greedy is only checked to be the exact greedy and below the optimum."""
    rng = np.random.default_rng(100 * dim + seed + (7 if objective == "fiedler" else 0))
    g = chain_graph(rng, n=7, extra=10, dim=dim)
    ref = from_vertices(g)
    ex = Exhaustive(objective, g)
    assert ex.cand.size == 10
    base = ex.value(())
    for k in (1, 3, 5):
        opt, _ = ex.best(k)
        greedy = select_edges(g, k, objective=objective, method="greedy", certify=True, reference=ref,
                              max_iter=60)
        relax = select_edges(g, k, objective=objective, method="relax", reference=ref, max_iter=60)
        for res in (greedy, relax):
            kept = np.r_[ex.fixed, res.selected_edges]
            assert res.value == pytest.approx(dense_value(objective, g, kept), rel=1e-9)
            assert res.base_value == pytest.approx(base, rel=1e-9)
            assert res.value <= opt + 1e-9 * abs(opt)
            assert res.upper_bound >= opt - 1e-9 * abs(opt)
            assert 0.0 <= res.certified_ratio <= 1.0
        assert sorted(greedy.order.tolist()) == sorted(ex.greedy_replay(k))
        if objective != "fiedler":
            assert greedy.value - base >= (1 - 1 / math.e) * (opt - base) - 1e-9 * abs(opt)
            assert greedy.certificate.bounds.submodular >= opt - 1e-9 * abs(opt)
            # relax keeps the greedy selection unless a rounding of the relaxation beats it
            assert relax.value >= greedy.value
            assert (relax.rounding == "greedy") == (relax.value == greedy.value
                                                    and relax.selected.tolist() == greedy.selected.tolist())


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("objective", ["tree", "fim"])
def test_greedy_strategies_and_engines_agree(dim, objective):
    g = chain_graph(np.random.default_rng(21 + dim), n=12, extra=30, dim=dim)
    ref = from_vertices(g)
    orders = []
    for strategy in ("incremental", "lazy"):
        for engine in ("path", "cholmod"):
            res = select_edges(g, 9, objective=objective, strategy=strategy, engine=engine, reference=ref)
            orders.append(res.order.tolist())
            assert res.value == pytest.approx(dense_value(objective, g, res.kept_edges), rel=1e-10)
    assert all(o == orders[0] for o in orders)


@pytest.mark.parametrize("seed", [0, 1])
def test_fused_single_laplacian_greedy_agrees_with_the_other_engines(seed):
    """Isotropic noise scaled per edge in 2D: w = 2 kappa is proportional to tau, one Laplacian
    block, the fused compiled greedy (distinct scales keep the gains free of exact ties)."""
    g = chain_graph(np.random.default_rng(41 + seed), n=30, extra=60, dim=2, uniform=True)
    g = replace(g, info=g.info * (1.0 + 0.5 * np.random.default_rng(1).random(g.m))[:, None, None])
    assert len(tree_objective(g).blocks) == 1
    runs = [select_edges(g, 25, strategy=s, engine=e) for s, e in
            (("incremental", "path"), ("incremental", "cholmod"), ("lazy", "path"))]
    assert runs[0].order.tolist() == runs[1].order.tolist() == runs[2].order.tolist()
    assert runs[0].value == pytest.approx(dense_value("tree", g, runs[0].kept_edges), rel=1e-11)


@pytest.mark.parametrize("uniform", [False, True])
def test_incremental_greedy_refresh_does_not_change_the_choice(monkeypatch, uniform):
    import posecrb.selection.greedy as sel

    g = chain_graph(np.random.default_rng(3), n=14, extra=40, dim=2, uniform=uniform)
    if uniform:
        g = replace(g, info=g.info * (1.0 + 0.5 * np.random.default_rng(2).random(g.m))[:, None, None])
    a = select_edges(g, 20)
    monkeypatch.setattr(sel, "REFRESH_EVERY", 3)
    b = select_edges(g, 20)
    assert b.stats["refreshes"] > 1
    assert a.order.tolist() == b.order.tolist()
    assert a.certificate.bounds.submodular == pytest.approx(b.certificate.bounds.submodular, rel=1e-10)


def test_two_thread_steps_choose_what_the_fused_kernel_chooses(monkeypatch):
    """The one-Laplacian greedy's steps on two threads (the backward substitution's two subtrees,
    the candidates' two halves) against the fused compiled steps, whose choices the tests above
    check against the other engines and dense values: the same order, gains and bound bit for bit,
    across a refresh, on a grid whose nested-dissection factor splits in two."""
    import posecrb.selection.greedy as sel

    g = grid(2, 70, noise=True, rng=1)      # 4,900 poses: the selection's analysis takes METIS
    g = replace(g, info=g.info * (1.0 + 0.5 * np.random.default_rng(4).random(g.m))[:, None, None])
    used = []
    two_threads = sel._steps_two_threads
    monkeypatch.setattr(sel, "_steps_two_threads", lambda *a: used.append(a[3]) or two_threads(*a))
    monkeypatch.setattr(sel, "THREADED_FACTOR_ENTRIES", 0)
    monkeypatch.setattr(sel, "_two_threads_allowed", lambda k: True)
    threaded = select_edges(g, 300)          # more than REFRESH_EVERY steps: one refresh on the way
    assert used and all(top > mid > 0 for top, mid in used)
    assert threaded.stats["refreshes"] == 2
    monkeypatch.setattr(sel, "_two_threads_allowed", lambda k: False)
    count = len(used)
    fused = select_edges(g, 300)
    assert len(used) == count
    assert threaded.order.tolist() == fused.order.tolist()
    assert threaded.value == fused.value
    assert threaded.certificate.bounds.submodular == fused.certificate.bounds.submodular


def _closed_pattern(parent: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """CSC pattern of a Cholesky factor whose column j holds j and all its ancestors."""
    cols = []
    for j in range(len(parent)):
        rows, a = [j], parent[j]
        while a != -1:
            rows.append(a)
            a = parent[a]
        cols.append(rows)
    indptr = np.cumsum([0] + [len(c) for c in cols]).astype(np.int64)
    return indptr, np.concatenate(cols).astype(np.int64)


def test_subtree_split_finds_the_two_halves_below_the_trunk():
    from posecrb.selection._kernels import subtree_split

    # two subtrees {0, 1, 2} and {3, 4, 5} below the trunk 6 <- 7
    parent = [2, 2, 6, 5, 5, 6, 7, -1]
    indptr, indices = _closed_pattern(parent)
    par = np.array(parent, dtype=np.int64)
    assert subtree_split(indptr, indices, par, 0.25) == (6, 3)
    assert subtree_split(indptr, indices, par, 0.5) == (-1, -1)          # halves too small
    # a column of the first half with a row in the second: not independent
    cross = np.insert(indices, indptr[1], 4)
    assert subtree_split(indptr + (np.arange(indptr.size) >= 2), cross, par, 0.25) == (-1, -1)
    for other in ([1, 2, 3, 4, 5, 6, 7, -1],            # a path: no node with two children
                  [2, 2, 6, 5, 5, 6, -1, -1],           # two roots
                  [2, 2, 7, 5, 5, 7, 7, -1],            # three children below the trunk
                  [4, 4, 5, 5, 6, 6, 7, -1]):           # not postordered: subtrees interleave
        indptr, indices = _closed_pattern(other)
        assert subtree_split(indptr, indices, np.array(other, dtype=np.int64), 0.0) == (-1, -1)


def test_lazy_greedy_with_random_projections_reports_exact_values():
    g = chain_graph(np.random.default_rng(8), n=14, extra=40, dim=2)
    jl = select_edges(g, 10, strategy="lazy", gains="jl", seed=3)
    exact = select_edges(g, 10, strategy="lazy")
    assert jl.stats["gains"] == "jl"
    assert jl.value == pytest.approx(dense_value("tree", g, jl.kept_edges), rel=1e-11)
    # the queue is only seeded by the estimates; re-evaluations are exact, so it is close to greedy
    assert jl.value >= exact.base_value + 0.9 * (exact.value - exact.base_value)
    with pytest.raises(UsageError, match="lazy"):
        select_edges(g, 10, strategy="incremental", gains="jl")


# ----------------------------------------------------------------------------- relaxation
def test_frank_wolfe_bound_brackets_the_relaxation_optimum_from_slsqp():
    from scipy.optimize import minimize

    g = chain_graph(np.random.default_rng(12), n=8, extra=9, dim=2)
    obj = tree_objective(g)
    split = split_edges(g)
    cand, k = split.candidates, 4
    x0 = np.zeros(g.m)
    x0[split.fixed] = 1.0
    terms = [(2, dense_laplacian_terms(g, precisions(g.info, 2)[0])),
             (1, dense_laplacian_terms(g, rot_weight(precisions(g.info, 2)[1], 2)))]

    def f(pi):
        x = x0.copy()
        x[cand] = pi
        return -sum(c * chol_logdet(np.tensordot(x, t, 1)) for c, t in terms)

    opt = minimize(f, np.full(cand.size, k / cand.size), method="SLSQP", bounds=[(0, 1)] * cand.size,
                   constraints=[{"type": "eq", "fun": lambda p: p.sum() - k}], options={"ftol": 1e-14, "maxiter": 500})
    relax_opt = -opt.fun
    base = obj.value(x0)
    fw = frank_wolfe(obj, x0, cand, k, np.full(cand.size, k / cand.size), max_iter=500, tol=1e-4, base_value=base)
    assert fw.bound >= relax_opt - 1e-9 * abs(relax_opt)
    assert fw.value <= relax_opt + 1e-9 * abs(relax_opt)
    assert fw.bound - fw.value <= 1e-3 * (fw.bound - base)
    assert abs(fw.weights.sum() - k) < 1e-9 and fw.weights.min() >= 0 and fw.weights.max() <= 1


def test_projected_gradient_bound_brackets_the_relaxation_optimum_from_slsqp():
    """The log-det relaxation by spectral projected gradient (what relax and --certify run) against
    SLSQP's optimum: its bound is above, its value below, and they close within ``tol``."""
    from scipy.optimize import minimize

    for seed, dim in ((12, 2), (13, 3)):
        g = chain_graph(np.random.default_rng(seed), n=8, extra=9, dim=dim)
        obj = tree_objective(g)
        split = split_edges(g)
        cand, k = split.candidates, 4
        x0 = np.zeros(g.m)
        x0[split.fixed] = 1.0
        tau, kappa = precisions(g.info, dim)
        terms = [(dim, dense_laplacian_terms(g, tau)),
                 (1 if dim == 2 else 3, dense_laplacian_terms(g, rot_weight(kappa, dim)))]

        def f(pi, x0=x0, cand=cand, terms=terms):
            x = x0.copy()
            x[cand] = pi
            return -sum(c * chol_logdet(np.tensordot(x, t, 1)) for c, t in terms)

        opt = minimize(f, np.full(cand.size, k / cand.size), method="SLSQP", bounds=[(0, 1)] * cand.size,
                       constraints=[{"type": "eq", "fun": lambda p, k=k: p.sum() - k}],
                       options={"ftol": 1e-14, "maxiter": 500})
        relax_opt = -opt.fun
        base = obj.value(x0)
        spg = projected_gradient(obj, x0, cand, k, np.full(cand.size, k / cand.size), max_iter=200, tol=1e-6,
                                 base_value=base)
        assert spg.converged and spg.step == "spg"
        assert spg.bound >= relax_opt - 1e-9 * abs(relax_opt)
        assert spg.value <= relax_opt + 1e-9 * abs(relax_opt)
        assert spg.bound - relax_opt <= 1e-6 * (spg.bound - base) + 1e-9 * abs(relax_opt)
        assert abs(spg.weights.sum() - k) < 1e-9 and spg.weights.min() >= 0 and spg.weights.max() <= 1


def test_capped_simplex_projection_against_bisection_and_a_quadratic_program():
    """``project_capped_simplex`` (the kinks of the piecewise-linear sum, sorted) against the same
    minimiser's threshold found by plain bisection, its form (KKT: ``y - x`` is one constant on the
    entries strictly inside (0, 1)), and SLSQP on ``min ||x - y||^2`` (never better than ours)."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(31)
    for n, k in ((6, 2), (40, 7), (25, 24.5), (30, 0.5), (50, 10)):
        y = 3.0 * rng.normal(size=n)
        if n == 50:
            y = np.round(y)                  # ties among the kinks
        x = project_capped_simplex(y, k)
        assert x.sum() == pytest.approx(k, abs=1e-12 * n) and x.min() >= 0.0 and x.max() <= 1.0
        lo, hi = y.min() - 1.0, y.max()
        for _ in range(200):                 # sum(clip(y - tau, 0, 1)) is non-increasing in tau
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.clip(y - mid, 0, 1).sum() > k else (lo, mid)
        assert np.abs(x - np.clip(y - 0.5 * (lo + hi), 0, 1)).max() <= 1e-12 * max(1.0, np.abs(y).max())
        inside = (x > 1e-12) & (x < 1 - 1e-12)
        if inside.sum() > 1:
            assert np.ptp((y - x)[inside]) <= 1e-12 * max(1.0, np.abs(y).max())
        ref = minimize(lambda z, y=y: ((z - y) ** 2).sum(), np.full(n, k / n), jac=lambda z, y=y: 2 * (z - y),
                       method="SLSQP", bounds=[(0, 1)] * n,
                       constraints=[{"type": "eq", "fun": lambda z, k=k: z.sum() - k}],
                       options={"ftol": 1e-15, "maxiter": 1000})
        assert ((x - y) ** 2).sum() <= ((ref.x - y) ** 2).sum() + 1e-9 * max(1.0, (y ** 2).sum())


def test_madow_sampling_has_the_requested_inclusion_probabilities():
    p = np.array([0.9, 0.1, 0.5, 0.5, 1.0, 0.25, 0.75])
    k = 4                     # = p.sum()
    rng = np.random.default_rng(0)
    trials = 20000
    counts = np.zeros(p.size)
    for _ in range(trials):
        pick = madow(p, k, rng)
        assert pick.size == k and np.unique(pick).size == k
        counts[pick] += 1
    # binomial standard error sqrt(p(1-p)/n) <= 0.0036; 5 sigma
    assert np.allclose(counts / trials, p, atol=0.018)


# ----------------------------------------------------------------------------- budgets, fixed edges
@pytest.mark.parametrize("spec,k", [("3", 3), ("10", 10), ("50%", 5), ("100%", 10), ("25%", 2), ("12.5%", 1)])
def test_budget_parsing(spec, k):
    assert parse_budget(spec, 10) == k


@pytest.mark.parametrize("spec,msg", [("0", ">= 1"), ("-3", ">= 1"), ("11", "exceeds"), ("abc", "expected"),
                                      ("5%%", "expected"), ("%", "expected"), ("0%", "(0, 100]"),
                                      ("101%", "(0, 100]"), ("1%", "rounds down"), ("2.5", "expected")])
def test_bad_budgets_are_usage_errors(spec, msg):
    with pytest.raises(UsageError) as info:
        parse_budget(spec, 10)
    assert msg in str(info.value)


def test_odometry_split_and_connectivity_repair():
    rng = np.random.default_rng(0)
    g = chain_graph(rng, n=8, extra=6, dim=2)
    split = split_edges(g)
    assert split.fixed.tolist() == list(range(7)) and split.connectivity.size == 0
    # break the chain between ids 3 and 4 and offer two candidates across the cut
    keep = np.r_[[0, 1, 2, 4, 5, 6], np.arange(7, g.m)]
    h = pruned_graph(g, keep)
    h = replace(h, src=np.r_[h.src, 2, 1], dst=np.r_[h.dst, 5, 6], rot=np.r_[h.rot, h.rot[:2]],
                trans=np.r_[h.trans, h.trans[:2]], info=np.r_[h.info, 3.0 * h.info[:1], h.info[:1]])
    tau = h.tau
    cross = [e for e in range(h.m) if (min(h.src[e], h.dst[e]) <= 3) != (max(h.src[e], h.dst[e]) <= 3)]
    split = split_edges(h)
    assert split.connectivity.size == 1
    assert split.connectivity[0] == max(cross, key=lambda e: (tau[e], -e))
    assert set(split.fixed) == set(range(6)) | set(split.connectivity.tolist())


def test_fixed_file_pairs_unknown_pair_and_disconnected_set(tmp_path):
    g = chain_graph(np.random.default_rng(0), n=6, extra=4, dim=2, ids=np.arange(6) * 10)
    f = tmp_path / "fixed.txt"
    f.write_text("# odometry\n0 10\n20 10\n\n20 30 # comment\n30 40\n50 40\n")
    split = split_edges(g, str(f))
    assert split.fixed.tolist() == list(range(5)) and split.rule == str(f)
    f.write_text("0 10\n10 20\n0 50\n")
    with pytest.raises(ParseError, match=r"fixed.txt:3: no edge between pose ids 0 and 50"):
        split_edges(g, str(f))
    f.write_text("0 10\n10 x\n")
    with pytest.raises(ParseError, match=r":2: expected two pose ids"):
        split_edges(g, str(f))
    f.write_text("0 10\n20 30\n")
    with pytest.raises(DisconnectedFixedSet, match="pieces"):
        split_edges(g, str(f))


def test_fixed_file_is_read_with_the_readers_line_rules(tmp_path):
    """Lines end at \\n, \\r\\n and \\r only, fields are separated by ASCII blanks, and the file must
    be a regular UTF-8 file: the rules of the g2o reader (``str.splitlines`` would also break at
    U+2028 and form feed, shifting every later line number)."""
    g = chain_graph(np.random.default_rng(0), n=6, extra=4, dim=2, ids=np.arange(6) * 10)
    f = tmp_path / "fixed.txt"
    f.write_bytes(b"0 10\r10 20\r\n20 30#c\n30 40\t# tab\r\n40 50")
    assert split_edges(g, str(f)).fixed.tolist() == list(range(5))
    f.write_bytes("0 10\r10 20\r\n20 30\u202830 40\n40 50\n".encode())
    with pytest.raises(ParseError, match=r"fixed.txt:3: expected two pose ids"):
        split_edges(g, str(f))
    f.write_bytes(b"0 10\x0c10 20\n20 x\n")          # form feed separates fields, it ends no line
    with pytest.raises(ParseError, match=r"fixed.txt:1: expected two pose ids"):
        split_edges(g, str(f))
    f.write_bytes(b"0 10\n\xff\xfe 20\n")
    with pytest.raises(ParseError, match=r"fixed.txt:2: not a text file"):
        split_edges(g, str(f))
    with pytest.raises(ParseError, match="not a regular file"):
        split_edges(g, str(tmp_path))


@pytest.mark.parametrize("keywords", [{"tol": float("nan")}, {"tol": 0.0}, {"tol": -1e-3}, {"tol": float("inf")},
                                      {"max_iter": 0}, {"max_iter": 2.5}, {"objective": "trees"},
                                      {"method": "exact"}, {"gains": "approx"}])
def test_invalid_options_are_usage_errors(keywords):
    g = chain_graph(np.random.default_rng(0), n=6, extra=4, dim=2)
    with pytest.raises(UsageError):
        select_edges(g, 2, **keywords)


def test_disconnected_graph_is_reported():
    g = chain_graph(np.random.default_rng(0), n=6, extra=2, dim=2)
    keep = [e for e in range(g.m) if not (g.src[e] <= 2 < g.dst[e] or g.dst[e] <= 2 < g.src[e])]
    with pytest.raises(DisconnectedGraph):
        split_edges(pruned_graph(g, keep))


# ----------------------------------------------------------------------------- pruned graph, CLI
def run_cli(argv, capsys):
    from posecrb.cli import main

    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture
def g2o_path(tmp_path):
    from posecrb.io import write_g2o

    g = chain_graph(np.random.default_rng(9), n=10, extra=12, dim=3)
    path = tmp_path / "small.g2o"
    write_g2o(g, path)
    return path


def test_cli_json_keys_and_pruned_file(g2o_path, tmp_path, capsys):
    from posecrb.io import load

    out = tmp_path / "pruned.g2o"
    code, text, err = run_cli(["select", str(g2o_path), "--budget", "40%", "--format", "json",
                               "--out", str(out), "--certify"], capsys)
    assert code == 0, err
    data = json.loads(text)
    for key in ("dataset", "objective", "method", "budget", "fixed", "candidates", "selected", "value",
                "base_value", "upper_bound", "certified_ratio", "times"):
        assert key in data
    assert data["budget"] == 4 and data["candidates"] == 12 and len(data["selected"]) == 4
    g = load(str(g2o_path))
    p = load(str(out))
    kept = sorted(list(range(9)) + [e for _, _, e in data["selected"]])
    assert p.m == 13 and np.array_equal(p.ids, g.ids)
    for (i, j, e) in data["selected"]:
        assert (g.ids[g.src[e]], g.ids[g.dst[e]]) == (i, j)
    assert np.allclose(p.info, g.info[kept]) and np.allclose(p.trans, g.trans[kept])
    assert data["value"] == pytest.approx(dense_value("tree", g, kept), rel=1e-10)
    assert data["upper_bound"] >= data["value"]
    assert not list(tmp_path.glob("*.tmp"))


def test_cli_table_output(g2o_path, capsys):
    code, text, err = run_cli(["select", str(g2o_path), "--budget", "3", "--method", "relax"], capsys)
    assert code == 0, err
    assert "certified ratio" in text and "upper bound" in text


@pytest.mark.parametrize("argv,code,msg", [
    (["--budget", "13"], 2, "exceeds the 12 candidate"),
    (["--budget", "0"], 2, ">= 1"),
    (["--budget", "-2"], 2, ">= 1"),
    (["--budget", "ten%"], 2, "expected a number"),
    (["--budget", "3", "--objective", "nope"], 2, "nope"),
])
def test_cli_usage_errors(g2o_path, capsys, argv, code, msg):
    rc, _, err = run_cli(["select", str(g2o_path), *argv], capsys)
    assert rc == code
    assert msg in err


def test_cli_fixed_file_errors(g2o_path, tmp_path, capsys):
    f = tmp_path / "pairs.txt"
    f.write_text("0 1\n1 2\n2 99\n")
    rc, _, err = run_cli(["select", str(g2o_path), "--budget", "2", "--fixed", str(f)], capsys)
    assert rc == 1 and "pairs.txt:3: no edge between pose ids 2 and 99" in err
    f.write_text("0 1\n1 2\n")
    rc, _, err = run_cli(["select", str(g2o_path), "--budget", "2", "--fixed", str(f)], capsys)
    assert rc == 1 and "pieces" in err


# ----------------------------------------------------------------------------- real data
def test_intel_tree_greedy_value_and_certificate(shared_datasets):
    from posecrb.io import load
    from posecrb.models.paper.bounds import compute_bounds

    g = load(shared_datasets / "intel.g2o")
    res = select_edges(g, "10%", certify=True)
    assert res.budget == 78 and res.candidates == 785
    assert res.value == pytest.approx(compute_bounds(pruned_graph(g, res.kept_edges)).lb, rel=1e-12)
    assert res.base_value < res.value <= res.upper_bound < res.full_value
    assert 0.5 < res.certified_ratio <= 1.0


def test_small_grid_fim_value_is_the_consistent_fim_logdet(shared_datasets):
    from posecrb.io import load
    from posecrb.models.paper.fim import fim_logdet, paper_fim

    g = load(shared_datasets / "smallGrid3D.g2o")
    res = select_edges(g, "20%", objective="fim", estimate="solve")
    assert res.estimate.certified
    from posecrb.solver.estimate import get_estimate

    est = get_estimate(g, "solve")
    f = paper_fim(pruned_graph(g, res.kept_edges), est.rot, est.trans, 0, variant="consistent")
    assert res.value == pytest.approx(fim_logdet(f), rel=1e-10)


# ----------------------------------------------------------------------------- sparsify experiment
def test_alignment_and_trajectory_errors_closed_forms():
    from scipy.spatial.transform import Rotation

    from posecrb.verification.trajectory import align, trajectory_error

    rng = np.random.default_rng(0)
    n = 9
    rot = random_rotations(rng, n, 3)
    trans = rng.normal(size=(n, 3))
    g_rot = Rotation.random(random_state=1).as_matrix()
    g_t = rng.normal(size=3)
    moved_rot, moved_trans = g_rot @ rot, trans @ g_rot.T + g_t
    r, _ = align(moved_trans, trans)
    ref, _ = Rotation.align_vectors(trans - trans.mean(0), moved_trans - moved_trans.mean(0))
    assert np.allclose(r, ref.as_matrix(), atol=1e-10)
    err = trajectory_error(moved_rot, moved_trans, rot, trans)
    assert max(vars(err).values()) < 1e-6
    # one translation moved by v: two relative translations change by |v| each
    v = np.array([0.3, -0.1, 0.2])
    tr2 = trans.copy()
    tr2[4] += v
    err = trajectory_error(rot, tr2, rot, trans)
    assert err.rpe_trans == pytest.approx(np.sqrt(2 * v @ v / (n - 1)), rel=1e-12)
    assert err.rpe_rot_deg < 1e-6
    # one orientation turned by a: the two relative rotations around it change by a
    a = 0.05
    rot2_ = rot.copy()
    rot2_[4] = rot[4] @ Rotation.from_rotvec([0.0, 0.0, a]).as_matrix()
    err = trajectory_error(rot2_, trans, rot, trans)
    assert err.rpe_rot_deg == pytest.approx(np.degrees(a * np.sqrt(2 / (n - 1))), rel=1e-9)


def test_sparsify_experiment_rows_and_executors():
    from posecrb.experiments.sparsify import sparsify_experiment

    g = chain_graph(np.random.default_rng(31), n=14, extra=12, dim=2)
    methods = "greedy,relax,fiedler-relax,random,naive,fim-greedy"
    res = sparsify_experiment(g, ["3", "100%"], methods, max_iter=30)
    assert len(res.rows) == 12
    full = [r for r in res.rows if r["budget_spec"] == "100%"]
    for r in full:   # every candidate kept: the full graph again
        assert r["tree"] == pytest.approx(res.reference["tree"], rel=1e-12)
        assert r["ate_trans"] < 1e-5 and r["certified"]
    for r in res.rows:
        sel = select_edges(g, r["budget_spec"], objective=r["objective"], method=r["method"].split("-")[-1],
                           max_iter=30, reference=from_reference(g))
        assert r["value"] == pytest.approx(sel.value, rel=1e-9)
    par = sparsify_experiment(g, ["3", "100%"], methods, max_iter=30, executor="local", jobs=2)
    keys = [k for k in res.rows[0] if not k.startswith("time")]
    assert [[r[k] for k in keys] for r in par.rows] == [[r[k] for k in keys] for r in res.rows]


def from_reference(g):
    from posecrb.solver.estimate import get_estimate

    return get_estimate(g, "solve")


def test_cli_experiment_sparsify_writes_run_record(g2o_path, tmp_path, capsys):
    out = tmp_path / "run"
    code, text, err = run_cli(["experiment", "sparsify", str(g2o_path), "--budgets", "2,50%", "--methods",
                               "greedy,naive", "--format", "json", "--out", str(out)], capsys)
    assert code == 0, err
    rows = json.loads(text)
    assert [(r["budget_spec"], r["method"]) for r in rows] == [("2", "greedy"), ("2", "naive"),
                                                                ("50%", "greedy"), ("50%", "naive")]
    run = json.loads((out / "run.json").read_text())
    assert run["experiment"] == "sparsify" and run["settings"]["candidates"] == 12
    assert (out / "sparsify.png").stat().st_size > 0 and (out / "rows.csv").exists()
    assert not list(out.glob("*.tmp"))
    rc, _, err = run_cli(["experiment", "sparsify", str(g2o_path), "--methods", "greedy,bogus"], capsys)
    assert rc == 2 and "bogus" in err


@pytest.mark.parametrize("state", ["warning", "unavailable"])
def test_sparsify_reports_a_doubtful_crlb_trace(g2o_path, capsys, monkeypatch, state):
    """The pruned graphs' CRLB traces carry the selected inverse's status (computed and tested in
    posecrb.linalg.selinv): here forced, to follow it through rows, JSON, the table and stderr."""
    import posecrb.experiments.sparsify as sparsify
    from posecrb.core.status import Status
    from posecrb.linalg.selinv import SelectedInverse

    class Doubtful(SelectedInverse):
        def __init__(self, factor, name="matrix", **kwargs):
            super().__init__(factor, name, **kwargs)
            self.status = Status(state, f"forced {state} of the {name}")

    monkeypatch.setattr(sparsify, "SelectedInverse", Doubtful)
    argv = ["experiment", "sparsify", str(g2o_path), "--budgets", "2", "--methods", "greedy"]
    code, text, err = run_cli([*argv, "--format", "json"], capsys)
    assert code == 0, err
    (row,) = json.loads(text)
    assert row["crlb_trace_status"] == {"status": state, "reason": f"forced {state} of the pruned graph FIM"}
    assert (row["crlb_trace"] is None) == (state == "unavailable")
    what = "not available" if state == "unavailable" else "doubtful"
    for where in ("full graph", "fixed edges only", "greedy@2"):
        assert f"posecrb: warning: tr CRLB ({where}) {what}: forced {state}" in err
    code, text, _ = run_cli([*argv, "--format", "markdown"], capsys)
    assert code == 0
    assert ("n/a (forced unavailable" if state == "unavailable" else "(warning)") in text
    code, text, _ = run_cli([*argv, "--format", "table"], capsys)   # the title names the full graph's trace
    assert code == 0
    assert ("tr CRLB n/a" in " ".join(text.split())) == (state == "unavailable")


@pytest.mark.parametrize("status", [("warning", "w", None), ("unavailable", "u", "rescale"), ("ok", None, None)])
def test_status_json_round_trip(status):
    from posecrb.core.status import Status

    st = Status(*status)
    assert Status.from_json(st.as_json()) == st


def test_a_singular_starting_point_names_the_fixed_edges(monkeypatch):
    """Where the FIM of the fixed edges alone fails to factor (information scaled to 1e-12 made a
    3D grid's odometry FIM singular to working precision), the error names the fixed edges, not the
    whole graph, and keeps the factorization's reason."""
    from posecrb.core.errors import NotPositiveDefinite
    from posecrb.selection.objectives import LogDetObjective

    g = chain_graph(np.random.default_rng(5), n=9, extra=10)
    base_weights = []

    def singular(self, x):
        base_weights.append(np.array(x))
        raise NotPositiveDefinite("anchored FIM", "matrix not positive definite (code 1)")

    monkeypatch.setattr(LogDetObjective, "evaluate", singular)
    with pytest.raises(NotPositiveDefinite) as exc:
        select_edges(g, 3, objective="fim", reference=from_vertices(g))
    assert base_weights[0].sum() == 8  # the odometry chain of 9 poses, the only thing evaluated
    msg = str(exc.value)
    assert "anchored FIM of the 8 fixed edges" in msg and "(code 1)" in msg
    assert "fixed edges alone must determine every pose" in msg


def record_inversion_kernels(monkeypatch) -> tuple[list, list]:
    """Every ``SelectedInverse`` made from now on records the kernels it took, and the kernels the
    same factor would take alone (without ``repeated``)."""
    from posecrb.linalg import selinv

    kernels, alone = [], []
    original = selinv.SelectedInverse.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        kernels.append(self._kernels)
        alone.append(selinv._inversion_kernels(self.indptr, self.indices,
                                               selinv.supernode_bounds(self.indptr, self.indices)))

    monkeypatch.setattr(selinv.SelectedInverse, "__init__", spy)
    return kernels, alone


@pytest.mark.parametrize("objective,method,certify", [("tree", "relax", False), ("tree", "greedy", True),
                                                      ("fim", "greedy", False)])
def test_selection_inverts_with_the_compiled_kernels(monkeypatch, objective, method, certify):
    """A selection inverts a factor per iteration: every inversion takes the compiled kernels, whose
    one-time cost the iterations share, even where one inversion alone would take the block kernels
    (a factor this small always would). Small problems take their H_e from solves instead (the
    test below); the limits are lowered here so that this small graph counts as large."""
    from posecrb.linalg import selinv
    from posecrb.selection import greedy, objectives

    monkeypatch.setattr(objectives, "H_SOLVE_ENTRIES", 0)
    monkeypatch.setattr(greedy, "CHOLMOD_ENGINE_ENTRIES", 0)
    kernels, alone = record_inversion_kernels(monkeypatch)
    g = chain_graph(np.random.default_rng(41), n=12, extra=10, dim=2)
    ref = from_vertices(g) if objective == "fim" else None
    select_edges(g, "4", objective=objective, method=method, certify=certify, reference=ref, max_iter=20)
    assert kernels, "the selection made no selected inversion"
    assert all(k is selinv._kernels() for k in kernels)
    # one of these factors inverted alone takes the block kernels: the check above is not vacuous
    assert all(isinstance(k, selinv._BlockKernels) for k in alone)


@pytest.mark.parametrize("objective", ["tree", "fim"])
def test_small_greedy_selections_solve_instead_of_inverting(monkeypatch, objective):
    """Below the limits the greedy takes every H_e from solves with the whole factor and runs the
    CHOLMOD engine: no selected inversion, no compiled kernel, and the values of the inverting run.
    (The relaxation's gradient, evaluated at every iteration, keeps the selected inversion.)"""
    from posecrb.selection import greedy, objectives

    g = chain_graph(np.random.default_rng(41), n=12, extra=10, dim=2)
    ref = from_vertices(g) if objective == "fim" else None
    kernels, _ = record_inversion_kernels(monkeypatch)
    compiled = []
    monkeypatch.setattr(greedy, "_compiled", lambda: compiled.append(1) or pytest.fail("compiled kernels loaded"))
    small = select_edges(g, "4", objective=objective, reference=ref)
    assert kernels == [] and compiled == []
    assert small.stats["engine"] == "cholmod"
    monkeypatch.undo()
    monkeypatch.setattr(objectives, "H_SOLVE_ENTRIES", 0)
    monkeypatch.setattr(greedy, "CHOLMOD_ENGINE_ENTRIES", 0)
    large = select_edges(g, "4", objective=objective, reference=ref)
    assert large.stats["engine"] == "path"
    assert small.selected.tolist() == large.selected.tolist()
    assert small.value == pytest.approx(dense_value(objective, g, small.kept_edges), rel=1e-10)
    assert small.upper_bound == pytest.approx(large.upper_bound, rel=1e-10)


def test_engine_choice_follows_the_problem_size():
    """``auto`` is the CHOLMOD engine up to CHOLMOD_ENGINE_ENTRIES entries of M^{-1} U and the path
    engine beyond; an unknown engine is a usage error."""
    from posecrb.selection.greedy import CHOLMOD_ENGINE_ENTRIES, pick_engine

    g = chain_graph(np.random.default_rng(5), n=12, extra=10, dim=2)
    obj = tree_objective(g)
    per_column = sum(b.size * b.U.shape[2] for b in obj.blocks)
    fits = CHOLMOD_ENGINE_ENTRIES // per_column
    assert pick_engine("auto", obj, 10, fits - 10) == "cholmod"
    assert pick_engine("auto", obj, 10, fits - 9) == "path"
    assert pick_engine("path", obj, 10, 1) == "path" and pick_engine("cholmod", obj, 10, 10 ** 9) == "cholmod"
    with pytest.raises(UsageError, match="unknown update engine"):
        pick_engine("dense", obj, 10, 1)


def test_sparsify_evaluates_with_the_compiled_kernels(monkeypatch):
    """The sparsification experiment inverts a pruned graph's FIM per selection it evaluates."""
    from posecrb.experiments import sparsify
    from posecrb.linalg import selinv

    kernels, _ = record_inversion_kernels(monkeypatch)
    g = chain_graph(np.random.default_rng(31), n=14, extra=12, dim=2)
    sparsify.sparsify_experiment(g, ["3"], "greedy,random", max_iter=20)
    assert len(kernels) >= 2
    assert all(k is selinv._kernels() for k in kernels)


@pytest.mark.parametrize("r", [1, 3, 6])
def test_numpy_logdet_eye_plus_matches_slogdet_and_the_compiled_kernel(r):
    """``logdet(I + H)`` of the objectives' gains (numpy) against numpy's slogdet of each ``I + H`` and the
    path engine's compiled kernel, on PSD blocks from zero to 10^5 in norm. A backward-stable
    factorization of I + H (>= I, so its inverse has norm <= 1) perturbs the log-det by at most
    about r eps ||I + H|| in absolute terms: the tolerance, with a margin of 64."""
    from posecrb.linalg.pathchol import logdet_eye_plus as compiled
    from posecrb.selection.objectives import logdet_eye_plus

    rng = np.random.default_rng(r)
    a = rng.standard_normal((40, r, r)) * np.exp(rng.uniform(-6, 6, 40))[:, None, None]
    a[:5, :, : max(r - 1, 0)] = 0.0                   # rank-deficient (for r = 1: H = 0)
    h = np.einsum("kab,kcb->kac", a, a)
    ref = np.array([np.linalg.slogdet(np.eye(r) + x)[1] for x in h])
    tol = 64 * r * np.finfo(float).eps * (1.0 + np.linalg.norm(h, ord=2, axis=(1, 2)))
    assert np.all(np.abs(logdet_eye_plus(h) - ref) <= tol)
    assert np.all(np.abs(logdet_eye_plus(h) - compiled(h)) <= tol)
