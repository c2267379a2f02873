"""One check of the matrices that must be rotations (posecrb.lie.so.check_rotations) wherever they
enter: an Estimate, a SolveResult built or loaded, the rows of an estimate file. Rotations off by
rounding are projected with a warning; scaled matrices, reflections, complex and non-finite values
are errors, never silent numbers."""
from __future__ import annotations

import dataclasses
import inspect
import math
import warnings

import numpy as np
import pytest
import scipy.linalg

import posecrb
from posecrb.lie.so import (
    PROJECTION_LIMIT,
    ROTATION_TOL_EPS,
    NotRotations,
    check_rotations,
    digits_tolerance,
    so2_exp,
    so3_exp,
)
from posecrb.sim.generators import grid

EPS = float(np.finfo(float).eps)


def _rotations(rng, n, d):
    return so2_exp(rng.uniform(-np.pi, np.pi, n)) if d == 2 else so3_exp(rng.normal(size=(n, 3)) * 2.0)


def _nearest(m):
    """The orthogonal polar factor (scipy), the nearest orthogonal matrix, independent of the SVD code."""
    return np.array([scipy.linalg.polar(x)[0] for x in m])


@pytest.mark.parametrize("d", [2, 3])
def test_rotations_pass_unchanged(d):
    r = _rotations(np.random.default_rng(1), 500, d)
    out, n = check_rotations(r)
    assert n == 0 and np.array_equal(out, r)
    # integer rotations (exact) too
    out, n = check_rotations(np.eye(d, dtype=int)[None])
    assert n == 0 and out.dtype == np.float64


@pytest.mark.parametrize("d", [2, 3])
def test_slightly_off_matrices_are_projected_with_one_warning(d, caplog):
    rng = np.random.default_rng(2)
    r = _rotations(rng, 200, d)
    off = r + rng.normal(size=r.shape) * 1e-7 * (np.arange(200) % 2 == 0)[:, None, None]   # half of them
    with caplog.at_level("WARNING", logger="posecrb"):
        out, n = check_rotations(off, name="poses")
    assert n == 100
    np.testing.assert_allclose(out[::2], _nearest(off[::2]), atol=1e-14)
    assert np.array_equal(out[1::2], off[1::2])
    (msg,) = [rec.getMessage() for rec in caplog.records]
    deviation = np.abs(np.einsum("kji,kjl->kil", off, off) - np.eye(d)).max()
    assert msg.startswith("poses: 100 of 200 matrices") and f"{deviation:.3g}" in msg


@pytest.mark.parametrize("bad,match", [
    (5 * np.eye(2), r"row 0 \(of 1\) is not a rotation: max \|R\^T R - I\| = 24 .*determinant 25"),
    (2 * so3_exp(np.array([0.1, 0.2, 0.3])), r"is not a rotation: max \|R\^T R - I\| = 3 .*determinant 8"),
    (np.diag([1.0, -1.0]), r"is a reflection \(determinant -1\)"),
    (-np.eye(3), r"is a reflection \(determinant -1\)"),
    (np.eye(2) * (1 + 2 * PROJECTION_LIMIT), "is not a rotation"),
    (np.eye(2) + 0j, "complex values"),
    (np.full((2, 2), np.nan), "non-finite"),
    (np.array([["1", "0"], ["0", "1"]]), "not real numbers"),
    (np.eye(4), r"shape \(1, 4, 4\)"),
])
def test_what_is_no_rotation_is_an_error_naming_the_rows(bad, match):
    with pytest.raises(NotRotations, match=match) as info:
        check_rotations(bad[None])
    assert info.value.rows.tolist() in ([0], [])


def test_the_error_names_the_rows_among_many():
    r = np.tile(np.eye(3), (10, 1, 1))
    r[[3, 7]] *= 2
    with pytest.raises(NotRotations, match=r"rows 3, 7 \(of 10\) are not rotations") as info:
        check_rotations(r)
    assert info.value.rows.tolist() == [3, 7]


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("digits", [4, 7, 10])
def test_the_tolerance_of_k_digits_bounds_their_rounding(d, digits):
    # rotations printed with k significant digits, as an estimate file holds them
    r = _rotations(np.random.default_rng(digits), 2000, d)
    printed = np.array([float(f"{x:.{digits - 1}e}") for x in r.ravel()]).reshape(r.shape)
    deviation = np.abs(np.einsum("kji,kjl->kil", printed, printed) - np.eye(d)).max()
    tol = digits_tolerance(digits, d)
    assert deviation <= tol and deviation > tol / 1e3               # the bound, and not a vacuous one
    out, n = check_rotations(printed, tol=tol)
    assert n == 0 and np.array_equal(out, printed)


def test_the_default_tolerance_is_a_few_hundred_eps_of_the_input_type():
    r = so3_exp(np.array([[0.3, -0.2, 0.1]]))
    off = r * (1 + 0.5 * ROTATION_TOL_EPS * EPS)                      # within: unchanged
    assert check_rotations(off)[1] == 0
    assert check_rotations(r * (1 + 4 * ROTATION_TOL_EPS * EPS))[1] == 1
    # float32 input: its own epsilon
    assert check_rotations(r.astype(np.float32))[1] == 0


# ---------------------------------------------------------------- where rotations enter the library
def _graph():
    return grid(2, 4, noise=True, rng=3)


def test_estimate_of_no_rotations_is_an_argument_error():
    g = _graph()
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                 # no ComplexWarning either
        for rot in (5 * np.tile(np.eye(2), (g.n, 1, 1)), np.tile(np.diag([1.0, -1.0]), (g.n, 1, 1)),
                    2 * g.vertex_rot, g.vertex_rot.astype(complex), np.where(True, np.nan, g.vertex_rot)):
            with pytest.raises(posecrb.ArgumentError, match="^rot="):
                posecrb.Estimate(rot, g.vertex_trans)
        for trans in (g.vertex_trans.astype(complex), g.vertex_trans[:-1], np.full_like(g.vertex_trans, np.inf)):
            with pytest.raises(posecrb.ArgumentError, match="^trans="):
                posecrb.Estimate(g.vertex_rot, trans)
    est = posecrb.Estimate(g.vertex_rot, g.vertex_trans)
    with pytest.raises(posecrb.ArgumentError, match="^rot="):
        dataclasses.replace(est, rot=2 * g.vertex_rot)


ESTIMATE_FUNCTIONS = [name for name in posecrb.__all__ if inspect.isfunction(getattr(posecrb, name))
                      and "estimate" in inspect.signature(getattr(posecrb, name)).parameters]


def test_every_public_function_with_an_estimate_is_listed():
    assert set(ESTIMATE_FUNCTIONS) == {"bounds", "fim", "crlb", "select", "timeline", "verify"}


@pytest.mark.parametrize("name", ESTIMATE_FUNCTIONS)
def test_every_function_evaluates_a_slightly_off_estimate_at_the_nearest_rotations(name, caplog):
    g = _graph()
    kwargs = {"budget": 3, "objective": "fim"} if name == "select" else {}
    fn = getattr(posecrb, name)
    with caplog.at_level("WARNING", logger="posecrb"):
        off = posecrb.Estimate(g.vertex_rot * (1 + 1e-9), g.vertex_trans)
    assert any("replaced by the nearest rotations" in r.getMessage() for r in caplog.records)
    exact = posecrb.Estimate(_nearest(g.vertex_rot * (1 + 1e-9)), g.vertex_trans)
    a, b = fn(g, estimate=off, **kwargs).to_dict(), fn(g, estimate=exact, **kwargs).to_dict()
    for key in ("fim_logdet", "lb", "logdet", "trace_crlb", "value", "objective"):
        if isinstance(a.get(key), float):
            assert a[key] == pytest.approx(b[key], rel=1e-12, abs=1e-12), key


def test_a_loaded_result_with_no_rotations_is_refused(tmp_path):
    g = _graph()
    res = posecrb.solve(g)
    path = res.save(tmp_path / "res.npz")
    assert np.array_equal(posecrb.SolveResult.load(path).rot, res.rot)
    with np.load(path) as npz:
        data = {k: npz[k] for k in npz.files}
    for rot in (2 * data["rot"], data["rot"] * np.array([1.0, -1.0])[:, None], data["rot"] + 0j):
        np.savez(tmp_path / "bad.npz", **{**data, "rot": rot})
        with pytest.raises(posecrb.ParseError, match=r"bad\.npz: a malformed SolveResult \(rot="):
            posecrb.SolveResult.load(tmp_path / "bad.npz")


def test_the_vertices_and_the_solvers_rotations_pass_without_a_warning(shared_datasets, caplog):
    # real files' vertices (angles, unit quaternions) and the solver's estimate are rotations to
    # within the default tolerance: no warning, values unchanged
    with caplog.at_level("WARNING", logger="posecrb"):
        for name in ("intel.g2o", "sphere2500.g2o", "parking-garage.g2o", "kitti_00.g2o"):
            g = posecrb.load(shared_datasets / name)
            if g.vertex_rot is not None:
                est = posecrb.Estimate(g.vertex_rot, g.vertex_trans)
                assert np.array_equal(est.rot, g.vertex_rot)
        res = posecrb.solve(shared_datasets / "intel.g2o")
    assert not [r for r in caplog.records if "nearest rotations" in r.getMessage()]
    deviation = np.abs(np.einsum("kji,kjl->kil", res.rot, res.rot) - np.eye(2)).max()
    assert deviation <= ROTATION_TOL_EPS * EPS and math.isfinite(deviation)
