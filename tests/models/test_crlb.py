"""Paper-model CRLB (posecrb.models.paper.crlb) against dense evaluations of eq. (67) and eq. (68), for both FIM
variants (the consistent one also against the finite-difference Fisher information of the model),
its statuses (eq. 68 outside its domain, accuracy of the inverse) and the CLI. Tolerances follow
from the conditioning of each matrix (tests/numerics.py)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from posecrb.core.errors import DisconnectedGraph, UsageError
from posecrb.models.paper.crlb import CURVATURE_WARN, curvature_status, inverse_accuracy, paper_crlb
from posecrb.models.paper.fim import FIM_VARIANTS, paper_fim

from ..helpers import _bridge_graph, dense_model_fisher, drop_edges, make_random_graph, run_cli
from ..numerics import EPS, MARGIN, assert_within, inverse_entry_atol, spd_condition, trace_inverse_rtol


def dense_eq68(f: np.ndarray, npf: int) -> np.ndarray:
    """Eq. (68) evaluated densely in the [translations; rotations] layout of eq. (64)."""
    finv = np.linalg.inv(f)
    lt = dense_ltilde(f, npf)
    return finv - (lt @ finv + finv @ lt) / 12.0


def dense_ltilde(f: np.ndarray, npf: int) -> np.ndarray:
    """ddiag(L~) of eq. (68): the 3 x 3 diagonal blocks of inv(I^SO(3)), on the rotation rows."""
    k = 3 * npf
    iso3_inv = np.linalg.inv(f[k:, k:])
    lt = np.zeros_like(f)
    for i in range(npf):
        s = slice(k + 3 * i, k + 3 * i + 3)
        lt[s, s] = iso3_inv[3 * i:3 * i + 3, 3 * i:3 * i + 3]
    return lt


def eq68_atol(f: np.ndarray, npf: int) -> float:
    """Entry tolerance of eq. (68) computed two ways: the errors of F^{-1} (2-norm ``e_f``) and of
    inv(I^SO(3)) (``e_l``) propagate through ``F^{-1} - (L F^{-1} + F^{-1} L) / 12``."""
    k = 3 * npf
    rot = f[k:, k:]
    e_f, e_l = inverse_entry_atol(f), inverse_entry_atol(rot)
    n_f = 1.0 / np.linalg.eigvalsh(f)[0]          # ||F^{-1}||_2
    n_l = 1.0 / np.linalg.eigvalsh(rot)[0]        # ||inv(I^SO(3))||_2 >= ||ddiag||_2
    return e_f + (e_l * n_f + n_l * e_f) / 6.0 + MARGIN * f.shape[0] * EPS * n_l * n_f


def scale_rotation_information(g, factor: float):
    """The graph with its rotation information (and cross terms) scaled so that kappa -> factor^2 kappa."""
    scale = np.where(np.arange(6) >= 3, factor, 1.0)
    return replace(g, info=g.info * scale[None, :, None] * scale[None, None, :])


def pose_block(mat: np.ndarray, npf: int, d: int, dr: int, i: int) -> np.ndarray:
    idx = np.concatenate([i * d + np.arange(d), npf * d + i * dr + np.arange(dr)])
    return mat[np.ix_(idx, idx)]


@pytest.mark.parametrize("seed", [0, 1])
def test_2d_crlb_is_dense_inverse(seed):
    rng = np.random.default_rng(seed)
    g = make_random_graph(rng, n=9, extra=6, dim=2)
    anchor = 3
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=anchor, per_pose=True)
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=anchor).matrix.toarray()
    finv = np.linalg.inv(f)
    npf = g.n - 1
    rtol, atol = trace_inverse_rtol(f), inverse_entry_atol(f)
    assert res.trace_crlb == pytest.approx(np.trace(finv), rel=rtol)
    assert res.mse_bound == pytest.approx(np.trace(finv) / npf, rel=rtol)
    assert res.trace_translation == pytest.approx(np.trace(finv[:2 * npf, :2 * npf]), abs=2 * npf * atol)
    assert res.trace_crlb_curvature is None and res.per_pose_curvature is None
    free = [k for k in range(g.n) if k != anchor]
    for t, k in enumerate(free):
        assert_within(res.per_pose[int(g.ids[k])], pose_block(finv, npf, 2, 1, t), atol, f"pose {k}")
    np.testing.assert_array_equal(res.per_pose[int(g.ids[anchor])], np.zeros((3, 3)))


@pytest.mark.parametrize("variant", FIM_VARIANTS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_3d_curvature_term_matches_dense_eq68(seed, variant):
    rng = np.random.default_rng(seed)
    g = make_random_graph(rng, n=7, extra=5, dim=3)
    # smaller rotation information makes the curvature term visible (4% to 37% of the first-order
    # term at the worst pose here), still inside eq. (68)'s domain
    g = scale_rotation_information(g, 0.5)
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=0, per_pose=True, variant=variant)
    assert res.fim_variant == variant
    assert res.curvature_status.available
    assert res.curvature_status.ok == (res.curvature_correction_max <= CURVATURE_WARN)
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0, variant=variant).matrix.toarray()
    npf = g.n - 1
    bound = dense_eq68(f, npf)
    finv = np.linalg.inv(f)
    atol, atol_c = inverse_entry_atol(f), eq68_atol(f, npf)
    assert res.trace_crlb == pytest.approx(np.trace(finv), rel=trace_inverse_rtol(f))
    assert res.trace_crlb_curvature == pytest.approx(np.trace(bound), abs=f.shape[0] * atol_c)
    assert res.mse_bound_curvature == pytest.approx(np.trace(bound) / npf, abs=f.shape[0] * atol_c / npf)
    # the correction is (1/6) sum trace(D_i C_i), a trace of products of PSD matrices: non-negative
    assert res.trace_crlb - res.trace_crlb_curvature > 1e3 * f.shape[0] * atol_c
    for t in range(npf):
        pid = int(g.ids[t + 1])
        ref, ref_c = pose_block(finv, npf, 3, 3, t), pose_block(bound, npf, 3, 3, t)
        assert_within(res.per_pose[pid], ref, atol, f"pose {pid}")
        assert_within(res.per_pose_curvature[pid], ref_c, atol_c, f"pose {pid} with curvature")


@pytest.mark.parametrize("dim", [2, 3])
def test_consistent_crlb_inverts_the_models_fisher_information(dim):
    """trace / curvature bound from the finite-difference Fisher information of the model (dense
    numpy inverse), anchor in the middle; in 2D the two variants give the same bound."""
    rng = np.random.default_rng(20 + dim)
    g = make_random_graph(rng, n=8, extra=6, dim=dim)
    anchor = 4
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=anchor)
    assert res.fim_variant == "consistent"          # the default
    f, f_rel = dense_model_fisher(g, g.vertex_rot, g.vertex_trans, anchor, with_error=True)
    f = (f + f.T) / 2
    npf = g.n - 1
    finv = np.linalg.inv(f)
    # the finite-difference reference has a relative error f_rel (its docstring), which the
    # inverse amplifies by at most cond(F) / (1 - cond(F) f_rel); a trace of n entries
    kappa = spd_condition(f)
    assert kappa * f_rel < 0.1, "reference too ill-conditioned for this check"
    rtol = f.shape[0] * kappa * f_rel / (1 - kappa * f_rel)
    assert res.trace_crlb == pytest.approx(np.trace(finv), rel=rtol)
    assert res.mse_bound == pytest.approx(np.trace(finv) / npf, rel=rtol)
    eq64 = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=anchor, variant="eq64")
    assert eq64.fim_variant == "eq64"
    if dim == 3:
        assert res.trace_crlb_curvature == pytest.approx(np.trace(dense_eq68(f, npf)), rel=rtol)
        # the variants differ far beyond the round-off of either computation
        f_lib = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=anchor).matrix.toarray()
        assert abs(eq64.trace_crlb / res.trace_crlb - 1) > 1e6 * trace_inverse_rtol(f_lib)
    else:
        assert eq64.trace_crlb == res.trace_crlb


@pytest.mark.parametrize("variant", FIM_VARIANTS)
def test_curvature_term_outside_its_domain_is_unavailable(variant):
    """Weak rotation information: the eq. (68) correction exceeds the first-order term at some
    pose (the dense evaluation of eq. 68 then has a non-positive diagonal entry there), so the
    curvature-corrected bound is reported unavailable with its reason, never as a number."""
    g = scale_rotation_information(make_random_graph(np.random.default_rng(1), n=7, extra=5, dim=3), 0.2)
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=0, per_pose=True, variant=variant)
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0, variant=variant).matrix.toarray()
    npf = g.n - 1
    bound, finv, lt = dense_eq68(f, npf), np.linalg.inv(f), dense_ltilde(f, npf)
    # independent check of the premise: at some pose the dense correction reaches the first-order term
    corr = np.array([np.trace(pose_block(lt @ finv, npf, 3, 3, t)) / 6 for t in range(npf)])
    first = np.array([np.trace(pose_block(finv, npf, 3, 3, t)) for t in range(npf)])
    assert (corr >= first).any()
    assert res.curvature_correction_max == pytest.approx((corr / first).max(), rel=1e-6)
    assert res.curvature_status.state == "unavailable" and "first-order term" in res.curvature_status.reason
    assert res.trace_crlb_curvature is None and res.mse_bound_curvature is None
    assert res.per_pose_curvature is None
    assert res.trace_crlb == pytest.approx(np.trace(finv), rel=trace_inverse_rtol(f))
    assert np.trace(bound) < res.trace_crlb  # eq. (68) evaluated anyway: below the first-order bound


def test_curvature_status_thresholds():
    ids = np.array([5, 7])
    assert curvature_status(np.array([0.0, 0.05]), np.array([1.0, 1.0]), ids).ok
    warn = curvature_status(np.array([0.0, 2 * CURVATURE_WARN]), np.array([1.0, 1.0]), ids)
    assert warn.state == "warning" and "pose 7" in warn.reason
    bad = curvature_status(np.array([3.0, 0.0]), np.array([1.0, 1.0]), ids)
    assert bad.state == "unavailable" and "1 of 2 poses" in bad.reason and "pose 5" in bad.reason
    assert curvature_status(np.array([0.0]), np.array([0.0]), ids[:1]).state == "unavailable"


def test_inverse_accuracy_against_dense_references():
    """Backward error of the sampled solves at round-off level; the condition estimate of the
    diagonally scaled F is a lower estimate of its 1-norm condition number (Hager-Higham), within
    the estimator's guaranteed factor n (and in practice much closer)."""
    import scipy.sparse as sp

    from posecrb.linalg.cholesky import cholesky

    g = make_random_graph(np.random.default_rng(3), n=9, extra=6, dim=3)
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0).matrix
    acc = inverse_accuracy(f, cholesky(f), "paper FIM")
    dense = f.toarray()
    n = dense.shape[0]
    s = 1 / np.sqrt(np.diag(dense))
    h = dense * s[:, None] * s[None, :]
    kappa1 = np.linalg.norm(h, 1) * np.linalg.norm(np.linalg.inv(h), 1)
    assert kappa1 / n <= acc.condition_estimate <= kappa1 * (1 + trace_inverse_rtol(h))
    kappa1_f = np.linalg.norm(dense, 1) * np.linalg.norm(np.linalg.inv(dense), 1)
    assert kappa1_f / n <= acc.condition_unscaled <= kappa1_f * (1 + trace_inverse_rtol(dense))
    assert acc.residual <= MARGIN * n * EPS
    assert acc.error_bound == pytest.approx(acc.condition_estimate * EPS)
    assert acc.status.ok and acc.columns == 4
    assert sp.issparse(f)


def test_inverse_accuracy_solves_at_one_thread_unless_the_matrix_is_threaded(monkeypatch):
    """The estimate's solves run CHOLMOD's BLAS at one thread for a matrix factored at one thread,
    even where the caller left it at two, and at the load-aware count for a threaded matrix; the
    numbers are the same either way."""
    import posecrb.models.paper.crlb as crlb_mod
    from posecrb.linalg import threads
    from posecrb.linalg.cholesky import cholesky

    g = make_random_graph(np.random.default_rng(3), n=9, extra=6, dim=3)
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0).matrix
    factor = cholesky(f)
    seen: list[int] = []

    def spied(b):
        seen.append(threads.cholmod_threads())
        return factor(b)

    monkeypatch.setattr(threads, "busy_cores", lambda: 0)     # an idle machine: no cores to leave
    with threads.cholmod_blas().limit(limits=2):
        if threads.cholmod_threads() != 2:
            pytest.skip("CHOLMOD's BLAS cannot be given two threads here")
        single = crlb_mod.inverse_accuracy(f, spied, "paper FIM")
        assert seen and set(seen) == {1}
        seen.clear()
        threaded = crlb_mod.inverse_accuracy(f, spied, "paper FIM", threaded=True)
        assert seen and set(seen) == {2}
        assert threads.cholmod_threads() == 2
    assert single.condition_estimate == pytest.approx(threaded.condition_estimate, rel=1e-10)
    assert single.status.state == threaded.status.state == "ok"


@pytest.mark.parametrize("weak,state", [(1e-6, "warning"), (1e-13, "unavailable")])
def test_accuracy_status_of_an_ill_conditioned_fim(weak, state):
    """A weak bridge makes F ill-conditioned; the scaled condition number (checked against a dense
    computation, within the estimator's factor n) drives the status."""
    g = _bridge_graph(2, weak)
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans)
    dense = paper_fim(g, g.vertex_rot, g.vertex_trans).matrix.toarray()
    s = 1 / np.sqrt(np.diag(dense))
    ev = np.linalg.eigvalsh(dense * s[:, None] * s[None, :])
    n = dense.shape[0]
    # 1-norm and 2-norm condition numbers agree within a factor n
    assert ev[-1] / ev[0] / n <= res.accuracy.condition_estimate * (1 + 1e-6)
    assert res.accuracy.status.state == state
    assert res.accuracy.residual <= MARGIN * n * EPS


def test_per_pose_subset_and_unknown_id():
    g = make_random_graph(np.random.default_rng(5), n=6, dim=2)
    ids = [int(g.ids[4]), int(g.ids[1])]
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans, per_pose=ids)
    assert list(res.per_pose) == ids
    with pytest.raises(UsageError):
        paper_crlb(g, g.vertex_rot, g.vertex_trans, per_pose=[int(g.ids.max()) + 1])
    assert paper_crlb(g, g.vertex_rot, g.vertex_trans).per_pose is None


def test_disconnected_graph_is_rejected():
    g = make_random_graph(np.random.default_rng(6), n=6, extra=0, parallel=0, dim=3)
    g2 = drop_edges(g, (g.src == 2) | (g.dst == 2))   # pose 2 isolated
    with pytest.raises(DisconnectedGraph):
        paper_crlb(g2, g.vertex_rot, g.vertex_trans)


# ---------------------------------------------------------------- CLI `posecrb crlb`
def write_graph(tmp_path, dim: int, seed: int = 0):
    from posecrb.io import load, write_g2o

    g = make_random_graph(np.random.default_rng(seed), n=7, dim=dim)
    path = tmp_path / f"c{dim}.g2o"
    write_g2o(g, path)
    return path, load(path)


@pytest.mark.parametrize("variant", [None, "eq64", "consistent"])
@pytest.mark.parametrize("dim", [2, 3])
def test_cli_crlb_paper_json(dim, variant, tmp_path, capsys):
    import json

    path, g = write_graph(tmp_path, dim)
    pid = int(g.ids[3])
    extra = [] if variant is None else ["--fim-variant", variant]
    code, out, err = run_cli(["crlb", str(path), "--estimate", "vertices", "--poses", str(pid), "--format", "json",
                              *extra], capsys)
    assert code == 0
    row = json.loads(out)
    for key in ("model", "dim", "poses", "components", "nullity", "trace_crlb", "mse_bound", "per_pose", "times",
                "fim_variant", "accuracy"):
        assert key in row
    assert row["fim_variant"] == (variant or "consistent")
    # the default is the model's Fisher information: no warning about it any more
    assert "warning" not in err, err
    assert row["accuracy"]["status"] == "ok" and row["accuracy"]["reason"] is None
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, variant=variant or "consistent").matrix.toarray()
    finv = np.linalg.inv(f)
    assert row["trace_crlb"] == pytest.approx(np.trace(finv), rel=trace_inverse_rtol(f))
    assert row["mse_bound"] == pytest.approx(np.trace(finv) / (g.n - 1), rel=trace_inverse_rtol(f))
    d, dr = dim, (1 if dim == 2 else 3)
    assert_within(np.array(row["per_pose"][str(pid)]), pose_block(finv, g.n - 1, d, dr, 2), inverse_entry_atol(f))
    assert ("trace_crlb_curvature" in row) == (dim == 3)


def test_cli_crlb_curvature_unavailable_is_null_with_reason(tmp_path, capsys):
    """3D, tiny rotation information (kappa 1e-6): eq. (68) does not hold; JSON null + status,
    table 'n/a (reason)', one warning on stderr, exit 0 (the first-order bound is still there)."""
    import json

    from posecrb.io import write_g2o
    from posecrb.sim.generators import grid

    path = tmp_path / "weak.g2o"
    write_g2o(grid(3, 3, tau=100.0, kappa=1e-6, rng=0), path)
    code, out, err = run_cli(["crlb", str(path), "--estimate", "vertices", "--format", "json"], capsys)
    assert code == 0
    row = json.loads(out)
    assert row["trace_crlb_curvature"] is None and row["mse_bound_curvature"] is None
    st = row["trace_crlb_curvature_status"]
    assert st["status"] == "unavailable" and "first-order term" in st["reason"] and st["hint"]
    assert row["trace_crlb"] > 0
    assert err.count("warning") == 1 and "eq. 68" in err
    code, out, _ = run_cli(["crlb", str(path), "--estimate", "vertices", "--poses", "all"], capsys)
    assert code == 0 and "n/a (the second-order curvature correction" in out
    code, out, _ = run_cli(["crlb", str(path), "--estimate", "vertices", "--format", "csv"], capsys)
    header, values = out.splitlines()[:2]
    assert "trace_crlb_curvature_status.status" in header.split(",")


def test_cli_crlb_accuracy_warning_and_unavailable(tmp_path, capsys):
    import json

    from posecrb.io import write_g2o

    for weak, state in ((1e-6, "warning"), (1e-13, "unavailable")):
        path = tmp_path / f"bridge{weak}.g2o"
        write_g2o(_bridge_graph(2, weak), path)
        code, out, err = run_cli(["crlb", str(path), "--estimate", "vertices", "--poses", "all", "--format",
                                  "json"], capsys)
        assert code == 0
        row = json.loads(out)
        assert row["accuracy"]["status"] == state and "condition number" in row["accuracy"]["reason"]
        assert "CRLB" in err and state.replace("unavailable", "not available").replace("warning", "doubtful") in err
        if state == "unavailable":
            assert row["trace_crlb"] is None and row["trace_crlb_status"]["status"] == "unavailable"
            assert "per_pose" not in row
        else:
            assert row["trace_crlb"] > 0 and "trace_crlb_status" not in row


def test_cli_crlb_sed_quotient_and_anchors(tmp_path, capsys):
    import json

    path, g = write_graph(tmp_path, 2, seed=4)
    code, out, _ = run_cli(["crlb", str(path), "--model", "sed", "--quotient", "--estimate", "vertices",
                            "--poses", "all", "--format", "json"], capsys)
    assert code == 0
    row = json.loads(out)
    assert row["kind"] == "quotient" and row["nullity"] == 3 and len(row["per_pose"]) == g.n
    code, out, _ = run_cli(["crlb", str(path), "--model", "sed", "--estimate", "vertices",
                            "--anchor", str(g.ids[0]), "--anchor", str(g.ids[5]), "--format", "json"], capsys)
    assert code == 0
    assert json.loads(out)["anchors"] == [int(g.ids[0]), int(g.ids[5])]


@pytest.mark.parametrize("extra", [["--quotient"], ["--anchor", "0", "--anchor", "1"], ["--poses", "a-b"],
                                   ["--model", "sed", "--fim-variant", "eq64"], ["--fim-variant", "world"]])
def test_cli_crlb_usage_errors(extra, tmp_path, capsys):
    path, g = write_graph(tmp_path, 2)
    if "--anchor" in extra:
        extra = ["--anchor", str(g.ids[0]), "--anchor", str(g.ids[1])]
    code, _, err = run_cli(["crlb", str(path), "--estimate", "vertices", *extra], capsys)
    assert code == 2, err


def test_cli_crlb_table_output(tmp_path, capsys):
    path, g = write_graph(tmp_path, 3)
    code, out, _ = run_cli(["crlb", str(path), "--estimate", "vertices", "--poses", "all"], capsys)
    assert code == 0 and "trace_crlb_curvature" in out and "per-pose" in out
