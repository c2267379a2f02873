"""The information timeline: every row against a from-scratch dense computation of its prefix, the
last row against `bounds`, loop-closure gains against dense log-det differences, the real datasets,
the command line."""
from __future__ import annotations

import itertools
import json
import math
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from posecrb import load
from posecrb.core.errors import UsageError
from posecrb.core.graph import PoseGraph
from posecrb.core.noise import rotation_weights
from posecrb.evaluation.evaluate import EvaluationSettings, evaluate
from posecrb.incremental import TimelineResult, timeline, tracker
from posecrb.models.paper.bounds import compute_bounds
from posecrb.models.paper.fim import paper_fim

from ..helpers import component_count, make_random_graph, random_pose_graph, run_cli
from ..numerics import MARGIN, logdet_atol, sum_atol


# ------------------------------------------------------------------ independent references
def prefix(graph, t):
    """The graph on poses 0..t (internal indices) and the edges among them, with its vertices."""
    keep = (graph.src <= t) & (graph.dst <= t)
    return replace(graph, ids=graph.ids[: t + 1], src=graph.src[keep], dst=graph.dst[keep], rot=graph.rot[keep],
                   trans=graph.trans[keep], info=graph.info[keep],
                   vertex_rot=None if graph.vertex_rot is None else graph.vertex_rot[: t + 1],
                   vertex_trans=None if graph.vertex_trans is None else graph.vertex_trans[: t + 1],
                   edge_lines=None)


def dense_matrices(g, variant="consistent"):
    """Reduced L_tau, L_w, the ub matrix L_w (x) I + blkdiag(Psi) (anchor: pose 0), and the FIM at
    the graph's vertices, dense, one edge at a time from the paper's definitions."""
    n, d, dr = g.n, g.dim, g.rot_dim
    tau, w = g.tau, rotation_weights(g.kappa, d)
    lt, lw = np.zeros((n, n)), np.zeros((n, n))
    psi = np.zeros((n, dr, dr))
    for e in range(g.m):
        i, j = g.src[e], g.dst[e]
        for lap, x in ((lt, tau[e]), (lw, w[e])):
            lap[i, i] += x
            lap[j, j] += x
            lap[i, j] -= x
            lap[j, i] -= x
        p = g.trans[e]
        psi[i] += tau[e] * (p @ p) if d == 2 else 0.5 * tau[e] * ((p @ p) * np.eye(3) - np.outer(p, p))
    lt, lw = lt[1:, 1:], lw[1:, 1:]
    m = np.kron(lw, np.eye(dr))
    for i in range(1, n):
        m[(i - 1) * dr: i * dr, (i - 1) * dr: i * dr] += psi[i]
    fim = None
    if g.vertex_rot is not None:
        fim = paper_fim(g, g.vertex_rot, g.vertex_trans, variant=variant).matrix.toarray()
    return lt, lw, m, fim


def logdet(a):
    sign, value = np.linalg.slogdet(a)       # LU: independent of the Cholesky code under test
    assert sign > 0
    return value


def reference_rows(g, variant="consistent"):
    """Per prefix t (1..n-1): None when disconnected, else (lb, ub, t_opt_graph, fim_logdet, tolerances)."""
    d, dr = g.dim, g.rot_dim
    # the timeline factors matrices of the size of the whole graph: their rounding counts too
    # (of the largest connected prefix when the whole graph is disconnected)
    last = max(t for t in range(1, g.n) if component_count(prefix(g, t)) == 1)
    whole_tol = [logdet_atol(a) for a in dense_matrices(prefix(g, last), variant) if a is not None]
    out = {}
    for t in range(1, g.n):
        s = prefix(g, t)
        if component_count(s) != 1:
            out[t] = None
            continue
        lt, lw, m, fim = dense_matrices(s, variant)
        tol_lb = d * logdet_atol(lt) + dr * logdet_atol(lw) + (d + dr) * max(whole_tol)
        tol_ub = d * logdet_atol(lt) + logdet_atol(m) + (d + 1) * max(whole_tol)
        trace = d * np.trace(lt) + dr * np.trace(lw)
        out[t] = {"lb": (d * logdet(lt) + dr * logdet(lw), tol_lb),
                  "ub": (d * logdet(lt) + logdet(m), tol_ub),
                  "t_opt_graph": (trace, sum_atol(np.concatenate([np.diag(lt), np.diag(lw)]) * (d + dr)))}
        if fim is not None:
            out[t]["fim_logdet"] = (logdet(fim), logdet_atol(fim) + max(whole_tol))
    return out


def check_rows(res, ref):
    seen = 0
    for row in res.row_dicts():
        t = row["poses"] - 1
        if ref[t] is None:
            assert row["components"] > 1 and row["status"]["status"] == "unavailable"
            assert all(row[k] is None for k in ("lb", "ub", "t_opt_graph", "gain"))
            continue
        assert row["components"] == 1 and "status" not in row
        for key, (value, tol) in ref[t].items():
            assert abs(row[key] - value) <= tol, (row["poses"], key, row[key], value, tol)
        seen += 1
    return seen


def graphs(dim):
    """Random graphs: a random spanning tree in random id order (prefixes often disconnected,
    parallel edges, ids with gaps, anisotropic information, random edge directions) and an odometry
    chain with random loop closures."""
    rng = np.random.default_rng(7 + dim)
    out = [make_random_graph(rng, n=10, extra=7, dim=dim) for _ in range(3)]
    out += [random_pose_graph(12, dim, rng, loop_closures=9, rot_noise=0.05, trans_noise=0.1)[0] for _ in range(3)]
    return out


# ------------------------------------------------------------------ small random graphs
@pytest.mark.parametrize("dim", [2, 3])
def test_every_row_equals_a_dense_computation_of_its_prefix(dim):
    total = 0
    for g in graphs(dim):
        res = timeline(g, estimate="vertices")
        total += check_rows(res, reference_rows(g))
        assert res.rows.poses.tolist() == list(range(2, g.n + 1))
    assert total > 30


def test_eq64_variant_in_3d():
    g = graphs(3)[4]
    res = timeline(g, estimate="vertices", fim_variant="eq64")
    check_rows(res, reference_rows(g, "eq64"))
    assert res.fim_variant == "eq64"


def test_last_row_equals_bounds_and_the_fim_at_the_same_estimate():
    for dim in (2, 3):
        for g in graphs(dim)[3:]:
            res = timeline(g, estimate="vertices")
            last = res.row_dicts()[-1]
            b = compute_bounds(g)
            m = evaluate(g, EvaluationSettings(estimate="vertices"))
            lt, lw, mm, fim = dense_matrices(g)
            tol = MARGIN * max(logdet_atol(a) for a in (lt, lw, mm, fim))
            assert abs(last["lb"] - b.lb) <= tol
            assert abs(last["ub"] - b.ub) <= tol
            assert abs(last["t_opt_graph"] - b.t_opt_graph) <= sum_atol([b.t_opt_graph] * g.m)
            assert abs(last["fim_logdet"] - m.result.fim_logdet) <= tol


def _processing_order(g):
    """Edges in the order the timeline adds them: by newer pose, the edge to the largest older id
    (first in file order) first, then the others in file order; and which ones are loop closures."""
    order, closure = [], []
    for t in range(1, g.n):
        edges = [e for e in range(g.m) if max(g.src[e], g.dst[e]) == t]
        if not edges:
            continue
        first = max(edges, key=lambda e: (min(g.src[e], g.dst[e]), -e))
        order += [first] + [e for e in edges if e != first]
        closure += [False] + [True] * (len(edges) - 1)
    return order, closure


def test_loop_closure_gains_are_sequential_increases_of_lb():
    for dim in (2, 3):
        for g in graphs(dim):
            res = timeline(g, estimate="none")
            order, closure = _processing_order(g)
            gains = [c.gain for c in res.closures]
            expected = []
            for k, e in enumerate(order):
                if not closure[k]:
                    continue
                before = replace(g, src=g.src[order[:k]], dst=g.dst[order[:k]], rot=g.rot[order[:k]],
                                 trans=g.trans[order[:k]], info=g.info[order[:k]])
                t = max(g.src[e], g.dst[e])
                pre, post = prefix(before, t), prefix(replace(g, src=g.src[order[: k + 1]], dst=g.dst[order[: k + 1]],
                                                              rot=g.rot[order[: k + 1]], trans=g.trans[order[: k + 1]],
                                                              info=g.info[order[: k + 1]]), t)
                if component_count(pre) != 1:
                    expected.append(None)
                    continue
                a, b = dense_matrices(pre)[:2], dense_matrices(post)[:2]
                lb = [g.dim * logdet(x[0]) + g.rot_dim * logdet(x[1]) for x in (a, b)]
                tol = 2 * g.dim * max(logdet_atol(x) for x in (*a, *b))
                expected.append((lb[1] - lb[0], tol))
            assert len(gains) == len(expected)
            for got, exp in zip(gains, expected, strict=True):
                if exp is None:
                    assert got is None
                else:
                    assert abs(got - exp[0]) <= exp[1]
            # a step's gain is the sum of its loop closures' gains
            for row in res.row_dicts():
                if row["gain"] is not None:
                    mine = [c.gain for c in res.closures if c.poses == row["poses"]]
                    assert row["gain"] == pytest.approx(sum(mine), abs=sum_atol(mine) + 0.0)
                    assert row["loop_closures"] == len(mine)


def test_drift_fallback_recomputes_segments_down_to_single_steps(monkeypatch):
    monkeypatch.setattr(tracker, "drift_tolerance", lambda level, *a: np.full(level.shape, -1.0))
    g = graphs(2)[4]
    res = timeline(g, estimate="vertices")
    check_rows(res, reference_rows(g))
    # no drift is accepted: every segment shrinks to a single step, whose row is the fresh value
    assert res.checks["L_tau"]["checkpoints"] == g.n - 1


# ------------------------------------------------------------------ the drift tolerance on long chains
def _chain(n, tau):
    """A 2D chain of n poses (odometry only) with edge precisions ``tau`` (kappa = tau / 2, so
    L_w = L_tau) and the prefix lb of every step in exact arithmetic of the rounded logs: on a tree
    the reduced Laplacian's determinant is the product of the edge weights."""
    rng = np.random.default_rng(7)
    th = rng.uniform(-0.3, 0.3, n - 1)
    rot = np.stack([np.stack([np.cos(th), -np.sin(th)], -1), np.stack([np.sin(th), np.cos(th)], -1)], -2)
    info = np.zeros((n - 1, 3, 3))
    info[:, 0, 0] = info[:, 1, 1] = tau
    info[:, 2, 2] = tau / 2
    g = PoseGraph(dim=2, ids=np.arange(n), src=np.arange(n - 1), dst=np.arange(1, n), rot=rot,
                  trans=rng.normal(size=(n - 1, 2)), info=info, format="synthetic")
    per_edge = 3 * np.log(g.tau)                      # d log tau + d_r log w, w = 2 kappa = tau
    lb = np.array([float(x) for x in itertools.accumulate(Fraction(v) for v in per_edge)])
    return g, lb


def test_drift_tolerance_follows_the_rounding_of_the_sums_on_a_long_chain():
    # 20,000 poses whose closed forms are tiny for the first 6,000 steps (tau = 1.001) and
    # log 50 after: the suffix sums add the small ones onto a large partial sum, and every
    # addition rounds the same way. A tolerance from the factorization alone (plus eps times the
    # values) is below that rounding: segments halve down to single steps and the drift is
    # reported as a warning.
    n = 20_000
    tau = np.full(n - 1, 50.0)
    tau[: 6000] = 1.001
    g, exact_lb = _chain(n, tau)
    res = timeline(g, estimate="none")
    assert res.lb_status.ok and res.ub_status.ok
    checks = res.checks["L_tau"]
    assert checks["checkpoints"] <= tracker.FIRST_SEGMENTS       # no halving: the first, then doubling
    assert checks["max_drift"] <= checks["tolerance"]
    # every row within the tolerance of the exact prefix lb (lb = 3 logdet L_tau here)
    assert np.max(np.abs(res.rows.lb - exact_lb)) <= 3 * checks["tolerance"]
    # the tolerance is the rounding of sums of n terms: of the order of n u sum |terms|, no looser
    terms = np.abs(np.log(g.tau)).sum()
    assert checks["tolerance"] <= 8 * tracker.SUM_MARGIN * n * np.finfo(float).eps * terms


@pytest.mark.parametrize("kind", ["equal", "small onto large", "alternating"])
def test_running_error_bounds_hold_against_exact_sums(kind):
    rng = np.random.default_rng(11)
    n = 20_000
    x = {"equal": np.full(n, 0.1),
         "small onto large": np.r_[np.full(n // 4, 1e-3), rng.uniform(3, 4, n - n // 4)],
         "alternating": rng.uniform(1, 2, n) * np.where(np.arange(n) % 2, 1e8, -1e8)}[kind]
    suffix, bound = tracker._suffix(x)
    exact = list(itertools.accumulate(Fraction(v) for v in x[::-1]))[::-1][1:] + [Fraction(0)]
    error = np.array([abs(Fraction(s) - e) for s, e in zip(suffix.tolist(), exact, strict=True)], dtype=float)
    assert np.all(error <= bound)
    assert error.max() > 0                                   # the sums do round: the test can fail
    assert bound.max() <= n * np.finfo(float).eps * np.abs(x).sum()    # never looser than the a priori bound
    # a log-det summed in any order (numpy's pairwise sum here)
    logs = np.log(rng.uniform(0.01, 100, n))
    assert abs(float(np.sum(logs)) - math.fsum(logs)) <= tracker._logdet_sum_error(logs)


def test_every_from_to_select_rows_of_the_same_computation():
    g = graphs(2)[3]
    full = {r["poses"]: r for r in timeline(g, estimate="vertices").row_dicts()}
    part = timeline(g, estimate="vertices", every=3, start=4, stop=11)
    assert part.rows.poses.tolist() == [4, 7, 10, 11]
    tol = max(c["tolerance"] for c in part.checks.values()) + max(c["tolerance"] for c in
                                                                 timeline(g, estimate="vertices").checks.values())
    for row in part.row_dicts():
        for key in ("lb", "ub", "fim_logdet", "gain", "t_opt_graph"):
            assert row[key] == pytest.approx(full[row["poses"]][key], abs=tol + 1e-300)
    assert (part.first, part.last, part.every) == (4, 11, 3)
    assert all(4 <= c.poses <= 11 for c in part.closures)


@pytest.mark.parametrize("kwargs", [{"every": 0}, {"start": 1}, {"stop": 13}, {"start": 6, "stop": 5},
                                    {"every": 1.5}, {"estimate": ""}, {"fim_variant": "x"}])
def test_bad_arguments_are_usage_errors(kwargs):
    g = graphs(2)[3]
    with pytest.raises(UsageError):
        timeline(g, **{"estimate": "none", **kwargs})


def test_two_poses_and_parallel_edges():
    g = random_pose_graph(2, 2, np.random.default_rng(1), loop_closures=0)[0]
    two = replace(g, src=np.r_[g.src, g.dst], dst=np.r_[g.dst, g.src], rot=np.r_[g.rot, np.swapaxes(g.rot, 1, 2)],
                  trans=np.r_[g.trans, -g.trans], info=np.r_[g.info, g.info])
    res = timeline(two, estimate="vertices")
    assert res.rows.poses.tolist() == [2] and res.rows.loop_closures.tolist() == [1]
    check_rows(res, reference_rows(two))
    assert res.closures[0].gain == pytest.approx(res.rows.gain[0])


def test_whole_graph_disconnected_keeps_the_connected_prefixes():
    g = random_pose_graph(12, 3, np.random.default_rng(3), loop_closures=6)[0]
    cut = ~((np.maximum(g.src, g.dst) >= 9) & (np.minimum(g.src, g.dst) < 9))    # poses 9..11 on their own
    g = replace(g, src=g.src[cut], dst=g.dst[cut], rot=g.rot[cut], trans=g.trans[cut], info=g.info[cut])
    assert component_count(g) == 2
    res = timeline(g, estimate="vertices")
    assert check_rows(res, reference_rows(g)) == 8
    assert res.rows.components[-1] == 2


def test_a_range_in_which_every_prefix_is_disconnected_is_unavailable_not_clean(tmp_path, capsys):
    """`timeline disc.g2o --estimate none --from 3` said "monotone: yes" for every metric, with status
    ok, no statuses and an empty figure: every prefix of that range is disconnected, so it has no value."""
    disc = tmp_path / "disc.g2o"
    disc.write_text("EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000\nEDGE_SE2 2 3 1 0 0 100 0 0 100 0 1000\n"
                    "EDGE_SE2 3 4 1 0 0 100 0 0 100 0 1000\n")
    res = timeline(load(disc), estimate="none", start=3)
    assert res.rows.components.tolist() == [2, 2, 2]
    assert res.status.state == "unavailable" and "has no values" in res.lb_status.reason
    assert {m: {s: v.monotone for s, v in d.items()} for m, d in res.monotonicity.items()} == \
        {m: {"raw": None, "per_dimension": None} for m in ("lb", "ub", "t_opt_graph")}
    assert TimelineResult.from_dict(res.to_dict()).status == res.status
    figure = tmp_path / "disc.png"
    code, out, err = run_cli(["timeline", str(disc), "--estimate", "none", "--from", "3", "--format", "json",
                              "--plot", str(figure)], capsys)
    d = json.loads(out)
    assert code == 0 and set(d["statuses"]) == {"lb", "ub"} and "has no values" in err
    assert not figure.exists() and f"no figure written to {figure}" in err
    # a range with values keeps its statuses clean
    assert timeline(load(disc), estimate="none", stop=2).status.ok


def test_protocol_round_trip_and_frames():
    g = graphs(3)[0]
    res = timeline(g, estimate="vertices")
    d = res.to_dict()
    again = TimelineResult.from_dict(json.loads(json.dumps(d)))
    assert again.to_dict() == d
    frame = res.to_frame()
    assert list(frame.columns) == ["poses", "pose", "edges", "loop_closures", "components", "lb", "ub",
                                   "t_opt_graph", "fim_logdet", "gain"]
    assert len(frame) == len(d["rows"])
    assert len(res.closures_frame()) == len(d["loop_closures"])
    assert d["rows"][0]["pose"] == int(g.ids[1]) and d["anchor"] == int(g.ids[0])


def test_monotonicity_against_the_rows():
    g = graphs(2)[3]
    res = timeline(g, estimate="vertices")
    rows = res.row_dicts()
    q = g.q
    for metric in ("lb", "ub", "t_opt_graph", "fim_logdet"):
        for scale in ("raw", "per_dimension"):
            vals = [(r["poses"], r[metric] / (1 if scale == "raw" else q * (r["poses"] - 1))) for r in rows]
            drops = [k for (_, a), (k, b) in zip(vals, vals[1:]) if b < a]
            mono = res.monotonicity[metric][scale]
            assert mono.decreases == len(drops) and mono.monotone == (not drops)
            if drops:
                assert mono.first["poses"] == drops[0]


# ------------------------------------------------------------------ real datasets
def _real(shared_datasets, name):
    path = shared_datasets / f"{name}.g2o"
    if not path.is_file():
        pytest.skip(f"{name}.g2o not in $POSECRB_DATA")
    return load(str(path))


@pytest.mark.slow
def test_intel_prefixes_against_dense_and_bounds(shared_datasets):
    g = _real(shared_datasets, "intel")
    res = timeline(g, estimate="vertices")
    rows = {r["poses"]: r for r in res.row_dicts()}
    for k in (2, 60, 271, 700):
        s = prefix(g, k - 1)
        lt, lw, m, fim = dense_matrices(s)
        assert rows[k]["lb"] == pytest.approx(2 * logdet(lt) + logdet(lw), abs=2 * logdet_atol(lt) + logdet_atol(lw))
        assert rows[k]["ub"] == pytest.approx(2 * logdet(lt) + logdet(m), abs=2 * logdet_atol(lt) + logdet_atol(m))
        assert rows[k]["fim_logdet"] == pytest.approx(logdet(fim), abs=logdet_atol(fim))
    b = compute_bounds(g)
    last = rows[g.n]
    tol = res.checks["L_tau"]["tolerance"] + res.checks["ub"]["tolerance"]
    assert last["lb"] == pytest.approx(b.lb, abs=tol) and last["ub"] == pytest.approx(b.ub, abs=tol)
    assert last["t_opt_graph"] == pytest.approx(b.t_opt_graph, abs=sum_atol([b.t_opt_graph] * g.m))
    m = evaluate(g, EvaluationSettings(estimate="vertices"))
    assert last["fim_logdet"] == pytest.approx(m.result.fim_logdet, abs=res.checks["fim"]["tolerance"])
    # every 100th prefix against bounds from scratch (sparse Cholesky), to the timeline's tolerance
    for k in range(100, g.n, 100):
        bk = compute_bounds(prefix(g, k - 1))
        assert rows[k]["lb"] == pytest.approx(bk.lb, abs=tol)
        assert rows[k]["ub"] == pytest.approx(bk.ub, abs=tol)
    assert all(c["max_drift"] <= c["tolerance"] for c in res.checks.values())


@pytest.mark.slow
def test_cubicle_disconnected_prefixes(shared_datasets):
    g = _real(shared_datasets, "cubicle")
    res = timeline(g, estimate="none")
    # independent count: components of every prefix by union-find over the edges in step order
    parent = list(range(g.n))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    hi = np.maximum(g.src, g.dst)
    comps, expected, k = 0, [], 0
    order = np.argsort(hi, kind="stable")
    for t in range(g.n):
        comps += 1
        while k < g.m and hi[order[k]] == t:
            a, b = find(g.src[order[k]]), find(g.dst[order[k]])
            if a != b:
                parent[a] = b
                comps -= 1
            k += 1
        expected.append(comps)
    assert res.rows.components.tolist() == expected[1:]
    rows = res.row_dicts()
    bad = [r for r in rows if r["components"] > 1]
    assert len(bad) == sum(c > 1 for c in expected[1:]) >= 1
    assert all(r["lb"] is None and r["status"]["status"] == "unavailable" for r in bad)
    after = rows[rows.index(bad[-1]) + 1]
    assert after["gain"] is None and after["gain_status"]["status"] == "unavailable"
    b = compute_bounds(prefix(g, after["poses"] - 1))
    tol = res.checks["L_tau"]["tolerance"] + res.checks["L_w"]["tolerance"] + res.checks["ub"]["tolerance"]
    assert after["lb"] == pytest.approx(b.lb, abs=tol) and after["ub"] == pytest.approx(b.ub, abs=tol)


# ------------------------------------------------------------------ command line
@pytest.fixture
def g2o_file(tmp_path):
    from posecrb.io import write_g2o

    g = graphs(2)[3]
    path = tmp_path / "g.g2o"
    write_g2o(g, path)
    return path


def test_cli_json_equals_to_dict(g2o_file, capsys):
    code, out, _ = run_cli(["timeline", str(g2o_file), "--estimate", "vertices", "--format", "json"], capsys)
    assert code == 0
    got = json.loads(out)
    want = timeline(load(str(g2o_file)), estimate="vertices").to_dict()
    got.pop("times")
    want.pop("times")
    assert got == json.loads(json.dumps(want))


def test_cli_formats_and_plot(g2o_file, tmp_path, capsys):
    code, out, _ = run_cli(["timeline", str(g2o_file), "--estimate", "none"], capsys)
    assert code == 0 and "lb" in out and "Top" in out
    code, out, _ = run_cli(["timeline", str(g2o_file), "--estimate", "none", "--format", "csv", "--every", "5"],
                           capsys)
    lines = out.strip().splitlines()
    assert code == 0 and lines[0].startswith("poses,pose,edges") and len(lines) == 1 + 3
    code, out, _ = run_cli(["timeline", str(g2o_file), "--estimate", "none", "--format", "markdown", "--from", "3",
                            "--to", "4"], capsys)
    assert code == 0 and out.count("\n") == 2 + 2
    fig = tmp_path / "out" / "t.png"
    fig.parent.mkdir()
    code, _, _ = run_cli(["timeline", str(g2o_file), "--estimate", "none", "--plot", str(fig)], capsys)
    assert code == 0 and fig.stat().st_size > 0


@pytest.mark.parametrize("args,code", [
    (["--every", "0"], 2), (["--from", "1"], 2), (["--from", "6", "--to", "5"], 2), (["--to", "13"], 2),
    (["--format", "latex"], 2), (["--plot", "x.txt"], 2),
])
def test_cli_bad_options(g2o_file, capsys, args, code):
    got, _, err = run_cli(["timeline", str(g2o_file), "--estimate", "none", *args], capsys)
    assert got == code, err
    assert f"'{args[0]}'" in err or f"{args[0]} " in err      # the option is named, as the user wrote it


def test_library_range_errors_name_the_keyword(g2o_file):
    """The library says start=/stop=; the command line says --from/--to (tested above)."""
    import posecrb

    with pytest.raises(posecrb.ArgumentError, match=r"^start=6 is after the last step asked for \(5 poses\)"):
        posecrb.timeline(g2o_file, estimate="none", start=6, stop=5)
    with pytest.raises(posecrb.ArgumentError, match=r"^every=0 "):
        posecrb.timeline(g2o_file, estimate="none", every=0)


def test_cli_plot_onto_the_input_is_refused(g2o_file, tmp_path, capsys):
    png = tmp_path / "g.png"
    png.write_bytes(b"not a figure, an input")
    code, _, err = run_cli(["timeline", str(g2o_file), "--estimate", str(png), "--plot", str(png)], capsys)
    assert code == 2 and "--plot" in err
    code, _, err = run_cli(["timeline", str(g2o_file), "--estimate", "none", "--plot", str(g2o_file)], capsys)
    assert code == 2 and "--plot" in err
    assert png.read_bytes() == b"not a figure, an input"


def test_cli_bad_input_files(tmp_path, capsys):
    code, _, err = run_cli(["timeline", str(tmp_path / "missing.g2o")], capsys)
    assert code == 1 and "missing.g2o" in err
    bad = tmp_path / "bad.g2o"
    bad.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 x\n")
    code, _, err = run_cli(["timeline", str(bad), "--estimate", "none"], capsys)
    assert code == 1 and "bad.g2o:3" in err
    one = tmp_path / "one.g2o"
    one.write_text("VERTEX_SE2 0 0 0 0\n")
    code, _, err = run_cli(["timeline", str(one), "--estimate", "none"], capsys)
    assert code != 0

