"""The solver's base preconditioner: SE-Sync's (Q + delta I)^{-1} through M_red, or the rotation
block's (C + delta I)^{-1} (posecrb.solver.problem.RotationBlockFactor), and the rule between them."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import UsageError
from posecrb.linalg.ordering import AUTO_ND_MIN_POSES, AUTO_ND_MIN_POSES_2D
from posecrb.solver import PreconditionerSettings, SolverOptions, solve
from posecrb.solver.options import BASE_PRECONDITIONERS
from posecrb.solver.preconditioners import base_preconditioner_kind
from posecrb.solver.problem import Problem, RotationBlockFactor
from posecrb.solver.trust_region import TROptions

from ..helpers import random_pose_graph, record_factor_full
from ..numerics import EPS, MARGIN, spd_condition


@pytest.mark.parametrize("dim", [2, 3])
def test_rotation_block_factor_solves_with_the_dense_rotation_block(dim):
    rng = np.random.default_rng(30 + dim)
    graph = random_pose_graph(25, dim, rng, loop_closures=15, rot_noise=0.1, trans_noise=0.1)[0]
    problem = Problem.from_graph(graph)
    shift = 1e-3 * problem.gershgorin_max()
    factor = problem.factor_rotation_block(shift, name="C + s I")
    assert isinstance(factor, RotationBlockFactor) and factor.shift == shift
    dense = problem.C.toarray() + shift * np.eye(problem.n * dim)
    W = rng.standard_normal((problem.n * dim, dim + 1))
    reference = np.linalg.solve(dense, W)
    # two backward-stable solves: ||x - x*|| <= c n kappa eps ||x*|| each
    tol = MARGIN * dense.shape[0] * spd_condition(dense) * EPS * np.abs(reference).max()
    np.testing.assert_allclose(factor.solve(W), reference, rtol=0, atol=tol)


def test_auto_takes_the_rotation_block_on_large_3d_graphs_only():
    assert base_preconditioner_kind("auto", 3, AUTO_ND_MIN_POSES) == "rotation"
    assert base_preconditioner_kind("auto", 3, AUTO_ND_MIN_POSES - 1) == "schur"
    for poses in (10, AUTO_ND_MIN_POSES_2D, 10 * AUTO_ND_MIN_POSES_2D):
        assert base_preconditioner_kind("auto", 2, poses) == "schur"
    for kind in ("schur", "rotation"):
        assert base_preconditioner_kind(kind, 3, 10) == kind
        assert base_preconditioner_kind(kind, 2, 10 ** 6) == kind
    assert SolverOptions().preconditioner_settings.base == "auto"
    assert set(BASE_PRECONDITIONERS) == {"auto", "schur", "rotation"}
    with pytest.raises(UsageError, match="base preconditioner"):
        base_preconditioner_kind("cholesky", 3, 10)
    with pytest.raises(UsageError, match="base preconditioner"):
        PreconditionerSettings(base="cholesky")
    with pytest.raises(UsageError, match="base preconditioner"):
        solve(random_pose_graph(5, 3, np.random.default_rng(0))[0],
              preconditioner_settings=PreconditionerSettings(base="C"))


@pytest.mark.parametrize("dim", [2, 3])
def test_both_base_preconditioners_reach_the_same_certified_optimum(dim, monkeypatch):
    rng = np.random.default_rng(40 + dim)
    graph = random_pose_graph(40, dim, rng, loop_closures=30, rot_noise=0.1, trans_noise=0.1)[0]
    calls = record_factor_full(monkeypatch)
    built: list[float] = []
    real = Problem.factor_rotation_block

    def recording(self, shift, name):
        built.append(shift)
        return real(self, shift, name)

    monkeypatch.setattr(Problem, "factor_rotation_block", recording)
    # the base preconditioner serves the whole first level where the tangent one is off
    schur = solve(graph, preconditioner="base", preconditioner_settings=PreconditionerSettings(base="schur"))
    assert not built and calls[0][0] == "preconditioner M_red(delta)"
    calls.clear()
    rotation = solve(graph, preconditioner="base", preconditioner_settings=PreconditionerSettings(base="rotation"))
    assert len(built) == 1
    assert "preconditioner M_red(delta)" not in [name for name, _ in calls]
    assert schur.certified and rotation.certified
    # both stop at a Newton decrement of decrement_tol |f| (TROptions), past the quadratic phase
    tol = 100 * TROptions().decrement_tol
    assert rotation.objective == pytest.approx(schur.objective, rel=tol)
    assert rotation.relaxation_value == pytest.approx(schur.relaxation_value, rel=tol)


def test_auto_is_schur_on_small_graphs():
    rng = np.random.default_rng(8)
    graph = random_pose_graph(30, 3, rng, loop_closures=20, rot_noise=0.1, trans_noise=0.1)[0]
    default = solve(graph)
    schur = solve(graph, preconditioner_settings=PreconditionerSettings(base="schur"))
    assert default.objective == schur.objective
    assert default.hessian_vector_products == schur.hessian_vector_products


def _count_calls(monkeypatch, cls, name: str) -> list[int]:
    """Count the calls of ``cls.name`` from now on (monkeypatched); the count is ``calls[0]``."""
    calls = [0]
    real = getattr(cls, name)

    def counting(self, *args, **kwargs):
        calls[0] += 1
        return real(self, *args, **kwargs)

    monkeypatch.setattr(cls, name, counting)
    return calls


def test_preconditioner_solves_count_every_application_of_the_rotation_block(monkeypatch):
    from posecrb.solver.tangent import TangentSystem

    rng = np.random.default_rng(12)
    graph = random_pose_graph(40, 3, rng, loop_closures=30, rot_noise=0.1, trans_noise=0.1)[0]
    rotation_solves = _count_calls(monkeypatch, RotationBlockFactor, "solve")
    tangent_applies = _count_calls(monkeypatch, TangentSystem, "apply")
    res = solve(graph, preconditioner="base",
                preconditioner_settings=PreconditionerSettings(base="rotation", adaptive_shift=None))
    # the rotation block's factor is used for nothing but preconditioning, and without the
    # adaptive or tangent factors every application is the base one
    assert res.preconditioner_solves == {"rotation": rotation_solves[0]}
    assert rotation_solves[0] > 0 and tangent_applies[0] == 0
    rotation_solves[0] = 0
    schur = solve(graph, preconditioner="base",
                  preconditioner_settings=PreconditionerSettings(base="schur", adaptive_shift=None))
    assert set(schur.preconditioner_solves) == {"schur"} and rotation_solves[0] == 0
    # truncated CG preconditions its first residual, then one per product that does not end it
    assert schur.preconditioner_solves["schur"] >= schur.iterations


def test_preconditioner_solves_name_the_tangent_system_in_2d_and_nothing_without_one(monkeypatch):
    from posecrb.solver.tangent import TangentSystem

    rng = np.random.default_rng(13)
    graph = random_pose_graph(40, 2, rng, loop_closures=30, rot_noise=0.1, trans_noise=0.1)[0]
    tangent_applies = _count_calls(monkeypatch, TangentSystem, "apply")
    res = solve(graph)
    assert res.certified and res.preconditioner_solves.get("tangent", 0) > 0
    assert set(res.preconditioner_solves) <= {"schur", "adaptive", "tangent", "split"}
    # the split preconditioner applies K too, once per application
    assert tangent_applies[0] == res.preconditioner_solves["tangent"] + res.preconditioner_solves.get("split", 0)
    bare = solve(graph, preconditioner="none")
    assert bare.preconditioner_solves == {} and bare.certified
    assert bare.to_dict()["preconditioner_solves"] == {}
    assert type(res).from_dict(res.to_dict()).preconditioner_solves == res.preconditioner_solves
