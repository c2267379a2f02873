"""The thesis model on SE(d)^n: FIM vs finite differences, gauge, anchored and quotient CRBs."""
from __future__ import annotations

import logging
from dataclasses import replace
from functools import partial

import numpy as np
import pytest
from scipy.linalg import expm

from posecrb.core.errors import NotPositiveDefinite, UsageError
from posecrb.core.graph import PoseGraph
from posecrb.io import load
from posecrb.lie import se as L
from posecrb.models.sed import example as te
from posecrb.models.sed.crlb import sed_crlb
from posecrb.models.sed.fim import edge_residuals, kernel_basis, left_information, sed_fim

from ..helpers import hat_ref, perturbed_graph
from ..numerics import (
    EPS,
    MARGIN,
    assert_within,
    inverse_entry_atol,
    pinv_entry_atol,
    pinv_trace_rtol,
    psd_sum_tolerance,
    trace_inverse_rtol,
)


# ------------------------------------------------------------------ independent references
def homog(r, t):
    d = r.shape[-1]
    out = np.eye(d + 1)
    out[:d, :d], out[:d, d] = r, t
    return out


def log_vec(x):
    # closed-form Log, itself checked against scipy.linalg.logm in tests/lie/test_se_lie.py
    return L.se_log(*L.from_homogeneous(x))


def reference_omega_left(graph: PoseGraph) -> np.ndarray:
    """Omega_left = K^{-T} Omega_right K^{-1}, K = d xi_left / d e by finite differences of
    xi_left(e) = Log(z Exp(e) z^{-1}) (z Exp(e) = Exp(xi_left) z), e the right error."""
    q = graph.q
    perm = [2, 0, 1] if q == 3 else [3, 4, 5, 0, 1, 2]
    out = np.empty((graph.m, q, q))
    h = 1e-6
    for k in range(graph.m):
        z = homog(graph.rot[k], graph.trans[k])
        zi = np.linalg.inv(z)
        kmat = np.empty((q, q))
        for a in range(q):
            d = np.zeros(q)
            d[a] = h
            kmat[:, a] = (log_vec(z @ expm(hat_ref(d)) @ zi) - log_vec(z @ expm(hat_ref(-d)) @ zi)) / (2 * h)
        om_r = graph.info[k][np.ix_(perm, perm)]
        kinv = np.linalg.inv(kmat)
        out[k] = kinv.T @ om_r @ kinv
    return out


def reference_fim(graph: PoseGraph, rot, trans, omega) -> np.ndarray:
    """Dense sum J^T Omega J with J from central differences of r_ij(delta) =
    Log(z (T_j Exp(d_j)) (T_i Exp(d_i))^{-1}), T = X^{-1} (thesis 4.3-4.6)."""
    q, n = graph.q, graph.n
    f = np.zeros((n * q, n * q))
    h = 1e-6
    for k in range(graph.m):
        i, j = graph.src[k], graph.dst[k]
        z = homog(graph.rot[k], graph.trans[k])
        ti = np.linalg.inv(homog(rot[i], trans[i]))
        tj = np.linalg.inv(homog(rot[j], trans[j]))
        jac = np.zeros((q, n * q))
        for a in range(q):
            d = np.zeros(q)
            d[a] = h
            ep, em = expm(hat_ref(d)), expm(hat_ref(-d))
            # perturb T_i
            rp = log_vec(z @ tj @ np.linalg.inv(ti @ ep))
            rm = log_vec(z @ tj @ np.linalg.inv(ti @ em))
            jac[:, i * q + a] += (rp - rm) / (2 * h)
            # perturb T_j
            rp = log_vec(z @ tj @ ep @ np.linalg.inv(ti))
            rm = log_vec(z @ tj @ em @ np.linalg.inv(ti))
            jac[:, j * q + a] += (rp - rm) / (2 * h)
        f += jac.T @ omega[k] @ jac
    return f


# residuals ~0.3 rad: a moderate error, well inside (-pi, pi); six poses, four loop closures
sed_graph = partial(perturbed_graph, n=6, extra=4)


def union(g1: PoseGraph, g2: PoseGraph) -> PoseGraph:
    off = g1.n
    return PoseGraph(
        dim=g1.dim, ids=np.r_[g1.ids, g2.ids + g1.ids.max() + 1], src=np.r_[g1.src, g2.src + off],
        dst=np.r_[g1.dst, g2.dst + off], rot=np.r_[g1.rot, g2.rot], trans=np.r_[g1.trans, g2.trans],
        info=np.r_[g1.info, g2.info], vertex_rot=np.r_[g1.vertex_rot, g2.vertex_rot],
        vertex_trans=np.r_[g1.vertex_trans, g2.vertex_trans], format="synthetic")


@pytest.fixture
def posecrb_log(caplog):
    """caplog attached to the "posecrb" logger itself (the CLI turns its propagation off)."""
    logger = logging.getLogger("posecrb")
    logger.addHandler(caplog.handler)
    caplog.handler.setLevel(logging.WARNING)
    try:
        yield caplog
    finally:
        logger.removeHandler(caplog.handler)


def dense_blocks(mat, q):
    n = mat.shape[0] // q
    return np.stack([mat[i * q:(i + 1) * q, i * q:(i + 1) * q] for i in range(n)])


# ------------------------------------------------------------------ FIM
@pytest.mark.parametrize("dim", [2, 3])
def test_left_information_is_the_adjoint_congruence(dim):
    g = sed_graph(np.random.default_rng(dim), dim)
    om, n_bad = left_information(g)
    assert n_bad == 0
    np.testing.assert_allclose(om, reference_omega_left(g), rtol=1e-7, atol=1e-7 * np.abs(om).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_fim_equals_the_g2o_error_model_at_zero_residual(dim):
    """End to end, no conversion formula: with the g2o error e = Log(z^{-1} X_i^{-1} X_j) and the
    file's matrix on it (reordered rotation first), sum J_e^T I J_e by finite differences in the
    thesis' perturbations T_k Exp(delta) equals sed_fim's F where the residuals vanish."""
    g = sed_graph(np.random.default_rng(40 + dim), dim, n=5, noise=0.0)
    q, n = g.q, g.n
    perm = [2, 0, 1] if q == 3 else [3, 4, 5, 0, 1, 2]
    ref = np.zeros((n * q, n * q))
    h = 1e-6
    for k in range(g.m):
        i, j = g.src[k], g.dst[k]
        zinv = np.linalg.inv(homog(g.rot[k], g.trans[k]))
        ti = np.linalg.inv(homog(g.vertex_rot[i], g.vertex_trans[i]))
        tj = np.linalg.inv(homog(g.vertex_rot[j], g.vertex_trans[j]))
        jac = np.zeros((q, n * q))
        for a in range(q):
            for sgn in (1, -1):
                e = expm(hat_ref(sgn * h * np.eye(q)[a]))
                # X_i^{-1} X_j = T_i T_j^{-1}
                jac[:, i * q + a] += sgn * log_vec(zinv @ ti @ e @ np.linalg.inv(tj)) / (2 * h)
                jac[:, j * q + a] += sgn * log_vec(zinv @ ti @ np.linalg.inv(tj @ e)) / (2 * h)
        ref += jac.T @ g.info[k][np.ix_(perm, perm)] @ jac
    got = sed_fim(g, g.vertex_rot, g.vertex_trans).matrix.toarray()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6 * np.abs(ref).max())


@pytest.mark.parametrize("dim,seed", [(2, 0), (2, 1), (3, 0), (3, 1)])
def test_fim_matches_finite_difference_jacobians(dim, seed):
    rng = np.random.default_rng(100 + seed)
    g = sed_graph(rng, dim, n=6 if dim == 2 else 5, extra=4, parallel=2)
    assert np.abs(edge_residuals(g, g.vertex_rot, g.vertex_trans)).max() > 0.1  # Jr^{-1} is exercised
    fim = sed_fim(g, g.vertex_rot, g.vertex_trans)
    ref = reference_fim(g, g.vertex_rot, g.vertex_trans, reference_omega_left(g))
    got = fim.matrix.toarray()
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6 * np.abs(ref).max())
    assert_within(got, got.T, psd_sum_tolerance(got, g.m + 1), "symmetry")
    assert fim.matrix.shape == (g.n * g.q, g.n * g.q)
    assert (fim.rank, fim.nullity, fim.components) == (g.n * g.q - g.q, g.q, 1)


@pytest.mark.parametrize("dim", [2, 3])
def test_disconnected_graph_nullity_and_kernel(dim):
    rng = np.random.default_rng(7)
    g = union(union(sed_graph(rng, dim, n=4), sed_graph(rng, dim, n=3, extra=1)),
              sed_graph(rng, dim, n=2, extra=0, parallel=1))
    assert g.n_components == 3
    fim = sed_fim(g, g.vertex_rot, g.vertex_trans)
    f = fim.matrix.toarray()
    ref = reference_fim(g, g.vertex_rot, g.vertex_trans, reference_omega_left(g))
    np.testing.assert_allclose(f, ref, rtol=0, atol=1e-6 * np.abs(ref).max())
    q, c = g.q, 3
    assert (fim.nullity, fim.components, fim.rank_method) == (q * c, c, "cholesky")
    ev = np.linalg.eigvalsh(f)
    assert int(np.sum(ev < 1e-10 * ev[-1])) == q * c == fim.nullity           # Th. 4.8.1
    nb = kernel_basis(g, g.vertex_rot, g.vertex_trans)
    assert nb.shape == (g.n * q, q * c)
    np.testing.assert_allclose(nb.T @ nb, np.eye(q * c), atol=MARGIN * g.n * EPS)   # sums of n_c terms 1/n_c
    np.testing.assert_allclose(f @ nb, 0, atol=1e-9 * ev[-1])
    # [delta; ...; delta] on one component, zero elsewhere
    labels = g.component_labels
    col = nb[:, 1].reshape(g.n, q)
    on = labels == 0
    np.testing.assert_allclose(col[on], np.tile(col[on][0], (on.sum(), 1)))
    assert np.all(col[~on] == 0)


def test_rank_deficiency_beyond_gauge_is_detected():
    """A zero information matrix on a bridge edge splits the identifiable structure: nullity 2q."""
    rng = np.random.default_rng(3)
    g = union(sed_graph(rng, 2, n=4), sed_graph(rng, 2, n=3, extra=1))
    g = replace(g, src=np.r_[g.src, 0], dst=np.r_[g.dst, 5], rot=np.r_[g.rot, g.rot[:1]],
                trans=np.r_[g.trans, g.trans[:1]], info=np.r_[g.info, g.info[:1]])
    assert g.n_components == 1
    om, _ = left_information(g)
    om[-1] = 0.0
    fim = sed_fim(g, g.vertex_rot, g.vertex_trans, information=om)
    assert (fim.nullity, fim.rank_method, fim.logdet_anchored) == (2 * g.q, "dense-eig", None)
    with pytest.raises(NotPositiveDefinite):
        sed_crlb(g, g.vertex_rot, g.vertex_trans, fim=fim)


# ------------------------------------------------------------------ CRBs
@pytest.mark.parametrize("dim", [2, 3])
def test_anchored_crb_is_the_dense_inverse_on_free_poses(dim):
    rng = np.random.default_rng(11 + dim)
    g = union(sed_graph(rng, dim, n=5), sed_graph(rng, dim, n=4, extra=2))
    q = g.q
    f = sed_fim(g, g.vertex_rot, g.vertex_trans).matrix.toarray()
    for anchors in (None, [1, 6], [0, 3, 5, 8]):
        res = sed_crlb(g, g.vertex_rot, g.vertex_trans, anchors=anchors, per_pose=True)
        used = [0, 5] if anchors is None else anchors        # smallest index per component
        assert res.anchors == used and res.kind == "anchored" and res.model == "sed"
        free = np.setdiff1d(np.arange(g.n), used)
        dofs = (free[:, None] * q + np.arange(q)).ravel()
        g_dense = np.zeros_like(f)
        g_dense[np.ix_(dofs, dofs)] = np.linalg.inv(f[np.ix_(dofs, dofs)])
        pi = np.diag(np.isin(np.arange(g.n * q) // q, free).astype(float))   # Pi = M (x) I_q
        np.testing.assert_allclose(g_dense, np.linalg.pinv(pi @ f @ pi, rcond=1e-12, hermitian=True),
                                   rtol=1e-6, atol=1e-9 * np.abs(g_dense).max())             # (5.1)
        f_ff = f[np.ix_(dofs, dofs)]
        rtol, atol = trace_inverse_rtol(f_ff), inverse_entry_atol(f_ff)
        np.testing.assert_allclose(res.trace_crlb, np.trace(g_dense), rtol=rtol)
        assert res.mse_bound == pytest.approx(np.trace(g_dense) / (g.n - len(used)), rel=rtol)
        assert res.accuracy is not None and res.accuracy.status.ok
        blocks = dense_blocks(g_dense, q)
        for i in range(g.n):
            assert_within(res.per_pose[i], blocks[i], atol, f"pose {i}")


@pytest.mark.parametrize("dim", [2, 3])
def test_quotient_crb_is_the_pseudoinverse(dim):
    rng = np.random.default_rng(21 + dim)
    g = union(union(sed_graph(rng, dim, n=5), sed_graph(rng, dim, n=4, extra=2)),
              sed_graph(rng, dim, n=3, extra=1))
    q, c = g.q, 3
    f = sed_fim(g, g.vertex_rot, g.vertex_trans).matrix.toarray()
    fp = np.linalg.pinv(f, rcond=1e-10, hermitian=True)                         # (5.5)
    ev = np.linalg.eigvalsh(f)
    assert ev[q * c - 1] < 1e-10 * ev[-1] < ev[q * c]        # the cut keeps exactly the range
    rtol, atol = pinv_trace_rtol(f, q * c), pinv_entry_atol(f, q * c)
    blocks = dense_blocks(fp, q)
    for anchors in (None, [2, 3, 4, 6, 10]):
        res = sed_crlb(g, g.vertex_rot, g.vertex_trans, anchors=anchors, quotient=True, per_pose=[0, 4, 9, 10])
        assert res.kind == "quotient" and res.nullity == q * c and res.components == c
        np.testing.assert_allclose(res.trace_crlb, np.trace(fp), rtol=rtol)
        assert res.mse_bound == pytest.approx(np.trace(fp) / (g.n - c), rel=rtol)
        assert sorted(res.per_pose) == [0, 4, 9, 10]
        for i, blk in res.per_pose.items():
            assert_within(blk, blocks[i], atol, f"pose {i}")


def test_unanchored_component_is_a_usage_error():
    rng = np.random.default_rng(5)
    g = union(sed_graph(rng, 2, n=4), sed_graph(rng, 2, n=3, extra=1))
    with pytest.raises(UsageError, match=r"component #1 \(3 poses"):
        sed_crlb(g, g.vertex_rot, g.vertex_trans, anchors=[0, 2])
    with pytest.raises(UsageError, match="out of range"):
        sed_crlb(g, g.vertex_rot, g.vertex_trans, anchors=[0, 99])


# ------------------------------------------------------------------ indefinite information
def indefinite_graph(rng):
    g = sed_graph(rng, 3, n=5)
    info = g.info.copy()
    info[:3] = np.diag([10.0, 10, 10, 10, 10, 10])
    info[:3, 2, 3] = info[:3, 3, 2] = 500.0     # PD blocks, indefinite whole (like cubicle.g2o)
    return replace(g, info=info)


def test_indefinite_information_policies(posecrb_log):
    g = indefinite_graph(np.random.default_rng(9))
    with pytest.raises(NotPositiveDefinite, match="3 of"):
        sed_fim(g, g.vertex_rot, g.vertex_trans, indefinite="raise")
    fb = sed_fim(g, g.vertex_rot, g.vertex_trans)
    assert "3 of 10" in posecrb_log.text and fb.indefinite_edges == 3 and fb.indefinite_policy == "blocks"
    # "blocks" == the file with those edges' cross terms removed
    info = g.info.copy()
    info[:3, :3, 3:] = 0
    info[:3, 3:, :3] = 0
    clean = sed_fim(replace(g, info=info), g.vertex_rot, g.vertex_trans)
    assert clean.indefinite_edges == 0
    # the same numbers through the same code: bit-identical whatever the machine
    np.testing.assert_array_equal(fb.matrix.toarray(), clean.matrix.toarray())
    # "project": nearest PSD (eigenvalues clipped at 0)
    fp = sed_fim(g, g.vertex_rot, g.vertex_trans, indefinite="project")
    lam, vec = np.linalg.eigh(g.info[0])
    proj = (vec * np.maximum(lam, 0)) @ vec.T
    info2 = g.info.copy()
    info2[:3] = proj
    # (the clipped matrix may come out with a -1e-14 eigenvalue: keep the same policy)
    ref = sed_fim(replace(g, info=info2), g.vertex_rot, g.vertex_trans, indefinite="project")
    np.testing.assert_allclose(fp.matrix.toarray(), ref.matrix.toarray(), rtol=1e-10, atol=1e-9)
    with pytest.raises(UsageError):
        sed_fim(g, g.vertex_rot, g.vertex_trans, indefinite="nope")


# ------------------------------------------------------------------ thesis chapter 6
def test_thesis_example_six_zero_eigenvalues():
    g = te.thesis_graph()
    rot, trans = te.true_estimate()
    fim = sed_fim(g, rot, trans)
    f = fim.matrix.toarray()
    ev = np.linalg.eigvalsh(f)
    assert int(np.sum(np.abs(ev) < 1e-9 * ev[-1])) == te.N_ZERO_EIGENVALUES == 6
    assert ev[6] > 1.0
    assert (fim.nullity, fim.components, fim.rank) == (6, 2, 9)
    # At the truth r_ij = 0, so J = [-Ad_{T_i}, Ad_{T_i}] with Ad from conjugation (2.7).
    rt, tt = te.true_poses()
    om = te.left_information()
    ref = np.zeros((15, 15))
    for k, (i, j) in enumerate(zip(te.SRC, te.DST)):
        t = homog(rt[i], tt[i])
        ad = np.stack([L.se_vee(t @ hat_ref(e) @ np.linalg.inv(t)) for e in np.eye(3)], 1)
        jac = np.zeros((3, 15))
        jac[:, 3 * i:3 * i + 3], jac[:, 3 * j:3 * j + 3] = -ad, ad
        ref += jac.T @ om[k] @ jac
    np.testing.assert_allclose(f, ref, atol=1e-10 * np.abs(ref).max())
    # block diagonal over the components {1,2} and {3,4,5} (sec. 6.6)
    assert np.all(f[:6, 6:] == 0)
    # the anchored bound with A = {1, 3} (sec. 6.7) and the quotient bound
    res = sed_crlb(g, rot, trans, anchors=te.ANCHORS, per_pose=True)
    dofs = np.r_[3:6, 9:15]
    f_ff = f[np.ix_(dofs, dofs)]
    np.testing.assert_allclose(res.trace_crlb, np.trace(np.linalg.inv(f_ff)), rtol=trace_inverse_rtol(f_ff))
    qres = sed_crlb(g, rot, trans, quotient=True)
    np.testing.assert_allclose(qres.trace_crlb, np.trace(np.linalg.pinv(f, rcond=1e-10, hermitian=True)),
                               rtol=pinv_trace_rtol(f, 6))
    assert qres.mse_bound == pytest.approx(qres.trace_crlb / 3)


def test_thesis_fixture_conventions_and_sampling():
    g = te.thesis_graph()
    np.testing.assert_allclose(left_information(g)[0], te.left_information(), rtol=1e-12, atol=1e-11)
    rot, trans = te.true_estimate()
    np.testing.assert_allclose(edge_residuals(g, rot, trans), 0, atol=1e-14)
    # the printed matrices of sec. 6.2 (4 digits)
    rt, _ = te.true_poses()
    np.testing.assert_allclose(rt[2], [[0.7317, 0.6816], [-0.6816, 0.7317]], atol=1e-4)
    np.testing.assert_allclose(rt[4], [[0.9888, 0.1494], [-0.1494, 0.9888]], atol=1e-4)
    # sampled measurements: residuals at the truth are the injected noise, ~ N(0, Sigma_ij)
    m = 4000
    gs = te.sample_graph(np.random.default_rng(0), m=m)
    assert gs.m == 6 * m and gs.n_components == 2
    np.testing.assert_allclose(left_information(gs)[0], np.repeat(te.left_information(), m, 0), rtol=1e-10,
                               atol=1e-10)
    res = edge_residuals(gs, rot, trans).reshape(6, m, 3)
    cov = np.einsum("emi,emj->eij", res, res) / m
    np.testing.assert_allclose(cov, te.sigma(), atol=0.1 * te.SIGMA_DIAG.max())
    # 2 independent samples per arc double the FIM to first order (4.12)
    g2 = te.sample_graph(np.random.default_rng(1), m=2)
    f1 = sed_fim(g, rot, trans).matrix.toarray()
    f2 = sed_fim(g2, rot, trans).matrix.toarray()
    np.testing.assert_allclose(f2, 2 * f1, rtol=0, atol=0.2 * np.abs(f1).max())


# ------------------------------------------------------------------ real data
@pytest.mark.slow
@pytest.mark.parametrize("name", ["intel", "smallGrid3D"])
def test_real_dataset_against_dense(shared_datasets, name):
    g = load(shared_datasets / f"{name}.g2o")
    fim = sed_fim(g, g.vertex_rot, g.vertex_trans)
    assert (fim.nullity, fim.components, fim.rank_method) == (g.q, 1, "cholesky")
    a = sed_crlb(g, g.vertex_rot, g.vertex_trans, fim=fim)
    qres = sed_crlb(g, g.vertex_rot, g.vertex_trans, fim=fim, quotient=True, per_pose=[0, g.n - 1])
    assert 0 < qres.trace_crlb <= a.trace_crlb
    if g.n * g.q <= 1000:
        f = fim.matrix.toarray()
        ev = np.linalg.eigvalsh(f)
        assert ev[g.q - 1] < 1e-11 * ev[-1] < ev[g.q]
        fp = np.linalg.pinv(f, rcond=1e-11, hermitian=True)
        np.testing.assert_allclose(qres.trace_crlb, np.trace(fp), rtol=pinv_trace_rtol(f, g.q))
        f_ff = f[g.q:, g.q:]
        np.testing.assert_allclose(a.trace_crlb, np.trace(np.linalg.inv(f_ff)), rtol=trace_inverse_rtol(f_ff))
        assert_within(qres.per_pose[g.n - 1], fp[-g.q:, -g.q:], pinv_entry_atol(f, g.q), "last pose")


def test_cubicle_indefinite_information_is_reported(shared_datasets, posecrb_log):
    g = load(shared_datasets / "cubicle.g2o")
    fim = sed_fim(g, g.vertex_rot, g.vertex_trans)
    assert fim.indefinite_edges > 0 and f"{fim.indefinite_edges} of {g.m}" in posecrb_log.text
    assert fim.nullity == 6
    with pytest.raises(NotPositiveDefinite):
        sed_fim(g, g.vertex_rot, g.vertex_trans, indefinite="raise")
