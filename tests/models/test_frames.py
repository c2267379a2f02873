"""World <-> body frame conversion of the thesis model against a dense finite-difference reference.

The reference never uses posecrb.models.sed.frames or posecrb.models.sed.fim: it differentiates the g2o/GTSAM
error
``e_ij = Log(z^{-1} X_i^{-1} X_j)`` (scipy's expm, posecrb.lie.se's checked Log) under body-frame retractions
``X_i expm(hat(xi_i))`` with ``xi`` in GTSAM's order (Pose2 (x, y, theta), Pose3 (rotation,
translation)) and weights it with the file's information matrix reordered the same way: the
Hessian GTSAM builds, in dense numpy.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp

from posecrb.models.sed.crlb import sed_crlb
from posecrb.models.sed.fim import kernel_basis, sed_fim
from posecrb.models.sed.frames import (
    FRAMES,
    body_map,
    convert_covariance_blocks,
    convert_information,
    coordinate_names,
    sed_crlb_in_frame,
    world_map,
)

from ..helpers import (
    body_fim_reference,
    consistent_graph,
    free_dofs,
    run_cli,
)

FD_RTOL = 1e-8


# ------------------------------------------------------------------ tests
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("dim", [2, 3])
def test_body_fim_is_the_gtsam_hessian_reference(dim, seed):
    g = consistent_graph(dim, seed)
    r, t = g.vertex_rot, g.vertex_trans
    ref = body_fim_reference(g, r, t)
    fb = convert_information(sed_fim(g, r, t).matrix, r, t, "body").toarray()
    assert np.abs(fb - fb.T).max() == 0.0
    np.testing.assert_allclose(fb, ref, rtol=0, atol=FD_RTOL * np.abs(ref).max())


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("dim", [2, 3])
def test_body_anchored_blocks_are_the_dense_inverse(dim, seed):
    g = consistent_graph(dim, seed)
    r, t = g.vertex_rot, g.vertex_trans
    q, n = g.q, g.n
    ref = body_fim_reference(g, r, t)
    anchors = [0, 4]
    dofs = free_dofs(n, q, anchors)
    cov = np.zeros((n * q, n * q))
    cov[np.ix_(dofs, dofs)] = np.linalg.inv(ref[np.ix_(dofs, dofs)])
    cond = np.linalg.cond(ref[np.ix_(dofs, dofs)])
    res = sed_crlb_in_frame(g, r, t, "body", anchors=anchors, per_pose=True)
    assert res.frame == "body"
    for i in range(n):
        blk = cov[i * q:(i + 1) * q, i * q:(i + 1) * q]
        np.testing.assert_allclose(res.per_pose[i], blk, rtol=0,
                                   atol=10 * cond * FD_RTOL * np.abs(cov).max())
    assert res.trace_crlb == pytest.approx(np.trace(cov), rel=10 * cond * FD_RTOL)
    assert res.mse_bound == pytest.approx(res.trace_crlb / (n - 2), rel=1e-15)


@pytest.mark.parametrize("dim", [2, 3])
def test_gauge_directions_in_body_coordinates(dim):
    """ker F_world is [delta; ...; delta] (Th. 4.8.1); in body coordinates it is [B_i delta]_i,
    which the independent body Hessian annihilates."""
    g = consistent_graph(dim, 2)
    r, t = g.vertex_rot, g.vertex_trans
    ref = body_fim_reference(g, r, t)
    n_world = kernel_basis(g)
    b = body_map(r, t)
    n_body = np.einsum("iab,ibc->iac", b, n_world.reshape(g.n, g.q, g.q)).reshape(g.n * g.q, g.q)
    scale = np.abs(ref).max() * np.abs(n_body).max()
    assert np.abs(ref @ n_body).max() < 1e2 * FD_RTOL * scale


@pytest.mark.parametrize("dim", [2, 3])
def test_round_trips_and_invariants(dim):
    g = consistent_graph(dim, 3)
    r, t = g.vertex_rot, g.vertex_trans
    q, n = g.q, g.n
    np.testing.assert_allclose(body_map(r, t) @ world_map(r, t), np.broadcast_to(np.eye(q), (n, q, q)),
                               atol=1e-12)
    np.testing.assert_allclose(np.abs(np.linalg.det(body_map(r, t))), 1.0, rtol=1e-12)
    fim = sed_fim(g, r, t)
    fb = convert_information(fim.matrix, r, t, "body")
    back = convert_information(fb, r, t, "world").toarray()
    np.testing.assert_allclose(back, fim.matrix.toarray(), rtol=0, atol=1e-11 * abs(fim.matrix).max())
    # log det (anchored), rank: the same in both frames; the pattern is kept
    dofs = free_dofs(n, q, [0])
    ld_w = np.linalg.slogdet(fim.matrix.toarray()[np.ix_(dofs, dofs)])
    ld_b = np.linalg.slogdet(fb.toarray()[np.ix_(dofs, dofs)])
    assert ld_w[0] == ld_b[0] == 1 and ld_b[1] == pytest.approx(ld_w[1], abs=1e-9)
    assert np.linalg.matrix_rank(fb.toarray()) == fim.rank
    assert (abs(fb) > 0).astype(int).nnz <= (abs(fim.matrix) > 0).astype(int).nnz
    blocks = np.stack([v for _, v in sorted(sed_crlb(g, r, t, per_pose=True).per_pose.items())])
    there = convert_covariance_blocks(blocks, r, t, "body")
    np.testing.assert_allclose(convert_covariance_blocks(there, r, t, "world"), blocks, rtol=0,
                               atol=1e-11 * np.abs(blocks).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_quotient_in_body_frame_is_a_generalised_inverse(dim):
    g = consistent_graph(dim, 4)
    r, t = g.vertex_rot, g.vertex_trans
    q, n = g.q, g.n
    f = sed_fim(g, r, t).matrix.toarray()
    fplus = np.linalg.pinv(f, rcond=1e-10, hermitian=True)
    bmat = sp.block_diag(list(body_map(r, t))).toarray()
    gb = bmat @ fplus @ bmat.T
    fb = convert_information(sp.csc_matrix(f), r, t, "body").toarray()
    np.testing.assert_allclose(fb @ gb @ fb, fb, rtol=0, atol=1e-8 * np.abs(fb).max())
    res = sed_crlb_in_frame(g, r, t, "body", quotient=True, per_pose=[1, 3])
    assert sorted(res.per_pose) == [1, 3]
    for i in (1, 3):
        np.testing.assert_allclose(res.per_pose[i], gb[i * q:(i + 1) * q, i * q:(i + 1) * q], rtol=1e-7,
                                   atol=1e-9 * np.abs(gb).max())
    assert res.trace_crlb == pytest.approx(np.trace(gb), rel=1e-8)
    assert res.mse_bound == pytest.approx(np.trace(gb) / (n - 1), rel=1e-8)


def test_world_frame_is_sed_crb_unchanged():
    g = consistent_graph(2, 5)
    r, t = g.vertex_rot, g.vertex_trans
    a = sed_crlb(g, r, t, per_pose=[2])
    b = sed_crlb_in_frame(g, r, t, "world", per_pose=[2])
    assert b.frame == "world" and a.trace_crlb == b.trace_crlb
    np.testing.assert_array_equal(a.per_pose[2], b.per_pose[2])


def test_coordinate_names_and_bad_frame():
    from posecrb.core.errors import UsageError

    assert FRAMES == ("world", "body")
    assert coordinate_names(2, "body") == ["x", "y", "theta"]
    assert coordinate_names(3, "body")[:3] == ["rx", "ry", "rz"]
    assert coordinate_names(2, "world") == ["omega", "vx", "vy"]
    with pytest.raises(UsageError):
        coordinate_names(2, "gtsam")
    g = consistent_graph(2, 6)
    with pytest.raises(UsageError):
        sed_crlb_in_frame(g, g.vertex_rot, g.vertex_trans, "body", per_pose=[g.n])


# ------------------------------------------------------------------ CLI
@pytest.mark.parametrize("dim", [2, 3])
def test_cli_crlb_and_fim_frames(dim, tmp_path, capsys):
    from posecrb.io import load, write_g2o

    path = tmp_path / f"f{dim}.g2o"
    write_g2o(consistent_graph(dim, 7), path)
    g = load(path)
    r, t = g.vertex_rot, g.vertex_trans
    base = ["crlb", str(path), "--model", "sed", "--estimate", "vertices", "--poses", "all", "--format", "json"]
    code, out, err = run_cli(base, capsys)
    assert code == 0, err
    world = json.loads(out)
    assert world["frame"] == "world" and world["coordinates"] == coordinate_names(dim, "world")
    assert "world" in world["coordinates_description"]
    code, out, err = run_cli(base + ["--frame", "body"], capsys)
    assert code == 0, err
    body = json.loads(out)
    assert body["frame"] == "body" and body["coordinates"] == coordinate_names(dim, "body")
    assert "X_i Exp(xi)" in body["coordinates_description"]
    ref = body_fim_reference(g, r, t)
    dofs = free_dofs(g.n, g.q, [0])
    cov = np.linalg.inv(ref[np.ix_(dofs, dofs)])
    cond = np.linalg.cond(ref[np.ix_(dofs, dofs)])
    assert body["trace_crlb"] == pytest.approx(np.trace(cov), rel=10 * cond * FD_RTOL)
    k = int(g.ids[3])
    np.testing.assert_allclose(np.array(body["per_pose"][str(k)]), cov[2 * g.q:3 * g.q, 2 * g.q:3 * g.q],
                               rtol=0, atol=10 * cond * FD_RTOL * np.abs(cov).max())

    npz = tmp_path / "fb.npz"
    code, out, err = run_cli(["fim", str(path), "--model", "sed", "--estimate", "vertices", "--frame", "body",
                              "--save", str(npz), "--format", "json"], capsys)
    assert code == 0, err
    row = json.loads(out)
    assert row["frame"] == "body"
    saved = sp.load_npz(npz).toarray()
    np.testing.assert_allclose(saved, ref, rtol=0, atol=FD_RTOL * np.abs(ref).max())
    with np.load(npz) as z:
        assert str(z["frame"]) == "body" and list(z["coordinate_names"]) == coordinate_names(dim, "body")
    assert row["trace"] == pytest.approx(np.trace(ref), rel=FD_RTOL)
    code, out, err = run_cli(["fim", str(path), "--model", "sed", "--estimate", "vertices", "--format", "json"],
                             capsys)
    world_fim = json.loads(out)
    assert world_fim["frame"] == "world" and world_fim["logdet"] == pytest.approx(row["logdet"], abs=1e-9)


@pytest.mark.parametrize("cmd", ["crlb", "fim"])
def test_cli_frame_with_paper_model_is_a_usage_error(cmd, tmp_path, capsys):
    from posecrb.io import write_g2o

    path = tmp_path / "p.g2o"
    write_g2o(consistent_graph(2, 8), path)
    code, _, err = run_cli([cmd, str(path), "--estimate", "vertices", "--frame", "body"], capsys)
    assert code == 2 and "--frame body applies to the sed model" in err
    code, out, err = run_cli([cmd, str(path), "--estimate", "vertices", "--format", "json"], capsys)
    assert code == 0 and json.loads(out)["frame"] == "mixed"
