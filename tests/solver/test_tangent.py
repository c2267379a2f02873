"""The first staircase level's tangent-space preconditioner (posecrb.solver.tangent) against dense references."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import NotPositiveDefinite
from posecrb.solver import PreconditionerSettings, SolverOptions, solve
from posecrb.solver.certificate import Certificate
from posecrb.solver.policy import PreconditionerPolicy
from posecrb.solver.preconditioners import (
    AdaptivePreconditioner,
    BasePreconditioner,
    SplitPreconditioner,
    TangentPreconditioner,
)
from posecrb.solver.problem import Problem
from posecrb.solver.relaxed import RelaxedProblem
from posecrb.solver.stiefel import lift, remove_vertical
from posecrb.solver.tangent import TangentSystem, so_basis
from posecrb.solver.trust_region import TROptions

from ..helpers import random_pose_graph, record_factor_full
from ..numerics import EPS, MARGIN, spd_condition


def _dense_Q(problem: Problem) -> np.ndarray:
    """Q = C - V_red^T L_red^{-1} V_red, dense (the Schur complement the solver never forms)."""
    V = problem.Vred.toarray()
    return problem.C.toarray() - V.T @ np.linalg.solve(problem.Lred.toarray(), V)


def _dense_E(Z: np.ndarray) -> np.ndarray:
    """(n d d) x (n k): column (i, a) is G_a Z_i at pose i, row-major over (i, row, column)."""
    n, d, r = Z.shape
    G = so_basis(d)
    k = G.shape[0]
    E = np.zeros((n, d, r, n, k))
    for i in range(n):
        for a in range(k):
            E[i, :, :, i, a] = G[a] @ Z[i]
    return E.reshape(n * d * r, n * k)


def _dense_S(problem: Problem, lam: np.ndarray | None, r: int) -> np.ndarray:
    """(Q - Lambda) (x) I_r acting on the row layout's vec (the Hessian's S, column by column)."""
    n, d = problem.n, problem.d
    S = _dense_Q(problem)
    if lam is not None:
        for i in range(n):
            S[i * d:(i + 1) * d, i * d:(i + 1) * d] -= lam[i]
    return np.kron(S, np.eye(r))


def _optimum(graph) -> np.ndarray:
    """The certified optimum's rotations in the solver's row layout (n, d, d): Z_i = R_i^T."""
    res = solve(graph, preconditioner="base")
    assert res.certified
    return np.ascontiguousarray(np.swapaxes(res.rot, 1, 2))


def _tangent_policy(problem: Problem, shift: float, *, system: TangentSystem | None = None, switch: int | None = None,
                    refactor_hvps: int | None = 30) -> PreconditionerPolicy:
    """The policy with the tangent preconditioner (from the start, or after a truncated-CG run of
    more than ``switch`` products) at shift ``shift``, its fallback and the base factor at 1.0,
    the adaptive factor at ``shift`` and the split after an escape."""
    tangent = TangentPreconditioner(problem, shift, 1.0, system)
    return PreconditionerPolicy(problem, base=BasePreconditioner(problem, 1.0, "schur"),
                                adaptive=AdaptivePreconditioner(problem, shift), tangent=tangent,
                                tangent_switch_hvps=switch, split=True, refactor_hvps=refactor_hvps)


def _model_at_optimum(rng: np.random.Generator, poses: int, dim: int, loop_closures: int):
    """(problem, relaxation, policy, state, s): a random graph's problem and relaxation, the policy
    with the tangent preconditioner at shift s = 1e-10 of the Gershgorin bound, refactoring the
    adaptive one at every point it prepares, and the state at the certified first-level optimum,
    where the policy's K with Lambda is factored."""
    graph = random_pose_graph(poses, dim, rng, loop_closures=loop_closures, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    shift = 1e-10 * problem.gershgorin_max()
    policy = _tangent_policy(problem, shift, system=TangentSystem.build(problem), refactor_hvps=None)
    relaxed = RelaxedProblem(problem)
    state = relaxed.evaluate(_optimum(graph))
    policy.prepare(state)
    return problem, relaxed, policy, state, shift


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("with_lambda", [False, True])
def test_apply_is_the_dense_inverse_on_the_tangent_space(dim, with_lambda):
    rng = np.random.default_rng(7 + dim)
    graph = random_pose_graph(14, dim, rng, loop_closures=8, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    system = TangentSystem.build(problem)
    model = RelaxedProblem(problem)
    # Without Lambda any point will do (Q + s I is positive definite); with it, the optimum, where
    # S = Q - Lambda is positive semidefinite.
    if with_lambda:
        Z = _optimum(graph)
    else:
        Z = np.ascontiguousarray(np.swapaxes(random_pose_graph(14, dim, rng)[1], 1, 2))
    state = model.evaluate(Z)
    shift = 1e-3 * problem.gershgorin_max()
    lam = state.lam if with_lambda else None
    E = _dense_E(Z)
    M = 2.0 * E.T @ (_dense_S(problem, lam, dim) + shift * np.eye(E.shape[0])) @ E
    R = rng.standard_normal(Z.shape)
    reference = (E @ np.linalg.solve(M, E.T @ R.ravel())).reshape(Z.shape)
    got = system.apply(system.factor(Z, lam, shift, name="K"), Z, R)
    # both sides solve with M (dense LU; sparse Cholesky of K, whose Schur complement M / 2 is):
    # backward-stable solves, each within cond(M) eps of the exact result
    scale = np.abs(reference).max()
    assert np.abs(got - reference).max() <= MARGIN * M.shape[0] * spd_condition(M) * EPS * scale


@pytest.mark.parametrize("dim", [2, 3])
def test_preconditioner_inverts_the_riemannian_hessian(dim):
    """At the optimum, P(Hess[v]) = v for every horizontal tangent v: the relaxation's own
    Hessian-vector product (an independent code path) undone, up to the shift's effect."""
    rng = np.random.default_rng(3 + dim)
    problem, relaxed, policy, state, shift = _model_at_optimum(rng, 16, dim, loop_closures=10)
    Z = state.Z
    G = so_basis(dim)
    v = remove_vertical(Z, np.einsum("na,axy,nyc->nxc", rng.standard_normal((problem.n, G.shape[0])), G, Z),
                        state.gram)
    back = policy.apply(state, relaxed.hvp(state, v))
    assert policy.solves() == {"tangent": 1}
    # 2 E^T S E's eigenvalues past the gauge's k zeros bound how much the shift moves the result
    E = _dense_E(Z)
    H = 2.0 * E.T @ _dense_S(problem, state.lam, dim) @ E
    ev = np.linalg.eigvalsh((H + H.T) / 2)
    mu = ev[G.shape[0]]
    assert mu > 0
    tol = 2.0 * shift / mu + MARGIN * H.shape[0] * (ev[-1] / mu) * EPS
    assert np.abs(back - v).max() <= tol * np.abs(v).max() * MARGIN


@pytest.mark.parametrize("dim", [2, 3])
def test_both_preconditioners_reach_the_same_certified_optimum(dim):
    rng = np.random.default_rng(11 + dim)
    graph = random_pose_graph(40, dim, rng, loop_closures=30, rot_noise=0.1, trans_noise=0.1)[0]
    schur = solve(graph, preconditioner="base")
    tangent = solve(graph, preconditioner="tangent")
    assert schur.certified and tangent.certified
    # both stop at a Newton decrement of decrement_tol |f| (TROptions), past the quadratic phase
    tol = 100 * TROptions().decrement_tol
    assert tangent.objective == pytest.approx(schur.objective, rel=tol)
    assert tangent.relaxation_value == pytest.approx(schur.relaxation_value, rel=tol)
    # truncated CG with the exact inverse: a Newton step in one or two products per iteration
    assert tangent.rank == schur.rank == dim + 1
    assert tangent.hessian_vector_products <= 2 * tangent.iterations


def test_default_uses_it_on_2d_graphs_only():
    rng = np.random.default_rng(5)
    for dim, default_is_tangent in ((2, True), (3, False)):
        graph = random_pose_graph(30, dim, rng, loop_closures=20, rot_noise=0.1, trans_noise=0.1)[0]
        default = solve(graph)
        chosen = solve(graph, preconditioner="tangent" if default_is_tangent else "base")
        other = solve(graph, preconditioner="base" if default_is_tangent else "tangent")
        assert default.hessian_vector_products == chosen.hessian_vector_products
        assert default.objective == chosen.objective
        assert SolverOptions().preconditioner == "auto"
        assert other.hessian_vector_products != default.hessian_vector_products


def test_not_positive_definite_falls_back_without_lambda_then_to_the_base_factor(monkeypatch):
    rng = np.random.default_rng(2)
    graph = random_pose_graph(12, 2, rng, loop_closures=6, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    system = TangentSystem.build(problem)
    Z = _optimum(graph)
    calls: list[bool] = []
    real_factor = system.factor

    def factor(Z, lam, shift, name):
        calls.append(lam is not None)
        if lam is not None:
            raise NotPositiveDefinite(name, "test", 0)
        return real_factor(Z, lam, shift, name)

    monkeypatch.setattr(system, "factor", factor)
    policy = _tangent_policy(problem, 1e-10, system=system)
    state = RelaxedProblem(problem).evaluate(Z)
    policy.prepare(state)
    assert calls == [True, False] and policy.tangent is not None and policy.tangent.factorizations == 2
    assert not policy.exact(state)
    R = remove_vertical(Z, np.einsum("na,axy,nyc->nxc", rng.standard_normal((problem.n, 1)), so_basis(2), Z))
    E = _dense_E(Z)
    M = 2.0 * E.T @ (_dense_S(problem, None, 2) + 1.0 * np.eye(E.shape[0])) @ E
    expected = remove_vertical(Z, (E @ np.linalg.solve(M, E.T @ R.ravel())).reshape(Z.shape))
    got = policy.apply(state, R)
    assert np.abs(got - expected).max() <= MARGIN * M.shape[0] * spd_condition(M) * EPS * np.abs(expected).max()

    # both fail: the base factor (Q + delta I)^{-1} preconditions, as without the tangent system
    def failing(Z, lam, shift, name):
        raise NotPositiveDefinite(name, "test", 0)

    monkeypatch.setattr(system, "factor", failing)
    policy = _tangent_policy(problem, 1e-10, system=system)
    state = RelaxedProblem(problem).evaluate(Z)
    policy.prepare(state)
    plain = PreconditionerPolicy(problem, base=BasePreconditioner(problem, 1.0, "schur"),
                                 adaptive=AdaptivePreconditioner(problem, 1e-10))
    np.testing.assert_array_equal(policy.apply(state, R), plain.apply(RelaxedProblem(problem).evaluate(Z), R))
    assert policy.solves() == plain.solves() == {"schur": 1}


def test_so_basis_is_orthogonal_and_skew():
    for d in (2, 3, 4):
        G = so_basis(d)
        assert G.shape == (d * (d - 1) // 2, d, d)
        np.testing.assert_array_equal(G, -np.swapaxes(G, 1, 2))
        np.testing.assert_array_equal(np.einsum("axy,bxy->ab", G, G), 2.0 * np.eye(G.shape[0]))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("extra_columns", [0, 1])
def test_tangent_blocks_are_each_generator_times_each_block(dim, extra_columns):
    """G_a Z_i for every pose and generator, at the first level's width and past it (the split
    preconditioner's point): the same digits as the matrix product, which only adds zeros."""
    rng = np.random.default_rng(40 + dim)
    graph = random_pose_graph(9, dim, rng, loop_closures=4)[0]
    system = TangentSystem.build(Problem.from_graph(graph))
    Z = rng.standard_normal((9, dim, dim + extra_columns))
    G = so_basis(dim)
    reference = np.stack([np.stack([G[a] @ Z[i] for a in range(G.shape[0])]) for i in range(9)])
    np.testing.assert_array_equal(system.tangent_blocks(Z), reference)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("with_lambda", [False, True])
def test_k_eliminates_to_the_tangent_hessian(dim, with_lambda):
    """K's Schur complement on the tangent coordinates is E^T (S + s I) E (module docstring), against
    the dense Q, Lambda and E at a random point."""
    rng = np.random.default_rng(50 + dim)
    graph = random_pose_graph(12, dim, rng, loop_closures=6, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    system = TangentSystem.build(problem)
    Z = np.ascontiguousarray(np.swapaxes(random_pose_graph(12, dim, rng)[1], 1, 2))
    lam = RelaxedProblem(problem).evaluate(Z).lam if with_lambda else None
    shift = 0.25
    K = system.matrix(Z, lam, shift).toarray()
    f = system.first
    L11 = K[:f, :f]
    schur = K[f:, f:] - K[f:, :f] @ np.linalg.solve(L11, K[:f, f:])
    E = _dense_E(Z)
    reference = E.T @ (_dense_S(problem, lam, dim) + shift * np.eye(E.shape[0])) @ E
    # the elimination solves with the translation Laplacian (backward stable: cond eps relative to
    # the eliminated term), both sides sum products of the same entries
    scale = np.abs(K[f:, :f]).max() ** 2 / np.linalg.eigvalsh(L11)[0] + np.abs(reference).max()
    tol = MARGIN * K.shape[0] * spd_condition(L11) * EPS * scale
    assert np.abs(schur - reference).max() <= tol


def test_a_graph_certified_at_the_first_level_never_factors_the_base_preconditioner(monkeypatch):
    """With the tangent preconditioner the base (Q + delta I)^{-1} is built on first use only:
    a 2D graph certified at the first level needs M_red once, for the certificate."""
    rng = np.random.default_rng(9)
    graph = random_pose_graph(30, 2, rng, loop_closures=20, rot_noise=0.05, trans_noise=0.05)[0]
    calls = record_factor_full(monkeypatch)
    res = solve(graph)
    assert res.certified and res.rank == 3
    assert [name for name, _ in calls] == ["certificate matrix Q - Lambda + eta I"]
    calls.clear()
    assert solve(graph, preconditioner="base").certified
    assert calls[0][0] == "preconditioner M_red(delta)"


def test_3d_switches_to_it_after_a_long_truncated_cg_run():
    rng = np.random.default_rng(4)
    graph = random_pose_graph(12, 3, rng, loop_closures=6, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    relaxed = RelaxedProblem(problem)
    policy = _tangent_policy(problem, 1e-10, switch=20)
    assert policy.tangent is not None
    Z = _optimum(graph)
    state = relaxed.evaluate(Z)
    policy.prepare(state, 20)            # not more than the threshold: M_red's preconditioner
    assert policy.tangent.system is None and not policy.exact(state)
    policy.apply(state, state.grad)
    switched = relaxed.evaluate(Z.copy())
    policy.prepare(switched, 21)
    assert policy.tangent.system is not None
    assert policy.exact(switched) and not policy.exact(state)
    policy.apply(switched, switched.grad)
    assert policy.solves() == {"schur": 1, "tangent": 1}
    # at a later level (width d + 1) the switch never happens
    fresh = _tangent_policy(problem, 1e-10, switch=20)
    wide = np.concatenate([Z, np.zeros((problem.n, 3, 1))], axis=2)
    fresh.prepare(relaxed.evaluate(wide), 100)
    assert fresh.tangent is not None and fresh.tangent.system is None


def test_a_vacuous_certificate_at_eta_is_proven_again_at_the_small_shift(caplog):
    """Near-exact measurements: the objective is below n d eta, so the certificate at eta would
    prove nothing; the solver proves it at the preconditioner's small shift instead (no warning)."""
    rng = np.random.default_rng(8)
    graph = random_pose_graph(60, 2, rng, loop_closures=40, rot_noise=1e-4, trans_noise=1e-4)[0]
    with caplog.at_level("WARNING", logger="posecrb"):
        res = solve(graph)
    assert res.certified
    assert res.objective < graph.n * 2 * 1e-3          # the bound at eta would be vacuous
    assert not [r for r in caplog.records if "not shown to be optimal" in r.getMessage()]


def test_the_second_certificate_counts_in_the_verify_phase_and_the_total(monkeypatch):
    """The re-proof at the small shift is verification work: its time is in ``times["verify"]``
    and in the total, never outside every phase."""
    import time

    rng = np.random.default_rng(8)
    graph = random_pose_graph(60, 2, rng, loop_closures=40, rot_noise=1e-4, trans_noise=1e-4)[0]
    real = Problem.factor_full

    def slow(self, lam, shift, name):
        if name == "certificate matrix Q - Lambda + s I":
            time.sleep(0.3)
        return real(self, lam, shift, name)

    monkeypatch.setattr(Problem, "factor_full", slow)
    res = solve(graph)
    assert res.certified
    assert res.times["verify"] >= 0.3
    assert res.times["total"] >= sum(res.times[k] for k in ("init", "optimize", "verify", "round"))


# ---- the split preconditioner after the escape from the first level --------------------------

def _escaping_grid():
    """A noisy 2D grid whose first level ends at a saddle: one escape to width 3, then certified."""
    from posecrb.sim.generators import grid

    sigma = 0.4
    return grid(2, 32, tau=1.0 / sigma ** 2, kappa=1.0 / (2.0 * sigma ** 2), noise=True,
                rng=np.random.default_rng(3))


@pytest.mark.parametrize("dim", [2, 3])
def test_gauge_modes_are_the_rotation_of_every_pose_at_once(dim):
    rng = np.random.default_rng(20 + dim)
    graph, rot = random_pose_graph(12, dim, rng)[:2]
    problem = Problem.from_graph(graph)
    system = TangentSystem.build(problem)
    Z = np.ascontiguousarray(np.swapaxes(rot, 1, 2))
    U = system.gauge_modes(Z)
    k = so_basis(dim).shape[0]
    assert U.shape == (problem.n * k, k)
    assert np.allclose(U.T @ U, np.eye(k), atol=MARGIN * problem.n * EPS)
    # E u is Z_i H with one H for every pose: vertical, removed whole by remove_vertical
    E = _dense_E(Z)
    for u in U.T:
        v = (E @ u).reshape(Z.shape)
        assert np.abs(remove_vertical(Z, v)).max() <= MARGIN * problem.n * EPS * np.abs(v).max()
    if dim == 2:
        # in 2D every Omega_i is the same generator: the constant vector
        assert abs(abs(U[:, 0].sum()) - np.sqrt(problem.n)) <= MARGIN * problem.n * EPS


def test_apply_with_the_gauge_replaced_is_the_dense_reference():
    rng = np.random.default_rng(31)
    graph = random_pose_graph(14, 3, rng, loop_closures=8, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    system = TangentSystem.build(problem)
    Z = _optimum(graph)
    state = RelaxedProblem(problem).evaluate(Z)
    shift = 1e-3 * problem.gershgorin_max()
    E = _dense_E(Z)
    M = 2.0 * E.T @ (_dense_S(problem, state.lam, 3) + shift * np.eye(E.shape[0])) @ E
    U = system.gauge_modes(Z)
    scale = 7.0
    Pi = np.eye(M.shape[0]) - U @ U.T
    R = rng.standard_normal(Z.shape)
    reference = (E @ ((Pi @ np.linalg.solve(M, Pi @ (E.T @ R.ravel()))) + U @ (U.T @ (E.T @ R.ravel())) / scale))
    got = system.apply(system.factor(Z, state.lam, shift, name="K"), Z, R, gauge=(U, scale))
    tol = MARGIN * M.shape[0] * spd_condition(M) * EPS * np.abs(reference).max()
    assert np.abs(got - reference.reshape(Z.shape)).max() <= tol


@pytest.mark.parametrize("dim", [2, 3])
def test_split_preconditioner_inverts_the_hessian_at_the_padded_point(dim):
    """At [Z1 | 0], Z1 a certified first-level optimum, the split preconditioner (K's factor at Z1
    for the in-plane directions, (Q - Lambda + s I)^{-1} for the new column's) undoes the
    relaxation's own Hessian-vector product on every horizontal tangent vector, up to the shift's
    effect."""
    rng = np.random.default_rng(40 + dim)
    problem, relaxed, policy, first, shift = _model_at_optimum(rng, 16, dim, loop_closures=10)
    Z1 = first.Z
    state = relaxed.evaluate(lift(Z1, dim + 1))
    policy.prepare(state)       # the adaptive factor at the padded point (refactored at every point)
    assert policy.adaptive is not None and policy.adaptive.factor_shift == shift
    v = remove_vertical(state.Z, relaxed.project(state, rng.standard_normal(state.Z.shape)))
    back = policy.apply(state, relaxed.hvp(state, v))
    assert policy.solves() == {"split": 1}
    # the in-plane block's eigenvalues past the gauge's k zeros, and S's past its d zeros (the
    # new column's vertical tilts), bound the shift's effect
    E = _dense_E(Z1)
    H = 2.0 * E.T @ _dense_S(problem, state.lam, dim) @ E
    ev_in = np.linalg.eigvalsh((H + H.T) / 2)
    S = _dense_S(problem, state.lam, 1)
    ev_out = np.linalg.eigvalsh((S + S.T) / 2)
    k = so_basis(dim).shape[0]
    mu = min(ev_in[k], 2.0 * ev_out[dim])
    assert mu > 0
    top = max(ev_in[-1], 2.0 * ev_out[-1])
    tol = 2.0 * shift / mu + MARGIN * max(H.shape[0], S.shape[0]) * (top / mu) * EPS
    assert np.abs(back - v).max() <= tol * np.abs(v).max() * MARGIN


def test_split_preconditioner_after_the_escape_reaches_the_same_certified_optimum(monkeypatch):
    graph = _escaping_grid()
    schur = solve(graph, preconditioner="base")
    calls = record_factor_full(monkeypatch)
    applied = []
    real = SplitPreconditioner.apply

    def spy(self, *args):
        applied.append(1)
        return real(self, *args)

    monkeypatch.setattr(SplitPreconditioner, "apply", spy)
    split = solve(graph)
    assert schur.certified and split.certified and split.rank == schur.rank == 3
    assert applied and split.preconditioner_solves["split"] == len(applied)
    # the saddle's shifted factor preconditions the new column: no factorization between the
    # shifted certificate at the saddle and the final certificate
    names = [name for name, _ in calls]
    assert "preconditioner M_red(Lambda, s)" not in names
    assert names[-1].startswith("certificate matrix")
    # both stop at a Newton decrement of decrement_tol |f| (TROptions), past the quadratic phase
    tol = 100 * TROptions().decrement_tol
    assert split.relaxation_value == pytest.approx(schur.relaxation_value, rel=tol)
    assert split.objective == pytest.approx(schur.objective, rel=tol)
    # the setting turns it off: M_red's preconditioner after the escape, refactored at the escape point
    applied.clear()
    calls.clear()
    off = solve(graph, preconditioner_settings=PreconditionerSettings(split_after_escape=False))
    assert not applied and off.certified and "split" not in off.preconditioner_solves
    assert "preconditioner M_red(Lambda, s)" in [name for name, _ in calls]
    assert off.relaxation_value == pytest.approx(split.relaxation_value, rel=tol)


def _leaning(Z1: np.ndarray, degrees: float) -> np.ndarray:
    """[Z1 | 0] with pose 0 rotated by ``degrees`` in the plane of its first and the new column."""
    Z = lift(Z1, Z1.shape[2] + 1)
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    Z[0] = Z[0] @ np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    return Z


def test_split_preconditioner_is_not_used_once_a_block_turns_to_the_new_column():
    problem, relaxed, policy, first, _ = _model_at_optimum(np.random.default_rng(50), 12, 2, loop_closures=8)
    split = policy.split
    assert split is not None
    # pose 0's rows lean on the new column by 70 degrees: past the split's 60
    assert not split.prepare(relaxed.evaluate(_leaning(first.Z, 70)))
    assert split.prepare(relaxed.evaluate(_leaning(first.Z, 50)))
    assert split.prepare(relaxed.evaluate(lift(first.Z, 3)))


def test_the_saddle_factor_is_replaced_once_the_split_stops_applying(monkeypatch):
    """The saddle's factor serves the split preconditioner's new column only: where a block has
    turned towards the new column and the split no longer applies, prepare() refactors M_red's
    preconditioner at the point."""
    problem, relaxed, policy, first, _ = _model_at_optimum(np.random.default_rng(60), 12, 2, loop_closures=8)
    assert policy.adaptive is not None and policy.split is not None
    saddle = problem.factor_full(first.lam, 0.5, name="shifted certificate matrix")
    policy.after_escape(Certificate(False, -0.1, np.zeros((problem.n, 2)), 1, 0, shifted_factor=(saddle, 0.5)))
    calls = record_factor_full(monkeypatch)
    padded = relaxed.evaluate(lift(first.Z, 3))
    policy.prepare(padded)
    assert calls == [] and policy.current is policy.adaptive and policy.adaptive.factor is saddle
    assert policy.split.prepare(padded)
    far = relaxed.evaluate(_leaning(first.Z, 80))
    policy.prepare(far, last_hvps=1)
    assert [name for name, _ in calls] and calls[0][0] == "preconditioner M_red(Lambda, s)"
    assert policy.adaptive.factor is not saddle
    assert not policy.split.prepare(far)
