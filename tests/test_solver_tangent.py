"""The first staircase level's tangent-space preconditioner (posecrb.solver.tangent) against dense references."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import NotPositiveDefinite
from posecrb.solver.problem import Problem
from posecrb.solver.solve import SolverOptions, solve
from posecrb.solver.staircase import RelaxedModel
from posecrb.solver.stiefel import gram_eigh, lift, remove_vertical
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


def _model_at_optimum(rng: np.random.Generator, poses: int, dim: int, loop_closures: int):
    """(problem, model, state, s): a random graph's problem, a model with the tangent preconditioner
    at shift s = 1e-10 of the Gershgorin bound, and its state at the certified first-level optimum,
    where the model's K with Lambda is factored."""
    graph = random_pose_graph(poses, dim, rng, loop_closures=loop_closures, rot_noise=0.05, trans_noise=0.05)[0]
    problem = Problem.from_graph(graph)
    shift = 1e-10 * problem.gershgorin_max()
    model = RelaxedModel(problem, problem.factor_full(None, 1.0, name="base"), shift,
                         tangent=TangentSystem.build(problem), tangent_fallback_shift=1.0)
    state = model.evaluate(_optimum(graph))
    model.prepare(state)
    return problem, model, state, shift


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
    problem, model, state, shift = _model_at_optimum(rng, 16, dim, loop_closures=10)
    Z = state.Z
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
    lam = RelaxedModel(problem).evaluate(Z).lam if with_lambda else None
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
    model = RelaxedModel(problem)
    Z = _optimum(graph)
    state = model.evaluate(Z)
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
    for the in-plane directions, (Q - Lambda + s I)^{-1} for the new column's) undoes the model's
    own Hessian-vector product on every horizontal tangent vector, up to the shift's effect."""
    rng = np.random.default_rng(40 + dim)
    problem, model, first, shift = _model_at_optimum(rng, 16, dim, loop_closures=10)
    Z1 = first.Z
    state = model.evaluate(lift(Z1, dim + 1))
    model.precond_factor = problem.factor_full(state.lam, shift, name="M_red(Lambda, s)")
    v = remove_vertical(state.Z, model.project(state, rng.standard_normal(state.Z.shape)))
    calls = []
    real = model._split_apply
    model._split_apply = lambda *a: calls.append(1) or real(*a)
    back = model.precondition(state, model.hvp(state, v))
    assert calls
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
    schur = solve(graph, tangent_precond=False)
    calls = record_factor_full(monkeypatch)
    applied = []
    real = RelaxedModel._split_apply

    def spy(self, *args):
        applied.append(1)
        return real(self, *args)

    monkeypatch.setattr(RelaxedModel, "_split_apply", spy)
    split = solve(graph)
    assert schur.certified and split.certified and split.rank == schur.rank == 3
    assert applied
    # the saddle's shifted factor preconditions the new column: no factorization between the
    # shifted certificate at the saddle and the final certificate
    names = [name for name, _ in calls]
    assert "preconditioner M_red(Lambda, s)" not in names
    assert names[-1].startswith("certificate matrix")
    # both stop at a Newton decrement of decrement_tol |f| (TROptions), past the quadratic phase
    tol = 100 * TROptions().decrement_tol
    assert split.relaxation_value == pytest.approx(schur.relaxation_value, rel=tol)
    assert split.objective == pytest.approx(schur.objective, rel=tol)
    # the option turns it off: M_red's preconditioner after the escape, refactored at the escape point
    applied.clear()
    calls.clear()
    off = solve(graph, split_precond=False)
    assert not applied and off.certified
    assert "preconditioner M_red(Lambda, s)" in [name for name, _ in calls]
    assert off.relaxation_value == pytest.approx(split.relaxation_value, rel=tol)


def test_split_preconditioner_is_not_used_once_a_block_turns_to_the_new_column():
    problem, model, first, _ = _model_at_optimum(np.random.default_rng(50), 12, 2, loop_closures=8)
    Z1 = first.Z
    Z = lift(Z1, 3)
    # pose 0 rotated in the (first, new) column plane by 70 degrees: its rows lean on the new column
    c, s = np.cos(np.radians(70)), np.sin(np.radians(70))
    Z[0] = Z[0] @ np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    state = model.evaluate(Z)
    model.precond_factor = problem.factor_full(None, 1.0, name="M_red")
    assert model._split_parts(state, gram_eigh(Z)) is None
    assert model._split_parts(model.evaluate(lift(Z1, 3)), gram_eigh(lift(Z1, 3))) is not None


def test_the_saddle_factor_is_replaced_once_the_split_stops_applying(monkeypatch):
    """The saddle's factor serves the split preconditioner's new column only: where a block has
    turned towards the new column and the split no longer applies, prepare() refactors M_red's
    preconditioner at the point."""
    problem, model, first, _ = _model_at_optimum(np.random.default_rng(60), 12, 2, loop_closures=8)
    Z1 = first.Z
    saddle = problem.factor_full(first.lam, 0.5, name="shifted certificate matrix")
    model.saddle_factor = (saddle, 0.5)
    model.lambda_hint, model.refactor_next = -0.1, True
    calls = record_factor_full(monkeypatch)
    padded = model.evaluate(lift(Z1, 3))
    model.prepare(padded)
    assert calls == [] and model.precond_factor is saddle
    assert model._split_parts(padded, gram_eigh(padded.Z)) is not None
    # pose 0 rotated by 80 degrees in the plane of its first and the new column
    Z = lift(Z1, 3)
    c, s = np.cos(np.radians(80)), np.sin(np.radians(80))
    Z[0] = Z[0] @ np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    far = model.evaluate(Z)
    model.prepare(far, last_hvps=1)
    assert [name for name, _ in calls] and calls[0][0] == "preconditioner M_red(Lambda, s)"
    assert model.precond_factor is not saddle
    assert model._split_parts(far, gram_eigh(far.Z)) is None
