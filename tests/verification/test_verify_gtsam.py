"""posecrb verify on estimates written by GTSAM's own writer (``gtsam.writeG2o``, six significant
digits): Levenberg-Marquardt from odometry reaches the optimum's basin; from random rotations on a ring
it stops in a local minimum, whose gap is recomputed here edge by edge."""
from __future__ import annotations

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam", reason="gtsam is not installed (pip install '.[gtsam]' from a clone)")

import posecrb  # noqa: E402
from posecrb.io import write_g2o  # noqa: E402

from ..helpers import objective_loop, ring  # noqa: E402


def gtsam_lm(path: str, out: str, *, dim: int, initial=None, iterations: int = 100) -> None:
    """GTSAM's LM on the g2o file ``path`` (from its vertices, or ``initial``), written by ``writeG2o``."""
    graph, values = gtsam.readG2o(path, dim == 3)
    first = min(values.keys())
    if initial is not None:
        values = initial
    if dim == 2:
        graph.add(gtsam.PriorFactorPose2(first, values.atPose2(first), gtsam.noiseModel.Diagonal.Sigmas([1e-6] * 3)))
    else:
        graph.add(gtsam.PriorFactorPose3(first, values.atPose3(first), gtsam.noiseModel.Diagonal.Sigmas([1e-6] * 6)))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(iterations)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    gtsam.writeG2o(graph, result, out)


def test_lm_from_odometry_reaches_the_optimums_basin(shared_datasets, tmp_path):
    out = tmp_path / "intel_lm.g2o"
    gtsam_lm(str(shared_datasets / "intel.g2o"), str(out), dim=2)
    r = posecrb.verify("intel", str(out), data_dir=shared_datasets)
    assert r.verdict == "global-basin", r.verdict_reason
    assert 0 < r.relative_suboptimality < 0.5
    assert r.refined_objective == pytest.approx(r.optimum_objective, rel=1e-8)
    assert r.estimate["rotation_quantum"] > 1e-9            # six digits, seen as such


def _random_initial(g, dim: int, rng) -> object:
    values = gtsam.Values()
    for k, i in enumerate(g.ids):
        t = g.vertex_trans[k]
        if dim == 2:
            values.insert(int(i), gtsam.Pose2(float(t[0]), float(t[1]), float(rng.uniform(-np.pi, np.pi))))
        else:
            values.insert(int(i), gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(size=3) * 2.0), t))
    return values


@pytest.mark.parametrize("dim", [2, 3])
def test_lm_from_random_rotations_on_a_ring_is_a_local_minimum(tmp_path, dim):
    g = ring(30, dim)
    path = tmp_path / "ring.g2o"
    write_g2o(g, str(path))
    rng = np.random.default_rng(11)
    for attempt in range(20):                      # seeded starts until LM stops away from the optimum
        out = tmp_path / f"lm{attempt}.g2o"
        gtsam_lm(str(path), str(out), dim=dim, initial=_random_initial(g, dim, rng), iterations=300)
        r = posecrb.verify(str(path), str(out))
        if r.relative_suboptimality > 10:
            break
    else:
        pytest.fail("no start of the 20 left LM in a local minimum")
    assert r.verdict == "local-minimum", r.verdict_reason
    est = posecrb.verify(str(path), str(out), solve=False)
    assert est.verdict == "uncertified"
    # the gap, edge by edge: the estimate as written against solve's optimum
    lm = posecrb.load(out)
    sol = posecrb.solve(str(path))
    gap = objective_loop(g, lm.vertex_rot, lm.vertex_trans) - objective_loop(g, sol.rot, sol.trans)
    assert r.suboptimality == pytest.approx(gap, rel=1e-9)
