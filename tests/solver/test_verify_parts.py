"""The solver's quantities at given poses (for certifying an estimate computed elsewhere) against
dense references on small random graphs: the objective F, the relaxation's Riemannian gradient,
SE-Sync's Lagrange multiplier Lambda(R), S = Q - Lambda and its lambda_min test, and the rank-d
refinement."""
from __future__ import annotations

import doctest

import numpy as np
import pytest

from posecrb.core.graph import PoseGraph
from posecrb.lie.so import so2_exp, so3_exp
from posecrb.solver import solve
from posecrb.solver.certificate import certificate_product, dual_certificate, lagrange_multipliers
from posecrb.solver.problem import Problem
from posecrb.solver.refine import refine, relaxed_gradient
from posecrb.solver.rounding import pose_objective

from ..helpers import objective_loop, random_pose_graph
from ..numerics import EPS, MARGIN, spd_condition


def _dense_translations(graph: PoseGraph, rot: np.ndarray) -> tuple[np.ndarray, float]:
    """The translations minimising F(R, .) with t_0 = 0 by dense weighted least squares, and the
    condition number of its normal matrix."""
    n, d = graph.n, graph.dim
    A = np.zeros((graph.m, n))
    A[np.arange(graph.m), graph.dst] += 1.0
    A[np.arange(graph.m), graph.src] -= 1.0
    w = np.sqrt(graph.tau)[:, None]
    b = np.einsum("eab,eb->ea", rot[graph.src], graph.trans)
    t = np.zeros((n, d))
    t[1:] = np.linalg.lstsq(w * A[:, 1:], w * b, rcond=None)[0]
    normal = (w * A[:, 1:]).T @ (w * A[:, 1:])
    return t, spd_condition(normal)


def _dense_Q(problem: Problem) -> tuple[np.ndarray, float]:
    """Q = C - V_red^T L_red^{-1} V_red, dense, and the absolute accuracy of the solver's Q products
    against it: both solve with the translation Laplacian (backward stable, within cond(L) eps of
    the eliminated term's size)."""
    V, L = problem.Vred.toarray(), problem.Lred.toarray()
    Q = problem.C.toarray() - V.T @ np.linalg.solve(L, V)
    scale = np.abs(problem.C.toarray()).max() + np.abs(V).max() ** 2 * V.shape[0] / np.linalg.eigvalsh(L)[0]
    return Q, MARGIN * Q.shape[0] * spd_condition(L) * EPS * scale


def _dense_lambda(Q: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """SymBlockDiag(Q Y^T Y) with Y = [R_1 ... R_n]: its (n, d, d) diagonal blocks."""
    n, d = rot.shape[:2]
    Y = np.concatenate(list(rot), axis=1)          # d x dn
    M = Q @ Y.T @ Y
    blocks = np.stack([M[i * d:(i + 1) * d, i * d:(i + 1) * d] for i in range(n)])
    return 0.5 * (blocks + np.swapaxes(blocks, 1, 2))


def _dense_S(Q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Q - Lambda with Lambda's (n, d, d) blocks on the block diagonal."""
    n, d = lam.shape[:2]
    S = Q.copy()
    for i in range(n):
        S[i * d:(i + 1) * d, i * d:(i + 1) * d] -= lam[i]
    return S


def _graph(dim: int, seed: int, noise: float = 0.1):
    rng = np.random.default_rng(seed)
    return random_pose_graph(15, dim, rng, loop_closures=10, rot_noise=noise, trans_noise=noise)


def _away_from_the_truth(dim: int, seed: int):
    """(graph, problem, R, dense Q, its accuracy): a random graph and rotations 0.3 rad off its truth."""
    graph, rot, _ = _graph(dim, seed)
    problem = Problem.from_graph(graph)
    Q, atol = _dense_Q(problem)
    return graph, problem, _perturbed(rot, 0.3, np.random.default_rng(seed + 1)), Q, atol


def _perturbed(rot: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    n, d = rot.shape[:2]
    noise = so2_exp(sigma * rng.standard_normal(n)) if d == 2 else so3_exp(sigma * rng.standard_normal((n, 3)))
    return rot @ noise


@pytest.mark.parametrize("dim", [2, 3])
def test_objective_with_given_and_with_eliminated_translations(dim):
    graph, rot, trans = _graph(dim, 1)
    problem = Problem.from_graph(graph)
    rng = np.random.default_rng(2)
    R = _perturbed(rot, 0.2, rng)
    t = trans + 0.3 * rng.standard_normal(trans.shape)
    # given translations: the same sum of m non-negative terms in another order
    assert pose_objective(problem, R, t) == pytest.approx(objective_loop(graph, R, t), rel=MARGIN * graph.m * EPS)
    # eliminated: the minimum over t, at the dense least-squares translations; the value is flat there,
    # so the solutions' difference (cond eps) enters squared, and the sums round at m eps
    t_star, cond = _dense_translations(graph, R)
    reference = objective_loop(graph, R, t_star)
    got = pose_objective(problem, R)
    assert got == pytest.approx(reference, rel=MARGIN * (graph.m + cond) * EPS)
    assert got <= pose_objective(problem, R, t) and got <= objective_loop(graph, R, t)


@pytest.mark.parametrize("dim", [2, 3])
def test_lagrange_multipliers_and_certificate_product_are_the_dense_ones(dim):
    graph, problem, R, Q, atol = _away_from_the_truth(dim, 3)
    lam = lagrange_multipliers(problem, R)
    dn = problem.n * dim
    # each block sums dn products of Q's entries with entries of R (at most 1 in size)
    np.testing.assert_allclose(lam, _dense_lambda(Q, R), rtol=0, atol=dn * atol)
    np.testing.assert_array_equal(lam, np.swapaxes(lam, 1, 2))
    X = np.random.default_rng(5).standard_normal((dn, 2))
    np.testing.assert_allclose(certificate_product(problem, lam, X), _dense_S(Q, lam) @ X, rtol=0,
                               atol=dn * atol * np.abs(X).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_dual_certificate_decides_lambda_min_as_the_dense_spectrum_does(dim):
    graph, rot, _ = _graph(dim, 6)
    problem = Problem.from_graph(graph)
    res = solve(graph)
    assert res.certified
    Q, atol = _dense_Q(problem)
    for R in (res.rot, _perturbed(res.rot, 0.3, np.random.default_rng(7))):
        cert = dual_certificate(problem, R, tol=1e-3)
        S = _dense_S(Q, cert.lam)
        exact = float(np.linalg.eigvalsh(0.5 * (S + S.T))[0])
        rounding = problem.n * dim * atol
        assert abs(exact + 1e-3) > rounding          # the dense reference decides the test
        assert cert.certified == (exact >= -1e-3)
        # a certified estimate: 1 / theta - tol from a Ritz value of (S + tol I)^{-1} at a residual
        # of 1e-8 (certificate.py); a saddle's: a Rayleigh quotient at a residual of 1e-4, second order
        tol = 1e-7 * (abs(exact) + 1e-3) if cert.certified else 1e-6 * abs(exact)
        assert abs(cert.lambda_min - exact) <= tol + rounding
    # "certified" means what solve's certificate means: at its estimate, its lambda_min (Lambda is
    # invariant under the anchoring's common rotation)
    at_solve = dual_certificate(problem, res.rot)
    assert at_solve.certified and abs(at_solve.lambda_min - res.lambda_min) <= 1e-7 * 1e-3 + 2 * rounding


@pytest.mark.parametrize("dim", [2, 3])
def test_relaxed_gradient_is_the_dense_one_and_vanishes_at_the_optimum(dim):
    graph, problem, R, Q, atol = _away_from_the_truth(dim, 8)
    lam = _dense_lambda(Q, R)
    Z = np.swapaxes(R, 1, 2)
    QZ = (Q @ Z.reshape(-1, dim)).reshape(Z.shape)
    dense = np.swapaxes(2.0 * (QZ - lam @ Z), 1, 2)
    grad = relaxed_gradient(problem, R)
    dn = problem.n * dim
    np.testing.assert_allclose(grad.gradient, dense, rtol=0, atol=4 * dn * atol)
    assert grad.norm == pytest.approx(np.linalg.norm(dense), rel=1e-12, abs=4 * dn * atol)
    assert grad.relative_norm == pytest.approx(np.linalg.norm(dense) / np.linalg.norm(2.0 * QZ), rel=1e-9)
    assert 0.05 < grad.relative_norm <= 1.0
    # along the curve R_i exp(h H_i) the derivative of F*(R) is <gradient, R H> (central differences)
    H = np.random.default_rng(10).standard_normal((problem.n, dim, dim))
    H = H - np.swapaxes(H, 1, 2)
    h = 1e-6
    from scipy.linalg import expm

    def along(step: float) -> float:
        return pose_objective(problem, np.stack([R[i] @ expm(step * H[i]) for i in range(problem.n)]))

    fd = (along(h) - along(-h)) / (2 * h)
    assert fd == pytest.approx(float(np.sum(grad.gradient * (R @ H))), rel=1e-6)
    # at the certified optimum the trust region stopped at a Newton decrement of 1e-11 |f| or below
    at_optimum = relaxed_gradient(problem, solve(graph).rot)
    assert at_optimum.relative_norm < 1e-5 * grad.relative_norm


@pytest.mark.parametrize("dim", [2, 3])
def test_refine_returns_a_perturbed_optimum_to_a_certified_critical_point(dim):
    graph, _, _ = _graph(dim, 11, noise=0.05)
    problem = Problem.from_graph(graph)
    res = solve(graph)
    start = _perturbed(res.rot, 0.2, np.random.default_rng(12))
    before = relaxed_gradient(problem, start)
    out = refine(problem, start)
    assert out.iterations > 0 and out.hessian_vector_products > 0 and out.preconditioner_solves
    assert out.rot.shape == start.shape       # the rank stays d: no staircase
    np.testing.assert_allclose(out.rot @ np.swapaxes(out.rot, 1, 2), np.broadcast_to(np.eye(dim), out.rot.shape),
                               atol=MARGIN * dim * EPS)
    assert np.all(np.linalg.det(out.rot) > 0)
    # where it ended: the objective with the optimal translations reported with it, a vanishing
    # gradient, the certified optimum's value (both stop at a Newton decrement of 1e-11 |f|)
    assert out.objective == pytest.approx(objective_loop(graph, out.rot, out.trans), rel=MARGIN * graph.m * EPS)
    assert out.gradient.relative_norm < 1e-5 * before.relative_norm
    assert out.objective == pytest.approx(res.objective, rel=1e-9)
    assert dual_certificate(problem, out.rot).certified


def test_refine_stops_at_a_saddle_without_escaping():
    """A cycle with identity measurements from a winding configuration: a critical point of the
    rank-d problem that is not optimal. refine stays there (solve would escape to rank d + 1)."""
    n = 16
    src, dst = np.arange(n), (np.arange(n) + 1) % n
    src, dst = np.minimum(src, dst), np.maximum(src, dst)
    g = PoseGraph(dim=2, ids=np.arange(n), src=src, dst=dst, rot=np.tile(np.eye(2), (n, 1, 1)),
                  trans=np.zeros((n, 2)), info=np.tile(np.diag([1.0, 1.0, 10.0]), (n, 1, 1)), format="synthetic")
    problem = Problem.from_graph(g)
    winding = so2_exp(2 * np.pi * np.arange(n) / n)
    out = refine(problem, winding)
    assert out.rot.shape == (n, 2, 2) and out.gradient.relative_norm < 1e-8
    cert = dual_certificate(problem, out.rot)
    assert not cert.certified and cert.lambda_min < -1e-3
    assert out.objective > 1.0 and solve(g, init=winding).objective < 1e-10


def test_examples_in_the_solver_modules_run():
    """The docstring examples of the solver's typed options and relaxed problem (not in
    posecrb.__all__, so tests/docs/test_doctests.py does not run them)."""
    import posecrb.solver.options as options
    import posecrb.solver.relaxed as relaxed

    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    found = 0
    for module in (options, relaxed):
        for test in doctest.DocTestFinder().find(module, module.__name__, globs={}):
            found += len(test.examples)
            runner.run(test)
    assert found >= 4 and runner.summarize(verbose=False).failed == 0
