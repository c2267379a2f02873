"""All shared datasets against SE-Sync C++'s certified optima.

Why the file is read twice. SE-Sync's g2o reader builds each 3D measurement rotation with
Eigen's ``Quaternion(qw, qx, qy, qz).toRotationMatrix()`` WITHOUT normalising the quaternion,
so its R~ is slightly non-orthogonal (files print 6-9 digits), and its data matrix puts
``kappa I`` on the rotation diagonal blocks and ``-kappa R~`` off the diagonal. Its objective
is therefore ``sum kappa (2d - 2 tr(R_j^T R_i R~)) + tau ||t_j - t_i - R_i t~||^2``, which is not
``kappa ||R_j - R_i R~||_F^2`` when R~ is not orthogonal. The reference values (SE-Sync C++'s optima) were
computed that way. posecrb normalises quaternions by default (docs/design.md#sesync-quaternions), so:

- ``load(path, quaternions="raw")`` (SE-Sync's reading) reproduces the references: every
  dataset certifies and matches to ~1e-8 relative or better, except parking-garage, whose
  reference is 1.11e-6 ABOVE the certified optimum. That reference is not the minimum of its
  own objective: the independent evaluation below, at posecrb's feasible estimate (rotations in
  SO(3)), gives a lower value, so SE-Sync stopped early there (its trust region stops at a
  1e-6 relative decrease and certifies with a 1e-3 tolerance).
- the default normalised reading differs from the references by what the quaternion
  normalisation changes: tinyGrid3D -1.1e-6, cubicle -1.1e-5, parking-garage +3.1e-5 (the
  other datasets stay within 1e-6, 2D files are unaffected). The test does not pin these
  numbers (they depend on where each solver stops): it brackets the move between the two
  certified optima by the change of the objective at either estimate, widened by the two
  certified suboptimality bounds (tests/numerics.py).

The expected objective at an estimate is evaluated here independently of posecrb: the g2o
text is split by hand, R~ comes from Eigen's formula written out, tau and kappa from the
information blocks (docs/design.md#noise-model), and the rotation term from SE-Sync's definition.
"""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.io import load
from posecrb.solver import solve

from ..helpers import SESYNC_STOP, print_rounding
from ..numerics import objective_atol, suboptimality_bound

pytestmark = pytest.mark.slow   # every dataset against SE-Sync's optima: the longest module

REFERENCE = {
    "CSAIL": 31.703715992, "MIT": 61.154116091, "intel": 52.348227593, "kitti_05": 276.51437895,
    "manhattan": 6431.3913895, "kitti_02": 108.35114045, "kitti_00": 125.69351454, "city10000": 638.62462187,
    "ais2klinik": 188.50180666, "tinyGrid3D": 18.519386873, "smallGrid3D": 1025.3980207,
    "parking-garage": 1.2624855350, "sphere2500": 1687.0056783, "sphere_bignoise_vertex3": 2961756.5055,
    "torus3D": 24227.041546, "cubicle": 717.13404328,
}
# Normalised reading: the 3D datasets whose optimum moves by more than 1e-6 with the normalisation.
KNOWN_NORMALIZED = ["tinyGrid3D", "cubicle", "parking-garage"]
TORO = ["csail.toro", "w100.graph", "sphere_smallnoise.graph", "sphere_bignoise.graph", "w10000.graph"]


def eigen_to_rotation_matrix(qx, qy, qz, qw):
    """Eigen's Quaternion::toRotationMatrix() (Eigen/src/Geometry/Quaternion.h), no normalisation."""
    tx, ty, tz = 2 * qx, 2 * qy, 2 * qz
    twx, twy, twz = tx * qw, ty * qw, tz * qw
    txx, txy, txz = tx * qx, ty * qx, tz * qx
    tyy, tyz, tzz = ty * qy, tz * qy, tz * qz
    return np.stack([np.stack([1 - (tyy + tzz), txy - twz, txz + twy], -1),
                     np.stack([txy + twz, 1 - (txx + tzz), tyz - twx], -1),
                     np.stack([txz - twy, tyz + twx, 1 - (txx + tyy)], -1)], -2)


def sesync_objective(path, rot, trans, quaternions):
    """SE-Sync's objective of the g2o file at the estimate (rot, trans), indexed by increasing id."""
    rows = [ln.split() for ln in open(path) if ln.startswith("EDGE")]
    vals = np.array([[float(x) for x in r[1:]] for r in rows])
    ids = np.unique(vals[:, :2].astype(np.int64))
    i, j = np.searchsorted(ids, vals[:, 0].astype(np.int64)), np.searchsorted(ids, vals[:, 1].astype(np.int64))
    d = rot.shape[1]
    if d == 2:
        t, th, u = vals[:, 2:4], vals[:, 4], vals[:, 5:11]
        Rm = np.stack([np.stack([np.cos(th), -np.sin(th)], -1), np.stack([np.sin(th), np.cos(th)], -1)], -2)
        cov_t = np.linalg.inv(np.stack([np.stack([u[:, 0], u[:, 1]], -1), np.stack([u[:, 1], u[:, 3]], -1)], -2))
        tau = 2 / np.trace(cov_t, axis1=1, axis2=2)
        kappa = u[:, 5]
    else:
        t, q = vals[:, 2:5], vals[:, 5:9]
        if quaternions == "normalize":
            q = q / np.linalg.norm(q, axis=1, keepdims=True)
        Rm = eigen_to_rotation_matrix(*q.T)
        info = np.zeros((len(rows), 6, 6))
        iu = np.triu_indices(6)
        info[:, iu[0], iu[1]] = vals[:, 9:30]
        info[:, iu[1], iu[0]] = vals[:, 9:30]
        tau = 3 / np.trace(np.linalg.inv(info[:, :3, :3]), axis1=1, axis2=2)
        kappa = 3 / (2 * np.trace(np.linalg.inv(info[:, 3:, 3:]), axis1=1, axis2=2))
    # kappa I on both diagonal blocks, -kappa R~ off the diagonal: kappa (|R_i|^2 + |R_j|^2 - 2 tr(R_j^T R_i R~))
    cross = np.einsum("eab,eab->e", rot[j], rot[i] @ Rm)
    sq = np.einsum("eab,eab->e", rot[i], rot[i]) + np.einsum("eab,eab->e", rot[j], rot[j])
    res = trans[j] - trans[i] - np.einsum("eab,eb->ea", rot[i], t)
    return float(np.sum(kappa * (sq - 2 * cross)) + np.sum(tau * np.einsum("ea,ea->e", res, res)))


@pytest.mark.parametrize("name", list(REFERENCE))
def test_g2o_dataset_sesync_reading_matches_reference(shared_datasets, name):
    path = shared_datasets / f"{name}.g2o"
    g = load(path, quaternions="raw")
    res = solve(g)
    assert res.certified, res.reason
    # The reference form |R_i|^2 + |R_j|^2 - 2 tr(...) loses ~eps * 4d * sum(kappa) to cancellation
    # (2D kitti_*: sum kappa ~ 5e9, ~1e-9 relative); posecrb sums without cancelling.
    d = res.rot.shape[1]
    atol = objective_atol(g.kappa, d, res.objective)
    expected = sesync_objective(path, res.rot, res.trans, "raw")
    assert expected == pytest.approx(res.objective, abs=atol)
    # The reference is the objective at a feasible point, hence >= F* >= our value - our certified
    # suboptimality: ours can exceed it only by that bound plus the rounding of both evaluations.
    assert res.objective - REFERENCE[name] <= suboptimality_bound(res, g.n, d) + 2 * atol + print_rounding(
        REFERENCE[name])
    if res.objective < REFERENCE[name] * (1 - SESYNC_STOP):
        # more than SE-Sync's stopping tolerance below it: the reference is not the minimum; show a
        # feasible estimate (rotations in SO(3)) whose independent evaluation is below it
        np.testing.assert_allclose(res.rot @ np.swapaxes(res.rot, 1, 2), np.broadcast_to(np.eye(d), res.rot.shape),
                                   atol=10 * d * np.finfo(float).eps)
        np.testing.assert_allclose(np.linalg.det(res.rot), 1.0, atol=10 * d * np.finfo(float).eps)
        assert expected + atol < REFERENCE[name]


@pytest.mark.parametrize("name", KNOWN_NORMALIZED)
def test_g2o_dataset_normalized_reading(shared_datasets, name):
    """posecrb's default reading: certified, and moved from the SE-Sync reading's optimum by what the
    normalisation changes in the objective. With x_n, x_r the two certified estimates and sub_n,
    sub_r their certified suboptimality bounds, F_n(x_n) - F_r(x_r) lies in
    [F_n(x_n) - F_r(x_n) - sub_r, F_n(x_r) - F_r(x_r) + sub_n] (each optimum is below the other
    estimate's value up to its bound); F_n - F_r is evaluated independently (sesync_objective)."""
    path = shared_datasets / f"{name}.g2o"
    gn, gr = load(path), load(path, quaternions="raw")
    res_n, res_r = solve(gn), solve(gr)
    assert res_n.certified and res_r.certified, (res_n.reason, res_r.reason)
    d = res_n.rot.shape[1]
    atol = objective_atol(gn.kappa, d, res_n.objective) + objective_atol(gr.kappa, d, res_r.objective)
    f_nn = sesync_objective(path, res_n.rot, res_n.trans, "normalize")
    assert f_nn == pytest.approx(res_n.objective, abs=atol)
    f_rn = sesync_objective(path, res_n.rot, res_n.trans, "raw")
    f_nr = sesync_objective(path, res_r.rot, res_r.trans, "normalize")
    f_rr = sesync_objective(path, res_r.rot, res_r.trans, "raw")
    move = res_n.objective - res_r.objective
    lo = f_nn - f_rn - suboptimality_bound(res_r, gr.n, d) - 2 * atol
    hi = f_nr - f_rr + suboptimality_bound(res_n, gn.n, d) + 2 * atol
    assert lo <= move <= hi
    # these are the datasets where the normalisation matters beyond SE-Sync's stopping tolerance
    assert abs(f_nn - f_rn) > SESYNC_STOP * res_n.objective


@pytest.mark.parametrize("name", TORO)
def test_toro_dataset_certified(shared_datasets, name):
    res = solve(load(shared_datasets / "toro" / name))
    assert res.certified, res.reason
    if name == "csail.toro":   # same graph as CSAIL.g2o
        assert res.objective == pytest.approx(REFERENCE["CSAIL"], rel=1e-6)
