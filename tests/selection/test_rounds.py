"""The round greedy (posecrb.selection.rounds, posecrb.selection._local) against dense references.

References: the exact greedy replayed by the incremental greedy (itself checked against brute force
in tests/selection/references.py), dense matrices and numpy solves for the balls' potentials, scipy's
Dijkstra for the balls, a dense numpy replay of one round's first-order Woodbury corrections, and
exhaustive search for the bounds. The certified ratio against the exact greedy's on grids is the
acceptance criterion of the method (at least the exact greedy's minus 0.01).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from posecrb.core.errors import UsageError
from posecrb.selection import fim_objective, select_edges, split_edges, tree_objective
from posecrb.selection.greedy import pick_strategy
from posecrb.sim.generators import grid
from posecrb.solver.estimate import from_vertices

from ..numerics import EPS, MARGIN, assert_within, spd_condition
from . import references as ts


def _objective(kind: str, g):
    if kind == "fim":
        ref = from_vertices(g)
        return fim_objective(g, ref.rot, ref.trans)
    return tree_objective(g)


# ----------------------------------------------------------------------------- the kernels
def test_ball_is_the_bounded_dijkstra_ball_with_its_shortest_path_tree():
    """The poses within the radius (the nearest ``cap`` of them) in the order they settle, each with a
    parent that closes its shortest path, against scipy's Dijkstra."""
    from posecrb.selection import _ballsolve
    from posecrb.selection.rounds import _csr

    rng = np.random.default_rng(3)
    g = ts.chain_graph(rng, n=60, extra=90)
    length = 0.2 + rng.random(g.m)
    ptr, to, ln = _csr(g.n, np.r_[g.src, g.dst], np.r_[g.dst, g.src], np.tile(length, 2))
    adj = sp.csr_matrix((length, (g.src, g.dst)), shape=(g.n, g.n))
    dist, tpar, spos = np.full(g.n, np.inf), np.zeros(g.n, np.int64), np.zeros(g.n, np.int64)
    for v0, v1, radius, cap in ((0, 1, 1.5, g.n), (10, 40, 3.0, g.n), (5, 5, 0.0, g.n), (7, 30, np.inf, g.n),
                                (7, 30, np.inf, 9), (3, 4, 2.0, 2)):
        poses, par = _ballsolve.ball(v0, v1, radius, cap, ptr, to, ln, dist, tpar, spos)
        ref = dijkstra(adj, directed=False, indices=[v0, v1], min_only=True)
        inside = np.flatnonzero(ref <= radius)
        nearest = inside[np.argsort(ref[inside], kind="stable")][:cap]   # random lengths: no ties
        assert sorted(poses.tolist()) == sorted(nearest.tolist())
        assert set(poses[:2].tolist()) == {v0, v1} and (par[:len({v0, v1})] == -1).all()
        for t in range(len({v0, v1}), poses.size):      # a tree edge closes each pose's shortest path
            assert par[t] < t
            u, v = poses[par[t]], poses[t]
            step = min(length[e] for e in range(g.m) if {g.src[e], g.dst[e]} == {u, v})
            assert ref[v] == pytest.approx(ref[u] + step, rel=1e-12)
        assert np.isinf(dist).all()                      # the work array is left as it came


def _whole_graph_potential(obj, x, f, tol):
    """The kernel's potential of edge f on a ball holding every pose, and the dense M^{-1} U_f."""
    from posecrb.selection import _ballsolve, _local
    from posecrb.selection.rounds import _csr, _pose_rows

    rows = _pose_rows(obj)
    n = rows.shape[0]
    sel = np.flatnonzero(x > 0)
    ptr, to, ln = _csr(n, np.r_[obj.src[sel], obj.dst[sel]], np.r_[obj.dst[sel], obj.src[sel]], np.ones(2 * sel.size))
    poses, par = _ballsolve.ball(obj.src[f], obj.dst[f], np.inf, n, ptr, to, ln, np.full(n, np.inf),
                             np.zeros(n, np.int64), np.zeros(n, np.int64))
    mats = [b.matrix(x) for b in obj.blocks]
    dense = [m.toarray() for m in mats]
    us = np.stack([b.U[[f]] for b in obj.blocks])
    exact = [np.linalg.solve(d, b.rhs(np.array([f]))) for d, b in zip(dense, obj.blocks)]
    hs = np.stack([(b.rhs(np.array([f])).T @ z)[None] for b, z in zip(obj.blocks, exact)])
    ends = np.array([[obj.src[f], obj.dst[f]]])
    lrow, phi, its, bad = _local.potential(0, ends, us, hs, poses, par, rows, mats[0].indptr.astype(np.int64),
                                           mats[0].indices.astype(np.int64), np.stack([m.data for m in mats]),
                                           np.full(dense[0].shape[0], -1, np.int64), tol, 10_000)
    assert bad == 0 and its > 0
    local = np.empty_like(np.stack(exact, axis=1))       # back to the blocks' row order
    for t, v in enumerate(poses):
        if lrow[t] >= 0:
            local[rows[v]] = phi[lrow[t]:lrow[t] + rows.shape[1]]
    return local, np.stack(exact, axis=1), dense


@pytest.mark.parametrize("kind,dim", [("tree", 2), ("tree", 3), ("fim", 2), ("fim", 3)])
def test_a_ball_holding_the_whole_graph_gives_the_exact_potential(kind, dim):
    """No boundary: the Dirichlet problem is M Phi = U_f itself, and the scaling to the exact H_f
    is then the identity; conjugate gradients to a relative residual t leave an error of at most
    kappa(M) t ||Phi|| (plus rounding)."""
    g = ts.chain_graph(np.random.default_rng(40 + dim), n=14, extra=25, dim=dim)
    obj = _objective(kind, g)
    split = split_edges(g)
    x = np.zeros(g.m)
    x[split.fixed] = 1.0
    x[split.candidates[::3]] = 1.0
    tol = 1e-12
    for f in split.candidates[1:8:3]:
        local, exact, dense = _whole_graph_potential(obj, x, f, tol)
        for b, d in enumerate(dense):
            kappa = spd_condition(d)
            scale = np.abs(exact[:, b]).max()
            assert_within(local[:, b], exact[:, b], MARGIN * kappa * (tol + d.shape[0] * EPS) * scale,
                          f"{kind} potential of edge {f}, block {b}")


def test_on_a_tree_the_preconditioner_is_the_matrix():
    """The odometry chain alone, searched from one pose, is its own shortest-path tree: the
    preconditioner is the ball's matrix and conjugate gradients stop after one iteration with the
    exact solution."""
    from posecrb.selection import _ballsolve
    from posecrb.selection.rounds import _csr, _pose_rows

    g = ts.chain_graph(np.random.default_rng(8), n=20, extra=10)
    obj = tree_objective(g)
    split = split_edges(g)
    x = np.zeros(g.m)
    x[split.fixed] = 1.0
    rows = _pose_rows(obj)
    ptr, to, ln = _csr(g.n, np.r_[g.src[split.fixed], g.dst[split.fixed]],
                       np.r_[g.dst[split.fixed], g.src[split.fixed]], np.ones(2 * split.fixed.size))
    poses, par = _ballsolve.ball(5, 5, np.inf, g.n, ptr, to, ln, np.full(g.n, np.inf), np.zeros(g.n, np.int64),
                             np.zeros(g.n, np.int64))
    assert poses.size == g.n
    mat = obj.blocks[0].matrix(x)
    lrow, lptr, cols, where = _ballsolve.ball_system(poses, rows, mat.indptr.astype(np.int64),
                                                 mat.indices.astype(np.int64), np.full(mat.shape[0], -1, np.int64))
    vals = mat.data[where]
    pivinv, up, ok = _ballsolve.tree_factor(lrow, par, 1, lptr, cols, vals)
    rhs = np.random.default_rng(0).standard_normal(lptr.size - 1)
    sol, its, conv = _ballsolve.pcg(lptr, cols, vals, lrow, par, pivinv, up, rhs, 1e-10, 50)
    local = sp.csr_matrix((vals, cols, lptr)).toarray()
    assert ok and conv and its == 1
    ref = np.linalg.solve(local, rhs)
    assert_within(sol, ref, MARGIN * spd_condition(local) * local.shape[0] * EPS * np.abs(ref).max(), "tree solve")


@pytest.mark.parametrize("kind", ["tree", "fim"])
def test_one_round_replays_the_first_order_woodbury_greedy(kind, monkeypatch):
    """With balls holding every pose the round's corrections are the first-order Woodbury terms of
    the round's first matrix: H_g -= C (I + H_f)^{-1} C^T, C = U_g^T M^{-1} U_f for each choice f,
    replayed here with dense numpy (the gains of the corrected H by the kernels' convention,
    ``posecrb.linalg.pathchol.logdet_eye_plus``: pivots of I + H below 1 count as 1)."""
    import posecrb.selection.rounds as rounds

    g = ts.chain_graph(np.random.default_rng(12), n=24, extra=30, dim=2)
    obj = _objective(kind, g)
    split = split_edges(g)
    x = np.zeros(g.m)
    x[split.fixed] = 1.0
    ce = split.candidates
    dense = [b.matrix(x).toarray() for b in obj.blocks]
    z = [np.linalg.solve(d, b.rhs(ce)) for d, b in zip(dense, obj.blocks)]
    r = obj.blocks[0].U.shape[2]
    cross = [(b.rhs(ce).T @ zb).reshape(ce.size, r, ce.size, r).transpose(0, 2, 1, 3) for b, zb in zip(obj.blocks, z)]
    hs = np.ascontiguousarray(np.stack([np.stack([c[i, i] for i in range(ce.size)]) for c in cross]))
    mult = np.array([b.mult for b in obj.blocks])

    from posecrb.linalg.pathchol import logdet_eye_plus

    def keys_of(h):
        return sum(m * logdet_eye_plus(np.ascontiguousarray(hb)) for m, hb in zip(mult, h))

    take = 8
    ref_h, ref_keys, alive, ref_order = hs.copy(), keys_of(hs), np.ones(ce.size, bool), []
    for step in range(take):
        f = int(np.flatnonzero(alive)[np.argmax(ref_keys[alive])])
        ref_order.append(f)
        alive[f] = False
        if step == take - 1:
            break
        for b in range(len(obj.blocks)):
            inv = np.linalg.inv(np.eye(r) + 0.5 * (ref_h[b, f] + ref_h[b, f].T))
            for gpos in np.flatnonzero(alive):
                c = cross[b][gpos, f]
                ref_h[b, gpos] -= c @ inv @ c.T
        ref_keys = keys_of(ref_h)

    monkeypatch.setattr(rounds, "CG_TOL", 1e-13)
    rows = rounds._pose_rows(obj)
    strength = np.ones(g.m)
    keys = keys_of(hs)
    order, stats = rounds._round(obj, x, ce, hs, keys, rows, strength, np.inf, take)
    assert ref_keys[ref_order[-1]] > 0.1 * ref_keys[ref_order[0]]     # choices not decided by rounding
    assert order.tolist() == ref_order
    assert stats[0] == take - 1 and stats[5] == 0
    left = np.setdiff1d(np.arange(ce.size), order)
    assert_within(keys[left], ref_keys[left], 1e-8 * np.abs(ref_keys).max(), "corrected gains")


# ----------------------------------------------------------------------------- the driver
def test_round_sizes_split_the_budget():
    from posecrb.selection.rounds import round_sizes

    assert round_sizes(10, 3) == [4, 3, 3]
    assert round_sizes(2, 5) == [1, 1]
    assert sum(round_sizes(19971, 24)) == 19971 and len(round_sizes(19971, 24)) == 24


@pytest.mark.parametrize("kind,dim,uniform", [("tree", 2, False), ("tree", 2, True), ("tree", 3, False),
                                              ("fim", 2, False), ("fim", 3, False)])
def test_one_choice_per_round_is_the_exact_greedy(kind, dim, uniform):
    """A round starts from exact gains, so with one choice per round the round greedy is the exact
    greedy (two Laplacian blocks, one, and the FIM's blocks of q columns)."""
    g = ts.chain_graph(np.random.default_rng(30 + dim), n=12, extra=30, dim=dim, uniform=uniform)
    if uniform:   # one block, with gains free of exact ties
        g = replace(g, info=g.info * (1.0 + 0.5 * np.random.default_rng(1).random(g.m))[:, None, None])
    ref = from_vertices(g)
    exact = select_edges(g, 9, objective=kind, strategy="incremental", reference=ref)
    rounds = select_edges(g, 9, objective=kind, strategy="rounds", rounds=9, reference=ref)
    assert rounds.order.tolist() == exact.order.tolist()
    assert rounds.stats["strategy"] == "rounds" and rounds.stats["local_solves"] == 0
    assert rounds.value == pytest.approx(exact.value, rel=1e-12)


@pytest.mark.parametrize("dim,objective,seed", [(2, "tree", 0), (2, "fim", 1), (3, "tree", 1), (3, "fim", 0)])
def test_values_and_bounds_stay_exact_whatever_the_choices(dim, objective, seed):
    """Two rounds of approximate choices: the value is the dense value of the chosen edges and every
    upper bound (the rounds' Minoux bounds and the one at the chosen set) is above the optimum."""
    rng = np.random.default_rng(200 + 10 * dim + seed)
    g = ts.chain_graph(rng, n=7, extra=10, dim=dim)
    ex = ts.Exhaustive(objective, g)
    for k in (3, 5):
        opt, _ = ex.best(k)
        res = select_edges(g, k, objective=objective, strategy="rounds", rounds=2, reference=from_vertices(g))
        assert res.value == pytest.approx(ts.dense_value(objective, g, res.kept_edges), rel=1e-9)
        assert res.value <= opt + 1e-9 * abs(opt)
        assert res.stats["online_bound"] >= opt - 1e-9 * abs(opt)
        assert res.upper_bound >= opt - 1e-9 * abs(opt)
        assert res.stats["round_sizes"] == [math.ceil(k / 2), k // 2]


def test_auto_takes_the_round_greedy_for_many_steps_on_large_graphs(monkeypatch):
    import posecrb.selection.greedy as greedy

    steps, poses = greedy.ROUNDS_FROM_STEPS, greedy.ROUNDS_FROM_POSES
    assert pick_strategy("auto", "auto", steps, poses) == "incremental"
    assert pick_strategy("auto", "auto", steps + 1, poses - 1) == "incremental"
    assert pick_strategy("auto", "exact", steps + 1, poses) == "rounds"
    assert pick_strategy("auto", "jl", steps + 1, poses) == "lazy"
    assert pick_strategy("incremental", "auto", 10 ** 9, 10 ** 9) == "incremental"
    g = ts.chain_graph(np.random.default_rng(5), n=14, extra=40)
    monkeypatch.setattr(greedy, "ROUNDS_FROM_STEPS", 9)
    monkeypatch.setattr(greedy, "ROUNDS_FROM_POSES", 14)
    assert select_edges(g, 9).stats["strategy"] == "incremental"
    res = select_edges(g, 10)
    assert res.stats["strategy"] == "rounds" and sum(res.stats["round_sizes"]) == 10


@pytest.mark.parametrize("keywords,msg", [({"rounds": 0}, "rounds"), ({"rounds": True}, "rounds"),
                                          ({"rounds": 2.5}, "rounds"), ({"strategy": "rounds", "gains": "jl"}, "lazy")])
def test_round_options_are_checked(keywords, msg):
    g = ts.chain_graph(np.random.default_rng(5), n=10, extra=20)
    with pytest.raises(UsageError, match=msg):
        select_edges(g, 5, **keywords)


@pytest.mark.parametrize("dim,side,objective", [(2, 50, "tree"), (3, 10, "tree"), (2, 22, "fim")])
def test_round_greedy_keeps_the_exact_greedys_certificate_on_grids(dim, side, objective):
    """The acceptance criterion in small: on full-lattice grids (every candidate's gain nearly the
    same, the round greedy's hardest case) the certified ratio is at least the exact greedy's minus
    0.01, and the value within 1% of the gain the exact greedy's bound leaves open."""
    g = grid(dim, side, noise=True, rng=1)
    ref = from_vertices(g) if objective == "fim" else None
    exact = select_edges(g, "20%", objective=objective, strategy="incremental", reference=ref)
    rounds = select_edges(g, "20%", objective=objective, strategy="rounds", reference=ref)
    assert rounds.stats["strategy"] == "rounds"
    if objective == "tree":   # the Fisher information's slower solves may stop at CG_MAX_ITER (counted)
        assert rounds.stats["cg_unconverged"] == 0
    assert rounds.certified_ratio >= exact.certified_ratio - 0.01
    assert rounds.value >= exact.value - 0.01 * (exact.upper_bound - exact.base_value)


def test_the_gains_option_and_the_flags_it_replaces(tmp_path, capsys):
    """--gains chooses the greedy; the 0.2 flags still work, with a warning naming the new form on
    stderr, and --gains with a flag is a usage error."""
    import json

    from posecrb.cli import main
    from posecrb.io import write_g2o

    from ..helpers import random_pose_graph

    path = tmp_path / "g.g2o"
    write_g2o(random_pose_graph(60, 2, np.random.default_rng(3), loop_closures=30)[0], str(path))
    runs = {}
    for argv in (["--gains", "exact"], ["--gains", "rounds"], ["--exact"], ["--lazy"], ["--gains", "lazy"]):
        assert main(["select", str(path), "--budget", "5", "--format", "json", *argv]) == 0
        out = capsys.readouterr()
        runs[" ".join(argv)] = json.loads(out.out)
        flag = argv[0] != "--gains"
        assert (f"{argv[0]} is deprecated: use --gains" in out.err) == flag
    assert runs["--gains rounds"]["stats"]["strategy"] == "rounds"
    assert runs["--exact"]["stats"]["strategy"] == runs["--gains exact"]["stats"]["strategy"] == "incremental"
    assert runs["--lazy"]["selected"] == runs["--gains lazy"]["selected"]
    assert main(["select", str(path), "--budget", "5", "--gains", "lazy", "--jl"]) == 2
    assert "--jl and --gains exclude each other" in capsys.readouterr().err
