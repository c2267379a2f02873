"""The paper FIM (posecrb.models.paper.fim) against dense references: finite-difference Jacobians of the
translation residuals, dense loops for the rotation Laplacian and Psi (eq. 41 / 63) for eq. (64)
as printed; finite-difference Jacobians of the translation AND relative-rotation residuals (scipy's
rotation vectors, not posecrb.lie.so) for the frame-consistent Fisher information."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from posecrb.core.errors import DisconnectedGraph, NotPositiveDefinite
from posecrb.core.noise import rotation_weights
from posecrb.models.paper.bounds import t_optimality
from posecrb.models.paper.fim import FIM_VARIANTS, fim_logdet, fim_symbolic, paper_fim, trace_fim

from ..helpers import (
    _bridge_graph,
    _fd_error,
    central_jacobian,
    dense_model_fisher,
    drop_edges,
    make_random_graph,
    run_cli,
)
from ..numerics import assert_within, logdet_atol, psd_sum_tolerance, sum_atol


def residuals(graph, rot, trans) -> np.ndarray:
    """Stacked translation residuals r_ij = R_i^T (x_j - x_i) - p_ij, one edge at a time."""
    out = []
    for e in range(graph.m):
        i, j = graph.src[e], graph.dst[e]
        out.append(rot[i].T @ (trans[j] - trans[i]) - graph.trans[e])
    return np.concatenate(out)


def dense_reference(graph, rot, trans, anchor: int, h: float = 1e-6, with_error: bool = False):
    """Eq. (64) as printed: J^T W J from central differences over the free variables
    ([translations; rotations], eq. 42/64 order) + the reduced rotation Laplacian (x) I_dr from a
    loop over edges. ``with_error``: also the relative 2-norm error bound of
    ``dense_model_fisher``."""
    d = graph.dim
    dr = 1 if d == 2 else 3
    free = [k for k in range(graph.n) if k != anchor]
    npf = len(free)
    jac = central_jacobian(lambda r, t: residuals(graph, r, t), rot, trans, free, h)
    wdiag = np.repeat(graph.tau, d)
    f = jac.T @ (wdiag[:, None] * jac)
    rel = _fd_error(jac, wdiag, max(np.abs(residuals(graph, rot, trans)).max(), np.abs(graph.trans).max(),
                                    np.abs(trans).max()), h, f)
    w = rotation_weights(graph.kappa, d)
    pos = {k: t for t, k in enumerate(free)}
    for e in range(graph.m):
        i, j = graph.src[e], graph.dst[e]
        for a in range(dr):
            ri = npf * d + pos[i] * dr + a if i in pos else None
            rj = npf * d + pos[j] * dr + a if j in pos else None
            if ri is not None:
                f[ri, ri] += w[e]
            if rj is not None:
                f[rj, rj] += w[e]
            if ri is not None and rj is not None:
                f[ri, rj] -= w[e]
                f[rj, ri] -= w[e]
    return (f, rel * np.linalg.norm(jac.T @ (wdiag[:, None] * jac), 2) / np.linalg.norm(f, 2)) if with_error else f


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fim_matches_finite_difference_jacobians(dim, seed):
    rng = np.random.default_rng(seed)
    g = make_random_graph(rng, n=7, extra=5, dim=dim, parallel=2)
    anchor = int(rng.integers(0, g.n))
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=anchor, variant="eq64")
    assert fim.variant == "eq64"
    ref, rel = dense_reference(g, g.vertex_rot, g.vertex_trans, anchor, with_error=True)
    got = fim.matrix.toarray()
    assert_within(got, got.T, psd_sum_tolerance(got, g.m + 2), "symmetry")
    assert_within(got, ref, rel * np.linalg.norm(ref, 2), "eq. (64) vs finite differences")
    assert fim.anchor_id == g.ids[anchor]
    np.testing.assert_array_equal(fim.pose_ids, np.delete(g.ids, anchor))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_consistent_variant_is_the_fisher_information_of_the_model(dim, seed):
    """variant="consistent" == J^T W J of translation + relative-rotation residuals (finite
    differences) at random poses (non-trivial relative rotations), random anchor."""
    rng = np.random.default_rng(100 + seed)
    g = make_random_graph(rng, n=7, extra=5, dim=dim, parallel=2)
    anchor = int(rng.integers(0, g.n))
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=anchor)
    assert fim.variant == "consistent"            # the default
    ref, rel = dense_model_fisher(g, g.vertex_rot, g.vertex_trans, anchor, with_error=True)
    got = fim.matrix.toarray()
    assert_within(got, got.T, psd_sum_tolerance(got, g.m + 2), "symmetry")
    assert_within(got, ref, rel * np.linalg.norm(ref, 2), "consistent FIM vs finite differences")
    eq64 = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=anchor, variant="eq64").matrix.toarray()
    if dim == 3:
        # eq. (64) as printed is NOT the model's information once poses are rotated relative to
        # each other; the variants differ in the rotation coupling only (same trace)
        # (the off-diagonal difference is w (R_i^T R_j - I), on the scale of the rotation weights)
        assert np.abs(eq64 - ref).max() > 0.1 * rotation_weights(g.kappa, 3).max()
        assert np.abs(eq64 - ref).max() > 1e3 * rel * np.linalg.norm(ref, 2)
        k = (g.n - 1) * 3
        np.testing.assert_array_equal(got[:, :k], eq64[:, :k])   # same assembly code, same order
        assert np.trace(got) == pytest.approx(np.trace(eq64), abs=sum_atol(np.diag(got)))


@pytest.mark.parametrize("seed", [0, 1])
def test_2d_variants_are_identical(seed):
    g = make_random_graph(np.random.default_rng(seed), n=9, dim=2)
    for anchor in (0, 4):
        a = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=anchor, variant="eq64")
        b = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=anchor)
        assert (a.variant, b.variant) == ("eq64", "consistent")
        np.testing.assert_array_equal(a.matrix.indptr, b.matrix.indptr)
        np.testing.assert_array_equal(a.matrix.indices, b.matrix.indices)
        np.testing.assert_array_equal(a.matrix.data, b.matrix.data)
        assert fim_logdet(a) == fim_logdet(b)


def test_unknown_variant_is_rejected():
    g = make_random_graph(np.random.default_rng(3), n=5, dim=3)
    assert FIM_VARIANTS == ("eq64", "consistent")
    with pytest.raises(ValueError, match="variant"):
        paper_fim(g, g.vertex_rot, g.vertex_trans, variant="world")


def test_psi_blocks_3d_match_eq63():
    """Rotation diagonal block minus the Laplacian part = Psi_i = sum_{j in V_i^+} tau/2 (|u|^2 I - u u^T)."""
    rng = np.random.default_rng(11)
    g = make_random_graph(rng, n=6, extra=4, dim=3, parallel=1)
    rot, trans = g.vertex_rot, g.vertex_trans
    fim = paper_fim(g, rot, trans, anchor=0, variant="eq64")
    rb = fim.rotation_block().toarray()
    w = rotation_weights(g.kappa, 3)
    for k in range(1, g.n):
        psi = np.zeros((3, 3))
        lap = 0.0
        for e in range(g.m):
            if g.src[e] == k:
                u = rot[k].T @ (trans[g.dst[e]] - trans[k])
                psi += g.tau[e] / 2 * (u @ u * np.eye(3) - np.outer(u, u))
            if k in (g.src[e], g.dst[e]):
                lap += w[e]
        blk = rb[3 * (k - 1):3 * k, 3 * (k - 1):3 * k]
        ref = psi + lap * np.eye(3)
        assert_within(blk, ref, psd_sum_tolerance(ref, g.m + 1), f"pose {k}")


@pytest.mark.parametrize("dim", [2, 3])
def test_pose_layout_is_a_permutation_with_a_consistent_index_map(dim):
    g = make_random_graph(np.random.default_rng(4), n=6, dim=dim)
    fb = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=2)
    fp = fb.to_layout("poses")
    ids_b, c_b = fb.index_map()
    ids_p, c_p = fp.index_map()
    # locate each "poses" row in the "blocks" layout through the index maps
    key_b = {(i, c): r for r, (i, c) in enumerate(zip(ids_b, c_b))}
    perm = np.array([key_b[(i, c)] for i, c in zip(ids_p, c_p)])
    np.testing.assert_array_equal(fp.matrix.toarray(), fb.matrix.toarray()[np.ix_(perm, perm)])
    assert len(fp.coordinate_names()) == fp.q


@pytest.mark.parametrize("variant", FIM_VARIANTS)
@pytest.mark.parametrize("dim", [2, 3])
def test_logdet_and_trace_match_dense(dim, variant):
    g = make_random_graph(np.random.default_rng(7), n=9, dim=dim)
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, variant=variant)
    dense = fim.matrix.toarray()
    if variant == "consistent":   # the reference matrix itself from finite differences of the model
        ref_f, rel = dense_model_fisher(g, g.vertex_rot, g.vertex_trans, 0, with_error=True)
        assert_within(dense, ref_f, rel * np.linalg.norm(ref_f, 2), "consistent FIM vs finite differences")
    sign, ref = np.linalg.slogdet(dense)
    assert sign > 0
    sym = fim_symbolic(fim)
    assert fim_logdet(fim, sym) == pytest.approx(ref, abs=logdet_atol(dense))
    # the symbolic analysis depends only on the pattern: reuse it at another estimate
    other = paper_fim(g, g.vertex_rot, g.vertex_trans * 1.5, variant=variant).matrix.toarray()
    assert fim_logdet(paper_fim(g, g.vertex_rot, g.vertex_trans * 1.5, variant=variant), sym) == pytest.approx(
        np.linalg.slogdet(other)[1], abs=logdet_atol(other))
    assert trace_fim(fim) == pytest.approx(np.trace(dense), abs=sum_atol(np.diag(dense)))


@pytest.mark.parametrize("dim", [2, 3])
def test_t_opt_approx_equals_trace_at_a_noise_free_estimate(dim):
    """Eq. (72) replaces x_j - x_i by p_ij; with noise-free measurements they coincide."""
    g = make_random_graph(np.random.default_rng(8), n=8, dim=dim)
    rot, trans = g.vertex_rot, g.vertex_trans
    p = np.einsum("mba,mb->ma", rot[g.src], trans[g.dst] - trans[g.src])
    g = replace(g, trans=p)
    for anchor in (0, 3):
        fim = paper_fim(g, rot, trans, anchor=anchor)
        diag = fim.matrix.diagonal()
        # the same sum of non-negative terms in two orders, from p_ij and from x_j - x_i (equal
        # up to rounding of the einsum that built p)
        assert t_optimality(g, anchor)[1] == pytest.approx(diag.sum(), abs=sum_atol(diag) + sum_atol(
            g.tau * np.einsum("ma,ma->m", p, p)))


def test_intel_table1_logdet(shared_datasets):
    from posecrb.io import load

    g = load(shared_datasets / "intel.g2o")
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans)
    assert f"{fim_logdet(fim):.4e}" == "3.0194e+04"


def test_disconnected_graph_is_rejected():
    g = make_random_graph(np.random.default_rng(1), n=6, extra=0, parallel=0, dim=2)
    # drop the spanning-tree edge into pose 5: pose 5 becomes isolated
    g2 = drop_edges(g, (g.src == 5) | (g.dst == 5))   # pose 5 isolated
    with pytest.raises(DisconnectedGraph):
        paper_fim(g2, g.vertex_rot, g.vertex_trans)


def test_singular_fim_is_reported_not_positive_definite():
    g = make_random_graph(np.random.default_rng(2), n=5, dim=2)
    info = g.info.copy()
    info[:, :2, :2] = np.array([[1.0, 1.0], [1.0, 1.0]])  # tau = 0: no translation information
    info[:, :2, 2:] = 0
    info[:, 2:, :2] = 0
    g2 = replace(g, info=info)
    fim = paper_fim(g2, g.vertex_rot, g.vertex_trans)
    with pytest.raises(NotPositiveDefinite):
        fim_logdet(fim)


def test_bad_estimate_shape():
    g = make_random_graph(np.random.default_rng(3), n=5, dim=3)
    with pytest.raises(ValueError):
        paper_fim(g, g.vertex_rot[:-1], g.vertex_trans[:-1])


# ---------------------------------------------------------------- CLI `posecrb fim`
@pytest.fixture
def g2o_file(tmp_path):
    from posecrb.io import write_g2o

    def make(dim: int, seed: int = 0, **kw):
        g = make_random_graph(np.random.default_rng(seed), n=8, dim=dim, **kw)
        path = tmp_path / f"g{dim}_{seed}.g2o"
        write_g2o(g, path)
        return path

    return make


@pytest.mark.parametrize("variant", [None, "eq64", "consistent"])
@pytest.mark.parametrize("dim", [2, 3])
def test_cli_fim_paper_json_and_npz(dim, variant, g2o_file, tmp_path, capsys):
    import json

    import scipy.sparse as sp

    from posecrb.io import load

    path = g2o_file(dim)
    npz = tmp_path / "f.npz"
    ids = load(path).ids
    extra = [] if variant is None else ["--fim-variant", variant]
    code, out, _ = run_cli(["fim", str(path), "--estimate", "vertices", "--anchor", str(ids[2]),
                            "--save", str(npz), "--format", "json", *extra], capsys)
    assert code == 0
    row = json.loads(out)
    g = load(path)
    assert row["fim_variant"] == (variant or "consistent")
    if variant == "eq64":
        dense, rel = dense_reference(g, g.vertex_rot, g.vertex_trans, 2, with_error=True)
    else:
        dense, rel = dense_model_fisher(g, g.vertex_rot, g.vertex_trans, 2, with_error=True)
        dense = (dense + dense.T) / 2
    assert row["size"] == dense.shape[0] and row["anchors"] == [int(ids[2])]
    # a relative 2-norm perturbation rel of F moves log det by at most n rel cond(F)
    n = dense.shape[0]
    assert row["logdet"] == pytest.approx(np.linalg.slogdet(dense)[1], abs=n * rel * np.linalg.cond(dense))
    assert row["trace"] == pytest.approx(np.trace(dense), abs=n * rel * np.linalg.norm(dense, 2))
    assert row["estimate"]["source"] == "vertices"
    saved = sp.load_npz(npz)
    assert_within(saved.toarray(), dense, rel * np.linalg.norm(dense, 2), "saved FIM")
    z = np.load(npz)
    assert z["row_pose_id"].size == dense.shape[0] and int(ids[2]) not in set(z["row_pose_id"].tolist())
    assert list(z["coordinate_names"]) == (["x", "y", "theta"] if dim == 2 else
                                           ["x", "y", "z", "phi1", "phi2", "phi3"])


def test_cli_fim_sed_reports_rank_and_nullity(g2o_file, capsys):
    import json

    code, out, err = run_cli(["fim", str(g2o_file(2, seed=3)), "--model", "sed", "--estimate", "vertices",
                              "--format", "json"], capsys)
    assert code == 0
    row = json.loads(out)
    assert row["nullity"] == 3 and row["rank"] == row["size"] - 3
    assert row["logdet"] is not None and "logdet_status" not in row and "warning" not in err


@pytest.mark.parametrize("dim", [2, 3])
def test_cli_fim_sed_near_singular_bridge_is_a_status(dim, tmp_path, capsys):
    """Two clusters joined by one edge of information 1e-14: the SE(d) FIM is numerically singular.
    logdet is null with a status naming the edge and its line, a warning on stderr; the
    numerical nullity is above q x components (checked against dense eigenvalues)."""
    import json

    from posecrb.io import load, write_g2o
    from posecrb.models.sed.fim import sed_fim

    path = tmp_path / "bridge.g2o"
    write_g2o(_bridge_graph(dim, 1e-14), path)
    code, out, err = run_cli(["fim", str(path), "--model", "sed", "--estimate", "vertices", "--format", "json"],
                             capsys)
    assert code == 0
    row = json.loads(out)
    q = 3 if dim == 2 else 6
    assert row["logdet"] is None
    st = row["logdet_status"]
    assert st["status"] == "unavailable" and "numerically singular" in st["reason"]
    g = load(path)
    weak_line = int(g.edge_lines[np.argmin(np.linalg.eigvalsh(g.info)[:, 0])])
    assert f"edge 3 -> 4, line {weak_line}" in st["reason"] and st["hint"]
    assert row["expected_nullity"] == q and row["nullity"] > q
    assert "warning" in err and "log det of the FIM not available" in err
    # independent: dense eigenvalues of F put more than q of them below n eps lambda_max
    f = sed_fim(g, g.vertex_rot, g.vertex_trans).matrix.toarray()
    ev = np.linalg.eigvalsh(f)
    assert np.sum(ev < f.shape[0] * np.finfo(float).eps * ev[-1]) > q
    code, out, _ = run_cli(["fim", str(path), "--model", "sed", "--estimate", "vertices"], capsys)
    assert code == 0 and "n/a (numerically singular" in out
    code, _, err = run_cli(["crlb", str(path), "--model", "sed", "--estimate", "vertices"], capsys)
    assert code == 1 and "numerically singular" in err and "Traceback" not in err


def test_cli_fim_variant_with_sed_is_a_usage_error(g2o_file, capsys):
    code, _, err = run_cli(["fim", str(g2o_file(2)), "--model", "sed", "--estimate", "vertices",
                            "--fim-variant", "consistent"], capsys)
    assert code == 2 and "--fim-variant" in err


def test_cli_fim_unknown_anchor_is_a_usage_error(g2o_file, capsys):
    code, _, err = run_cli(["fim", str(g2o_file(2)), "--estimate", "vertices", "--anchor", "999999"], capsys)
    assert code == 2 and "999999" in err
