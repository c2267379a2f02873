"""The first staircase level's tangent-space preconditioner (posecrb.solver.tangent) against dense references."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import NotPositiveDefinite
from posecrb.solver.problem import Problem
from posecrb.solver.solve import SolverOptions, solve
from posecrb.solver.staircase import RelaxedModel
from posecrb.solver.stiefel import gram_eigh, remove_vertical
from posecrb.solver.tangent import TangentSystem, so_basis
from posecrb.solver.trust_region import TROptions

from .helpers import random_pose_graph, record_factor_full
from .numerics import EPS, MARGIN, spd_condition


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
    res = solve(graph, tangent_precond=False)
    assert res.certified
    return np.ascontiguousarray(np.swapaxes(res.rot, 1, 2))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("with_lambda", [False, True])
def test_apply_is_the_dense_inverse_on_the_tangent_space(dim, with_lambda):
    rng = np.random.default_rng(7 + dim)
    graph = random_pose_graph(14, dim, rng, loop_closures=8, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    system = TangentSystem.build(problem)
    model = RelaxedModel(problem)
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
    """At the optimum, P(Hess[v]) = v for every horizontal tangent v: the model's own
    Hessian-vector product (an independent code path) undone, up to the shift's effect."""
    rng = np.random.default_rng(3 + dim)
    graph = random_pose_graph(16, dim, rng, loop_closures=10, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    shift = 1e-10 * problem.gershgorin_max()
    model = RelaxedModel(problem, problem.factor_full(None, 1.0, name="base"), shift,
                         tangent=TangentSystem.build(problem), tangent_fallback_shift=1.0)
    Z = _optimum(graph)
    state = model.evaluate(Z)
    model.prepare(state)
    gram = gram_eigh(Z)
    G = so_basis(dim)
    v = remove_vertical(Z, np.einsum("na,axy,nyc->nxc", rng.standard_normal((problem.n, G.shape[0])), G, Z), gram)
    back = model.precondition(state, model.hvp(state, v))
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
    schur = solve(graph, tangent_precond=False)
    tangent = solve(graph, tangent_precond=True)
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
        chosen = solve(graph, tangent_precond=default_is_tangent)
        other = solve(graph, tangent_precond=not default_is_tangent)
        assert default.hessian_vector_products == chosen.hessian_vector_products
        assert default.objective == chosen.objective
        assert SolverOptions().tangent_precond is None
        assert other.hessian_vector_products != default.hessian_vector_products


def test_not_positive_definite_falls_back_without_lambda_then_to_the_base_factor(monkeypatch):
    rng = np.random.default_rng(2)
    graph = random_pose_graph(12, 2, rng, loop_closures=6, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    system = TangentSystem.build(problem)
    base = problem.factor_full(None, 1.0, name="base")
    Z = _optimum(graph)
    calls: list[bool] = []
    real_factor = system.factor

    def factor(Z, lam, shift, name):
        calls.append(lam is not None)
        if lam is not None:
            raise NotPositiveDefinite(name, "test", 0)
        return real_factor(Z, lam, shift, name)

    monkeypatch.setattr(system, "factor", factor)
    model = RelaxedModel(problem, base, 1e-10, tangent=system, tangent_fallback_shift=1.0)
    state = model.evaluate(Z)
    model.prepare(state)
    assert calls == [True, False] and model.factorizations == 2
    R = remove_vertical(Z, np.einsum("na,axy,nyc->nxc", rng.standard_normal((problem.n, 1)), so_basis(2), Z))
    E = _dense_E(Z)
    M = 2.0 * E.T @ (_dense_S(problem, None, 2) + 1.0 * np.eye(E.shape[0])) @ E
    expected = remove_vertical(Z, (E @ np.linalg.solve(M, E.T @ R.ravel())).reshape(Z.shape))
    got = model.precondition(state, R)
    assert np.abs(got - expected).max() <= MARGIN * M.shape[0] * spd_condition(M) * EPS * np.abs(expected).max()

    # both fail: the base factor (Q + delta I)^{-1} preconditions, as without the tangent system
    def failing(Z, lam, shift, name):
        raise NotPositiveDefinite(name, "test", 0)

    monkeypatch.setattr(system, "factor", failing)
    model = RelaxedModel(problem, base, 1e-10, tangent=system, tangent_fallback_shift=1.0)
    state = model.evaluate(Z)
    model.prepare(state)
    plain = RelaxedModel(problem, base, 1e-10)
    np.testing.assert_array_equal(model.precondition(state, R), plain.precondition(plain.evaluate(Z), R))


def test_so_basis_is_orthogonal_and_skew():
    for d in (2, 3, 4):
        G = so_basis(d)
        assert G.shape == (d * (d - 1) // 2, d, d)
        np.testing.assert_array_equal(G, -np.swapaxes(G, 1, 2))
        np.testing.assert_array_equal(np.einsum("axy,bxy->ab", G, G), 2.0 * np.eye(G.shape[0]))


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
    assert solve(graph, tangent_precond=False).certified
    assert calls[0][0] == "preconditioner M_red(delta)"


def test_3d_switches_to_it_after_a_long_truncated_cg_run():
    rng = np.random.default_rng(4)
    graph = random_pose_graph(12, 3, rng, loop_closures=6, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    built: list[TangentSystem] = []

    def factory() -> TangentSystem:
        built.append(TangentSystem.build(problem))
        return built[-1]

    model = RelaxedModel(problem, problem.factor_full(None, 1.0, name="base"), 1e-10, tangent_fallback_shift=1.0,
                         tangent_factory=factory, tangent_switch_hvps=20)
    Z = _optimum(graph)
    state = model.evaluate(Z)
    model.prepare(state, 20)            # not more than the threshold: M_red's preconditioner
    assert not built and model.tangent is None
    switched = model.evaluate(Z.copy())
    model.prepare(switched, 21)
    assert len(built) == 1 and model.tangent is built[0]
    assert model.exact_preconditioner(switched) and not model.exact_preconditioner(state)
    # at a later level (width d + 1) the switch never happens
    fresh = RelaxedModel(problem, problem.factor_full(None, 1.0, name="base"), 1e-10, tangent_fallback_shift=1.0,
                         tangent_factory=factory, tangent_switch_hvps=20)
    wide = np.concatenate([Z, np.zeros((problem.n, 3, 1))], axis=2)
    fresh.prepare(fresh.evaluate(wide), 100)
    assert fresh.tangent is None and len(built) == 1


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
