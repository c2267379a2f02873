"""Paper-model CRLB (posecrb.crlb) against dense evaluations of eq. (67) and eq. (68), for both FIM
variants (the consistent one also against the finite-difference Fisher information of the model)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from posecrb.crlb import paper_crlb
from posecrb.errors import DisconnectedGraph, UsageError
from posecrb.fim import FIM_VARIANTS, paper_fim

from .conftest import make_random_graph
from .test_fim import dense_model_fisher


def dense_eq68(f: np.ndarray, npf: int) -> np.ndarray:
    """Eq. (68) evaluated densely in the [translations; rotations] layout of eq. (64)."""
    finv = np.linalg.inv(f)
    k = 3 * npf
    iso3_inv = np.linalg.inv(f[k:, k:])
    ddiag = np.zeros_like(iso3_inv)
    for i in range(npf):
        s = slice(3 * i, 3 * i + 3)
        ddiag[s, s] = iso3_inv[s, s]
    lt = np.zeros_like(f)
    lt[k:, k:] = ddiag
    return finv - (lt @ finv + finv @ lt) / 12.0


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
    assert res.trace_crlb == pytest.approx(np.trace(finv), rel=1e-10)
    assert res.mse_bound == pytest.approx(np.trace(finv) / npf, rel=1e-10)
    assert res.trace_translation == pytest.approx(np.trace(finv[:2 * npf, :2 * npf]), rel=1e-10)
    assert res.trace_crlb_curvature is None and res.per_pose_curvature is None
    free = [k for k in range(g.n) if k != anchor]
    for t, k in enumerate(free):
        np.testing.assert_allclose(res.per_pose[int(g.ids[k])], pose_block(finv, npf, 2, 1, t),
                                   rtol=1e-9, atol=1e-14)
    np.testing.assert_array_equal(res.per_pose[int(g.ids[anchor])], np.zeros((3, 3)))


@pytest.mark.parametrize("variant", FIM_VARIANTS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_3d_curvature_term_matches_dense_eq68(seed, variant):
    rng = np.random.default_rng(seed)
    g = make_random_graph(rng, n=7, extra=5, dim=3)
    # small rotation information makes the curvature term visible
    scale = np.where(np.arange(6) >= 3, 0.2, 1.0)
    g = replace(g, info=g.info * scale[None, :, None] * scale[None, None, :])
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=0, per_pose=True, variant=variant)
    assert res.fim_variant == variant
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0, variant=variant).matrix.toarray()
    npf = g.n - 1
    bound = dense_eq68(f, npf)
    finv = np.linalg.inv(f)
    assert res.trace_crlb == pytest.approx(np.trace(finv), rel=1e-10)
    assert res.trace_crlb_curvature == pytest.approx(np.trace(bound), rel=1e-10)
    assert res.mse_bound_curvature == pytest.approx(np.trace(bound) / npf, rel=1e-10)
    assert abs(res.trace_crlb - res.trace_crlb_curvature) > 1e-8 * res.trace_crlb
    # Two inverses of F (selected inversion vs dense LU) agree norm-wise to about cond(F) eps, so
    # an entry may differ by that times the largest entry (cond ~5e6 here: a 1e-9 rtol is too tight).
    tol = 10 * np.linalg.cond(f) * np.finfo(float).eps
    for t in range(npf):
        pid = int(g.ids[t + 1])
        ref, ref_c = pose_block(finv, npf, 3, 3, t), pose_block(bound, npf, 3, 3, t)
        np.testing.assert_allclose(res.per_pose[pid], ref, rtol=0, atol=tol * np.abs(finv).max())
        np.testing.assert_allclose(res.per_pose_curvature[pid], ref_c, rtol=0, atol=tol * np.abs(bound).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_consistent_crlb_inverts_the_models_fisher_information(dim):
    """trace / curvature bound from the finite-difference Fisher information of the model (dense
    numpy inverse), anchor in the middle; in 2D the two variants give the same bound."""
    rng = np.random.default_rng(20 + dim)
    g = make_random_graph(rng, n=8, extra=6, dim=dim)
    anchor = 4
    res = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=anchor, variant="consistent")
    f = dense_model_fisher(g, g.vertex_rot, g.vertex_trans, anchor)
    f = (f + f.T) / 2
    npf = g.n - 1
    finv = np.linalg.inv(f)
    assert res.trace_crlb == pytest.approx(np.trace(finv), rel=1e-6)
    assert res.mse_bound == pytest.approx(np.trace(finv) / npf, rel=1e-6)
    if dim == 3:
        assert res.trace_crlb_curvature == pytest.approx(np.trace(dense_eq68(f, npf)), rel=1e-6)
        eq64 = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=anchor)
        assert abs(eq64.trace_crlb / res.trace_crlb - 1) > 1e-3
    else:
        eq64 = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=anchor)
        assert eq64.trace_crlb == res.trace_crlb and eq64.fim_variant == "eq64"


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
    keep = g.dst != 2
    g2 = replace(g, src=g.src[keep], dst=g.dst[keep], rot=g.rot[keep], trans=g.trans[keep], info=g.info[keep])
    with pytest.raises(DisconnectedGraph):
        paper_crlb(g2, g.vertex_rot, g.vertex_trans)


# ---------------------------------------------------------------- CLI `posecrb crlb`
def run_cli(argv, capsys):
    from posecrb.cli import main

    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


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
                "fim_variant"):
        assert key in row
    assert row["fim_variant"] == (variant or "eq64")
    # one warning, only for the implicit eq. (64) in 3D
    warned = [line for line in err.splitlines() if "warning" in line and "--fim-variant consistent" in line]
    assert len(warned) == (1 if dim == 3 and variant is None else 0), err
    f = paper_fim(g, g.vertex_rot, g.vertex_trans, variant=variant or "eq64").matrix.toarray()
    finv = np.linalg.inv(f)
    assert row["trace_crlb"] == pytest.approx(np.trace(finv), rel=1e-9)
    assert row["mse_bound"] == pytest.approx(np.trace(finv) / (g.n - 1), rel=1e-9)
    d, dr = dim, (1 if dim == 2 else 3)
    np.testing.assert_allclose(np.array(row["per_pose"][str(pid)]), pose_block(finv, g.n - 1, d, dr, 2),
                               rtol=1e-8, atol=1e-14)
    assert ("trace_crlb_curvature" in row) == (dim == 3)


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
