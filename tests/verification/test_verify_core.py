"""The verdict of posecrb.verification on estimates with a known answer: the certified optimum, a
perturbed one, a pose moved across the map, a planted local minimum, an estimate written with few digits."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.graph import PoseGraph
from posecrb.lie.so import so2_exp, so3_exp
from posecrb.solver.problem import Problem
from posecrb.solver.refine import refine
from posecrb.solver.solve import solve
from posecrb.verification.judge import Precision
from posecrb.verification.verify import Poses, verify_estimate

from ..helpers import objective_loop, ring
from ..numerics import EPS


def judged(g: PoseGraph, rot, trans, precision=None, **kw):
    return verify_estimate(g, Poses(rot, trans, precision or Precision.exact(g.n), {"source": "test"}), **kw)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_certified_optimum_is_certified_from_its_own_certificate(dim):
    g = ring(24, dim, closures=4)
    sol = solve(g)
    assert sol.certified
    for run_solve in (False, True):
        r = judged(g, sol.rot, sol.trans, run_solve=run_solve)
        assert r.verdict == "certified-optimal", r.verdict_reason
        assert r.lower_bound is not None and r.lower_bound <= r.objective
        assert r.objective == pytest.approx(objective_loop(g, sol.rot, sol.trans), rel=100 * g.m * EPS)
    assert r.suboptimality == pytest.approx(0.0, abs=100 * g.m * EPS * sol.objective)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_perturbed_optimum_is_in_the_basin_with_a_nonzero_gradient(dim):
    g = ring(24, dim, closures=4)
    sol = solve(g)
    rng = np.random.default_rng(3)
    turn = so2_exp(1e-3 * rng.standard_normal(g.n)) if dim == 2 else so3_exp(1e-3 * rng.standard_normal((g.n, 3)))
    rot, trans = sol.rot @ turn, sol.trans + 1e-3 * rng.standard_normal(sol.trans.shape)
    r = judged(g, rot, trans)
    assert r.verdict == "global-basin", r.verdict_reason
    assert r.gradient_norm > 1e-6
    assert r.refined_objective == pytest.approx(sol.objective, rel=1e-8)
    assert r.suboptimality == pytest.approx(objective_loop(g, rot, trans) - objective_loop(g, sol.rot, sol.trans),
                                            rel=1e-9, abs=100 * g.m * EPS * sol.objective)
    assert r.ate_trans > 0 and r.mahalanobis["total"] > 0


@pytest.mark.parametrize("dim", [2, 3])
def test_one_pose_moved_across_the_map_is_not_certified(dim):
    g = ring(24, dim, closures=4)
    sol = solve(g)
    trans = sol.trans.copy()
    trans[7] += 25.0
    r = judged(g, sol.rot, trans)
    assert r.verdict != "certified-optimal"
    assert not r.certificate["critical"]
    gap = objective_loop(g, sol.rot, trans) - objective_loop(g, sol.rot, sol.trans)
    assert r.suboptimality == pytest.approx(gap, rel=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_planted_local_minimum_is_one(dim):
    """A ring twisted once: each edge carries 1/n of a full turn, a critical point far above the optimum."""
    g = ring(30, dim)
    n = g.n
    z = np.zeros(n)
    twist = so2_exp(2 * np.pi * np.arange(n) / n) if dim == 2 else \
        so3_exp(np.column_stack([z, z, 2 * np.pi * np.arange(n) / n]))
    stuck = refine(Problem.from_graph(g), g.vertex_rot @ twist)
    r = judged(g, stuck.rot, stuck.trans)
    assert r.verdict == "local-minimum", r.verdict_reason
    sol = solve(g)
    gap = objective_loop(g, stuck.rot, stuck.trans) - objective_loop(g, sol.rot, sol.trans)
    # F's terms are O(1) each here: the two edge-by-edge sums agree to ~m eps relative
    assert r.suboptimality == pytest.approx(gap, rel=1e-9)
    assert r.refined_objective == pytest.approx(objective_loop(g, stuck.rot, stuck.trans), rel=1e-9)
    assert r.relative_suboptimality > 100


@pytest.mark.parametrize("dim", [2, 3])
def test_six_digits_of_the_optimum_are_certified_and_other_costs_optimum_is_not(dim):
    """The optimum written with 6 significant digits is optimal within its digits; the least-squares
    optimum of the linearised g2o-like cost (here: a few Gauss-Newton steps' worth of a 1e-2 shift)
    is not."""
    g = ring(24, dim, closures=4)
    sol = solve(g)
    six = np.vectorize(lambda x: float(f"{x:.6g}"))
    if dim == 2:
        th = six(np.arctan2(sol.rot[:, 1, 0], sol.rot[:, 0, 0]))
        rot = so2_exp(th)
        rq = np.abs(th) * 1e-5
    else:
        from scipy.spatial.transform import Rotation
        q = six(Rotation.from_matrix(sol.rot).as_quat())
        rot = Rotation.from_quat(q).as_matrix()
        rq = np.abs(q).max(axis=1) * 1e-5
    trans = six(sol.trans)
    tq = np.abs(sol.trans).max(axis=1) * 1e-5
    r = judged(g, rot, trans, Precision(rq, tq), run_solve=False)
    assert r.verdict == "certified-optimal", r.verdict_reason
    # the same point read as exact float64 is not converged to solve's tolerance
    assert not judged(g, rot, trans, run_solve=False).certificate["critical"]


def test_where_the_relaxation_is_not_exact_nothing_is_certified(tmp_path):
    """A noisy grid whose relaxation is not exact: solve's own estimate is uncertified, with solve's gap."""
    from posecrb.core.noise import precisions_from_sigma
    from posecrb.sim.generators import generate

    tau, kappa = precisions_from_sigma(0.5)       # posecrb datasets synth grid2d --poses 25 --noise 0.5 --seed 1
    g = generate("grid2d", 25, tau=tau, kappa=kappa, noise=True, seed=1)
    sol = solve(g)
    assert sol.certified and not sol.duality_gap_status.ok      # the premise: an inexact relaxation
    r = judged(g, sol.rot, sol.trans)
    assert r.verdict == "uncertified", r.verdict_reason
    assert f"{sol.duality_gap:.3g}" in r.verdict_reason
    assert r.lower_bound_source == "solve's certified relaxation"
    assert r.lower_bound <= sol.relaxation_value <= r.objective
    assert r.optimum_status.state == "warning"


def test_the_certificate_and_the_refinement_run_under_the_solvers_thread_policy(monkeypatch):
    """The judgements at the estimate and at the optimum and the refinement run the solver's linear
    algebra as ``solve`` does: CHOLMOD's BLAS at one thread for a small graph, even where the
    caller left it at two (outside that policy each Lanczos solve paid for the threads)."""
    import posecrb.verification.verify as verify_mod
    from posecrb.linalg import threads

    g = ring(24, 3, closures=4)
    sol = solve(g)
    seen: dict[str, list[int]] = {"judge": [], "refine": []}
    for name, real in (("judge", verify_mod.judge), ("refine", verify_mod.refine)):
        def spy(*args, _real=real, _name=name, **kwargs):
            seen[_name].append(threads.cholmod_threads())
            return _real(*args, **kwargs)
        monkeypatch.setattr(verify_mod, name, spy)
    rng = np.random.default_rng(3)
    rot = sol.rot @ so3_exp(1e-3 * rng.standard_normal((g.n, 3)))
    with threads.cholmod_blas().limit(limits=2):
        if threads.cholmod_threads() != 2:
            pytest.skip("CHOLMOD's BLAS cannot be given two threads here")
        judged(g, rot, sol.trans)
        assert threads.cholmod_threads() == 2      # restored after the call
    assert seen == {"judge": [1, 1], "refine": [1]}
