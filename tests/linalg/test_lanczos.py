"""Thick-restart Lanczos against dense eigendecompositions (numpy.linalg.eigh).

A Ritz value never exceeds lambda_max (Cauchy interlacing), and with residual r = ||A x - theta x||
and gap delta to the next eigenvalue, Kato-Temple gives lambda_max - theta <= r^2 / delta. Both
bounds are checked with the residual recomputed here from the dense matrix, not the one reported.
"""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.linalg.lanczos import largest_eigenpair

EPS = np.finfo(float).eps


def _symmetric(rng: np.random.Generator, eigenvalues: np.ndarray) -> np.ndarray:
    q, _ = np.linalg.qr(rng.standard_normal((eigenvalues.size, eigenvalues.size)))
    a = (q * eigenvalues) @ q.T
    return 0.5 * (a + a.T)


def _check(a: np.ndarray, tol: float, rng: np.random.Generator, **kwargs) -> None:
    ev = np.linalg.eigvalsh(a)
    norm = np.abs(ev).max()
    ritz = largest_eigenpair(lambda x: a @ x, rng.standard_normal(a.shape[0]), tol=tol, max_restarts=500, **kwargs)
    assert ritz.converged
    x = ritz.vector
    assert abs(np.linalg.norm(x) - 1.0) <= 100 * a.shape[0] * EPS
    residual = np.linalg.norm(a @ x - ritz.value * x)
    margin = 100 * a.shape[0] * EPS * norm           # rounding in the recomputed residual and the basis
    assert residual <= tol * abs(ritz.value) + margin
    assert ritz.value <= ev[-1] + margin                # interlacing
    distinct = ev[ev < ev[-1] - 1e-6 * norm]
    gap = ev[-1] - distinct[-1] if distinct.size else np.inf
    assert ev[-1] - ritz.value <= residual ** 2 / gap + margin


@pytest.mark.parametrize("n", [1, 2, 3, 7, 19, 20, 21, 64, 300])
def test_random_spectra(n):
    rng = np.random.default_rng(n)
    _check(_symmetric(rng, rng.uniform(-1.0, 1.0, n)), 1e-10, rng)


def test_close_top_pair_needs_restarts():
    """lambda_1 / lambda_2 = 1 + 1e-3 in a spectrum of 400: many restarts, still the right value."""
    rng = np.random.default_rng(1)
    ev = rng.uniform(0.0, 1.0, 400)
    ev[:2] = 1.0, 1.0 - 1e-3
    _check(_symmetric(rng, ev), 1e-12, rng)


def test_repeated_largest_eigenvalue():
    """The certificate's operator (S + s I)^{-1} has its largest eigenvalue d-fold (the null space of S)."""
    rng = np.random.default_rng(2)
    ev = np.concatenate([np.full(3, 1e6), rng.uniform(0.0, 10.0, 200)])
    _check(_symmetric(rng, ev), 1e-10, rng)


def test_few_distinct_eigenvalues_end_in_an_invariant_subspace():
    rng = np.random.default_rng(3)
    a = _symmetric(rng, np.repeat([1.0, 2.0, 5.0], 50))
    ritz = largest_eigenpair(lambda x: a @ x, rng.standard_normal(150), tol=0.0, max_restarts=5)
    assert ritz.converged and ritz.restarts == 1 and ritz.matvecs <= 4
    assert abs(ritz.value - 5.0) <= 1e3 * EPS * 5.0


def test_small_basis_and_indefinite_operator():
    rng = np.random.default_rng(4)
    _check(_symmetric(rng, rng.standard_normal(120)), 1e-9, rng, basis=4)


def test_unconverged_search_says_so_and_returns_its_best_pair():
    rng = np.random.default_rng(5)
    ev = np.linspace(0.0, 1.0, 500)            # no gap: one short basis cannot converge to 1e-14
    a = _symmetric(rng, ev)
    ritz = largest_eigenpair(lambda x: a @ x, rng.standard_normal(500), tol=1e-14, max_restarts=1, basis=6)
    assert not ritz.converged and ritz.restarts == 1 and ritz.matvecs == 6
    assert ritz.value <= 1.0 + 1e3 * EPS
    assert ritz.residual == pytest.approx(np.linalg.norm(a @ ritz.vector - ritz.value * ritz.vector), rel=1e-6)


@pytest.mark.parametrize("v0", [np.zeros(5), np.array([1.0, np.nan, 0.0]), np.array([])])
def test_bad_start_vector(v0):
    with pytest.raises(ValueError, match="start vector"):
        largest_eigenpair(lambda x: x, v0, tol=1e-8, max_restarts=3)


def test_no_restart_allowed_is_an_error():
    with pytest.raises(ValueError, match="max_restarts"):
        largest_eigenpair(lambda x: x, np.ones(3), tol=1e-8, max_restarts=0)


def test_a_separated_top_eigenvalue_stops_before_the_basis_is_full():
    """The certificate's case: (S + s I)^{-1} with s << the next eigenvalue of S. Convergence is
    tested at every step, so a few products suffice where a full basis would take 20."""
    rng = np.random.default_rng(6)
    ev = np.concatenate([[1e6], rng.uniform(0.0, 1.0, 300)])
    a = _symmetric(rng, ev)
    ritz = largest_eigenpair(lambda x: a @ x, rng.standard_normal(301), tol=1e-10, max_restarts=10, basis=20)
    assert ritz.converged and ritz.restarts == 1 and ritz.matvecs <= 6
    _check(a, 1e-10, rng)
