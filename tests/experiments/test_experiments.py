"""Experiments: CRLB sweep, thesis case study, octagon; CLI wiring.

References: closed forms for the error coordinates, a dense from-scratch FIM of the simulated
model, numpy pinv, finite differences of the thesis log-likelihood, the noise-free solver output.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from posecrb.core.errors import UsageError
from posecrb.experiments.crlb_sweep import crlb_sweep, parse_levels, pose_errors, rotation_errors
from posecrb.lie.so import so2_exp, so3_exp, so3_hat
from posecrb.models.paper.fim import paper_fim
from posecrb.sim import generators as synth
from posecrb.sim.random_graphs import random_graph
from posecrb.solver.rounding import anchor_estimate


# ---------------------------------------------------------------- crlb sweep
def test_parse_levels():
    assert parse_levels("20") == [20.0]
    assert parse_levels("1,5,20") == [1.0, 5.0, 20.0]
    assert parse_levels("1:20") == [float(k) for k in range(1, 21)]
    assert parse_levels("1:2:0.5") == [1.0, 1.5, 2.0]
    assert parse_levels("5, 1:2") == [1.0, 2.0, 5.0]
    for bad in ["", "0", "-1", "a", "3:1", "1:2:0", "1:2:3:4"]:
        with pytest.raises(UsageError):
            parse_levels(bad)


def test_error_coordinates_match_the_fim_perturbation():
    rng = np.random.default_rng(0)
    # 2D: R_est = R_true Exp(theta E) -> error theta
    rt = so2_exp(rng.uniform(-3, 3, 4))
    th = rng.normal(scale=0.1, size=4)
    assert np.allclose(rotation_errors(rt, rt @ so2_exp(th))[:, 0], th)
    # 3D: R_est = R_true Exp(phi_k E_k), E_k = G_k / sqrt 2 -> rotation vector phi / sqrt 2
    r3 = so3_exp(rng.normal(size=(4, 3)))
    phi = rng.normal(scale=0.1, size=(4, 3))
    assert np.allclose(rotation_errors(r3, r3 @ so3_exp(phi / np.sqrt(2))), phi)
    # errors do not depend on the gauge of the estimate
    tt = rng.normal(size=(4, 3))
    te = tt + rng.normal(scale=0.01, size=(4, 3))
    g_r, g_t = so3_exp(np.array([0.3, -1.0, 2.0])), np.array([5.0, -2.0, 1.0])
    e1 = pose_errors(r3, tt, r3 @ so3_exp(phi), te, 1)
    e2 = pose_errors(r3, tt, g_r @ r3 @ so3_exp(phi), te @ g_r.T + g_t, 1)
    assert np.allclose(e1[0], e2[0]) and np.allclose(e1[1], e2[1])
    ar, at = anchor_estimate(r3, tt, 2)
    assert np.allclose(ar[2], np.eye(3)) and np.allclose(at[2], 0)


def _dense_model_fim(g, rot, trans, anchor):
    """From scratch: body-frame Jacobians of translation and relative-rotation residuals."""
    n, tau, w = g.n, g.tau, g.rotation_weights
    f = np.zeros((6 * n, 6 * n))
    for k, (i, j) in enumerate(zip(g.src, g.dst)):
        u = rot[i].T @ (trans[j] - trans[i])
        jac = np.zeros((6, 6 * n))
        jac[:3, 6 * i:6 * i + 3], jac[:3, 6 * j:6 * j + 3] = -rot[i].T, rot[i].T
        jac[:3, 6 * i + 3:6 * i + 6] = so3_hat(u) / np.sqrt(2)
        jac[3:, 6 * j + 3:6 * j + 6], jac[3:, 6 * i + 3:6 * i + 6] = np.eye(3), -(rot[i].T @ rot[j]).T
        f += jac.T @ np.diag([tau[k]] * 3 + [w[k]] * 3) @ jac
    keep = np.ones(6 * n, bool)
    keep[6 * anchor:6 * anchor + 6] = False
    return f[np.ix_(keep, keep)]


def test_consistent_fim_is_the_simulated_models_fim():
    """The sweep's model bound comes from paper_fim(variant="consistent"): against the
    analytic dense reference above (the FD reference is in tests/models/test_fim.py)."""
    g = random_graph(np.random.default_rng(1), 7, 12, 3, info="isotropic")
    rng = np.random.default_rng(2)
    rot, trans = so3_exp(rng.normal(size=(g.n, 3))), rng.normal(size=(g.n, 3))
    for anchor in (0, 3):
        fc = paper_fim(g, rot, trans, anchor, variant="consistent").to_layout("poses").matrix.toarray()
        assert np.allclose(fc, _dense_model_fim(g, rot, trans, anchor), atol=1e-9 * np.abs(fc).max())
    # same trace as eq. (64) as printed (T-optimality unaffected); 2D is the same matrix
    assert np.isclose(paper_fim(g, rot, trans, variant="consistent").matrix.diagonal().sum(),
                      paper_fim(g, rot, trans).matrix.diagonal().sum())
    g2 = synth.octagon([(1, 3), (2, 6)], radius=0.5)
    a = paper_fim(g2, g2.vertex_rot, g2.vertex_trans, variant="consistent").matrix
    b = paper_fim(g2, g2.vertex_rot, g2.vertex_trans).matrix
    assert abs(a - b).max() == 0


@pytest.mark.parametrize("variant", ["consistent", "eq64"])
def test_sweep_bounds_come_from_the_chosen_variant(variant):
    """mse_bound* = paper_crlb of the scaled noise model with the chosen FIM variant (default:
    the model's Fisher information); the variants differ in 3D."""
    from posecrb.experiments.crlb_sweep import _bounds
    from posecrb.models.paper.crlb import paper_crlb
    from posecrb.sim.sampling import noise_model_graph

    g = synth.grid(3, 2, tau=100.0, kappa=200.0, orientation="random", rng=3)
    rot, trans = anchor_estimate(g.vertex_rot, g.vertex_trans, 0)
    b = _bounds(g, rot, trans, 0, 5.0, "both", None, None, variant)
    model = noise_model_graph(g, 5.0, "both", None, None)
    res = paper_crlb(model, rot, trans, anchor=0, variant=variant)
    assert b["mse_bound"] == res.trace_crlb / (g.n - 1)
    assert b["mse_bound_curvature"] == res.trace_crlb_curvature / (g.n - 1)
    other = _bounds(g, rot, trans, 0, 5.0, "both", None, None, "eq64" if variant == "consistent" else "consistent")
    assert abs(other["mse_bound"] / b["mse_bound"] - 1) > 1e-2     # the variants differ in 3D
    assert _bounds(g, rot, trans, 0, 5.0, "both", None, None)["mse_bound"] == (
        b["mse_bound"] if variant == "consistent" else other["mse_bound"])


@pytest.mark.parametrize("dim", [2, 3])
def test_crlb_sweep_reaches_the_bound_on_a_small_grid(dim):
    """MSE of the certified MLE vs the CRLB at high SNR (independent MC check of the whole chain)."""
    g = synth.grid(dim, 3 if dim == 2 else 2, tau=100.0, kappa=200.0, orientation="random", rng=3)
    res = crlb_sweep(g, [10.0], trials=60, seed=4, truth=(g.vertex_rot, g.vertex_trans))
    lv = res.levels[0]
    assert lv.uncertified == 0 and lv.fim_variant == "consistent" and res.fim_variant == "consistent"
    # 3 standard errors plus 10% of second-order effects
    tol = 3 * lv.mse_stderr / lv.mse_bound + 0.1
    assert abs(lv.ratio - 1) < tol
    if dim == 2:
        eq64 = crlb_sweep(g, [10.0], trials=2, seed=4, truth=(g.vertex_rot, g.vertex_trans), fim_variant="eq64")
        assert eq64.levels[0].mse_bound == lv.mse_bound      # one matrix in 2D


@pytest.mark.slow
def test_crlb_sweep_bit_identical_across_executors():
    g = synth.grid(2, 3, tau=100.0, kappa=200.0)
    truth = (g.vertex_rot, g.vertex_trans)
    a = crlb_sweep(g, [2.0, 5.0], trials=6, seed=9, truth=truth)
    b = crlb_sweep(g, [2.0, 5.0], trials=6, seed=9, truth=truth, executor="local", jobs=2)
    c = crlb_sweep(g, [5.0], trials=6, seed=9, truth=truth)            # a level alone: same trials
    for kc in (2.0, 5.0):
        assert np.array_equal(a.trial_data[kc]["sq_trans"], b.trial_data[kc]["sq_trans"])
        assert np.array_equal(a.trial_data[kc]["sq_rot"], b.trial_data[kc]["sq_rot"])
    assert np.array_equal(a.trial_data[5.0]["sq_rot"], c.trial_data[5.0]["sq_rot"])
    assert a.rows() == b.rows()


# ---------------------------------------------------------------- thesis
def test_thesis_bounds_and_mle_on_noise_free_data():
    from posecrb.experiments import thesis as th
    from posecrb.models.sed.example import ANCHORS, left_information, thesis_graph, true_poses

    fm, anch, quot, nb = th.thesis_bounds(3)
    assert np.allclose(quot, np.linalg.pinv(fm, rcond=1e-10), atol=1e-10 * np.abs(quot).max())
    ev = np.linalg.eigvalsh(fm)
    assert np.sum(np.abs(ev) < 1e-9 * ev.max()) == 6
    assert np.allclose(fm @ nb, 0, atol=1e-9 * ev.max())
    # noise-free measurements: the anchored MLE is the truth
    g = thesis_graph()
    rt, tt = true_poses()
    mle = th.anchored_mle(g, left_information(), ANCHORS, rt, tt)
    assert mle.converged and np.allclose(mle.rot, rt, atol=1e-10) and np.allclose(mle.trans, tt, atol=1e-10)


def test_thesis_gradient_matches_finite_differences():
    from posecrb.experiments import thesis as th
    from posecrb.models.sed.example import left_information, sample_graph, true_poses

    g = sample_graph(np.random.default_rng(5), 2)
    omega = np.repeat(left_information(), 2, axis=0)
    rt, tt = true_poses()
    dofs = np.arange(15)
    cost, grad, hess = th._cost_grad_hess(g, omega, rt, tt, dofs)
    h = 1e-6
    num = np.zeros(15)
    for k in range(15):
        d = np.zeros(15)
        d[k] = h
        cp = th._cost_grad_hess(g, omega, *th._retract(rt, tt, d.reshape(5, 3)), dofs)[0]
        cm = th._cost_grad_hess(g, omega, *th._retract(rt, tt, -d.reshape(5, 3)), dofs)[0]
        num[k] = (cp - cm) / (2 * h)
    assert np.allclose(grad, num, rtol=1e-5, atol=1e-6 * np.abs(num).max())
    assert np.allclose(hess, hess.T)


@pytest.mark.slow
def test_thesis_quick_experiment_converges_with_m():
    from posecrb.experiments.thesis import horizontal_errors, thesis_experiment

    res = thesis_experiment([1, 10, 100], trials=60, seed=1)
    for form in ("anchored", "quotient"):
        rows = [r for r in res.table if r.formulation == form]
        frob = [r.frob for r in rows]
        assert frob[0] > frob[1] > frob[2]
        assert all(r.nullity == 6 and r.not_converged == 0 for r in rows)
        assert all(r.frob_rel < 3 * r.frob_rel_noise for r in rows)   # efficient at MC precision
    # horizontal errors: zero mean per component
    rng = np.random.default_rng(0)
    rt = so2_exp(rng.uniform(-1, 1, 5))
    tt = rng.normal(size=(5, 2))
    re_ = rt @ so2_exp(rng.normal(scale=0.1, size=5))
    te = tt + rng.normal(scale=0.1, size=(5, 2))
    labels = np.array([0, 0, 1, 1, 1])
    e = horizontal_errors(rt, tt, re_, te, labels)
    assert np.allclose(e[:2].sum(0), 0, atol=1e-12) and np.allclose(e[2:].sum(0), 0, atol=1e-12)


# ---------------------------------------------------------------- octagon
def test_octagon_t_vs_d_optimality():
    from posecrb.experiments.octagon import octagon_experiment

    res = octagon_experiment(trials=4, seed=0)
    assert [lv.extra_edges for lv in res.levels] == list(range(22))
    assert res.levels[0].graphs == 1 and res.levels[-1].graphs == 1 and res.levels[1].graphs == 4
    assert res.corr_trace_degree > 0.999            # Fig. 4: T-optimality ~ total degree
    assert res.corr_logdet_degree < res.corr_trace_degree
    assert res.flagged >= 1                          # Fig. 5: more edges, worse D-optimality
    for lv in res.levels:
        assert lv.total_degree == 2 * lv.m - 1       # the anchor keeps degree 1
    # trace(F) = eq. (73) + sum tau ||x_j - x_i||^2 over edges whose source is free (eq. 69-71)
    g0 = [g for g in res.graphs if g.m == 7][0]
    assert g0.trace == pytest.approx(g0.trace_eq73 + 1e4 * 6 * (2 * 0.1 * np.sin(np.pi / 8)) ** 2)


def test_octagon_truth_is_the_solver_estimate():
    from posecrb.solver import solve

    g = synth.octagon([(1, 4), (2, 7), (3, 5)], radius=0.1)
    res = solve(g)
    f_solve = paper_fim(g, res.rot, res.trans).matrix.toarray()
    f_truth = paper_fim(g, *anchor_estimate(g.vertex_rot, g.vertex_trans, 0)).matrix.toarray()
    assert np.allclose(f_solve, f_truth, rtol=1e-6, atol=1e-6 * np.abs(f_truth).max())


# ---------------------------------------------------------------- CLI
def _png_size(path) -> tuple[int, int]:
    """(width, height) from the IHDR chunk of a PNG file (whose signature is checked)."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR"
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def _run(args):
    from posecrb.cli import cli

    return CliRunner().invoke(cli, args, catch_exceptions=False)


def test_cli_octagon_and_thesis(tmp_path):
    r = _run(["experiment", "octagon", "--trials", "2", "--format", "json", "--out", str(tmp_path / "o")])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)
    # one row per number of extra edges k = 0..21 on the 8-pose chain (7 edges); at most `trials`
    # distinct graphs per level, exactly one where there is only one choice (k = 0, 21)
    assert [row["extra_edges"] for row in rows] == list(range(22))
    assert [row["m"] for row in rows] == [7 + k for k in range(22)]
    assert [row["graphs"] for row in rows] == [min(math.comb(21, k), 2) for k in range(22)]
    assert all(row["trace_min"] <= row["trace_max"] and row["logdet_min"] <= row["logdet_max"] for row in rows)
    run = json.loads((tmp_path / "o" / "run.json").read_text())
    assert run["settings"]["trials"] == 2 and run["settings"]["seed"] == 0
    # every level draws from its own child of the root seed
    assert [s["level"] for s in run["seeds"]] == list(range(22))
    assert {s["entropy"] for s in run["seeds"]} == {0}
    assert len({tuple(s["spawn_key"]) for s in run["seeds"]}) == 22
    import numpy

    assert run["versions"]["numpy"] == numpy.__version__
    assert _png_size(tmp_path / "o" / "octagon.png") > (0, 0)
    r = _run(["experiment", "thesis", "--m", "1,5", "--trials", "10", "--format", "csv",
              "--plot", str(tmp_path / "t.png")])
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    assert lines[0].startswith("m,formulation,trials,frob")
    assert [tuple(ln.split(",")[:3]) for ln in lines[1:]] == [(m, f, "10") for m in ("1", "5")
                                                             for f in ("anchored", "quotient")]
    assert _png_size(tmp_path / "t.png") > (0, 0)


def test_cli_crlb(tmp_path):
    g = synth.grid(2, 3, tau=100.0, kappa=200.0)
    from posecrb.io import write_g2o

    path = tmp_path / "grid.g2o"
    write_g2o(g, path, g.vertex_rot, g.vertex_trans)
    r = _run(["experiment", "crlb", str(path), "--kc", "5,10", "--trials", "4", "--format", "json",
              "--plot", str(tmp_path / "c.png"), "--out", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)
    assert [row["kc"] for row in rows] == [5.0, 10.0]
    assert {"kc", "trials", "mse", "mse_bound", "ratio"} <= set(rows[0])
    assert (tmp_path / "c" / "trials.csv").read_text().count("\n") == 9
    from posecrb.cli import main

    assert main(["experiment", "crlb", str(path), "--kc", "0"]) == 2
    assert main(["experiment", "crlb", str(path), "--scheduler", "tcp://x:1"]) == 2


# ---------------------------------------------------------------- quick modes (what CI runs)
@pytest.mark.slow
@pytest.mark.parametrize("args", [["crlb", "CSAIL"], ["crlb", "tinyGrid3D"], ["thesis"], ["octagon"]])
def test_quick_mode_of_each_experiment(shared_datasets, args):
    r = _run(["experiment", *args, "--quick", "--format", "json"])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)
    if args[0] == "crlb":
        assert [row["kc"] for row in rows] == [1.0, 20.0]
        for row in rows:
            assert row["uncertified"] == 0 and row["trials"] == 20
            assert row["fim_variant"] == "consistent"
            # the MSE of an (asymptotically) efficient estimator is the model's bound: within 3
            # standard errors of the 20-trial mean, plus 5% for second-order effects
            assert row["ratio"] == pytest.approx(row["mse"] / row["mse_bound"], rel=4 * np.finfo(float).eps)
            assert abs(row["ratio"] - 1) < 3 * row["mse_stderr"] / row["mse_bound"] + 0.05
    elif args[0] == "thesis":   # --quick: m = 1, 10, 100 measurements per arc, both formulations
        assert [(row["m"], row["formulation"]) for row in rows] == [(m, f) for m in (1, 10, 100)
                                                                     for f in ("anchored", "quotient")]
    else:
        assert [row["extra_edges"] for row in rows] == list(range(22))


@pytest.mark.slow
def test_tinygrid3d_mse_reaches_the_default_bound_not_eq64(shared_datasets):
    """`posecrb experiment crlb tinyGrid3D --kc 20` (100 trials, seed 0): the MSE of the certified
    MLE matches the default CRLB (the model's Fisher information) within 3 standard errors plus 5%
    for second-order effects, and is far above the CRLB of eq. (64) as printed."""
    from posecrb.experiments.crlb_sweep import _bounds
    from posecrb.io import load

    g = load(shared_datasets / "tinyGrid3D.g2o")
    res = crlb_sweep(g, [20.0], trials=100, seed=0)
    lv = res.levels[0]
    assert lv.uncertified == 0 and lv.fim_variant == "consistent"
    se = lv.mse_stderr / lv.mse_bound
    assert abs(lv.ratio - 1) < 3 * se + 0.05
    # the same truth as the sweep's (its certified solution, anchored), for the eq. (64) bound
    from posecrb.solver import solve

    sol = solve(g, anchor=0)
    rot, trans = anchor_estimate(sol.rot, sol.trans, 0)
    eq64 = _bounds(g, rot, trans, 0, 20.0, "both", None, None, "eq64")["mse_bound"]
    assert lv.mse / eq64 > 1 + 6 * lv.mse_stderr / eq64
