"""The largest eigenpair of a symmetric operator by thick-restart Lanczos.

docs/design.md#linear-algebra. The solver's certificate estimates lambda_min(Q - Lambda) as
1 / mu - s from the largest eigenvalue mu of (Q - Lambda + s I)^{-1}, applied through a Cholesky
factor that the certificate test already computed. ARPACK (``scipy.sparse.linalg.eigsh``) does the
same, but importing it loads ``scipy.linalg``, in every process as much as the whole certified
solve of a 10^3-pose dataset (docs/decisions/fixed-costs.md); this module needs only numpy.

Method: Lanczos with full reorthogonalisation (every new vector is orthogonalised twice against the
whole basis, so the Ritz values cannot repeat as in plain Lanczos), convergence tested after every
step, restarted (when the basis is full) by keeping the
``basis // 2`` largest Ritz vectors and the residual direction (thick restart, Wu and Simon 2000).
The projected matrix T = V^T A V is built column by column from the orthogonalisation coefficients,
so after a restart it is the usual arrowhead plus tridiagonal matrix without special cases.
A Ritz pair (theta, x) is accepted when ``||A x - theta x|| <= tol |theta|``, ARPACK's criterion.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RitzPair:
    """Largest Ritz value and its unit vector; ``residual`` is ``||A x - value x||``."""

    value: float
    vector: np.ndarray
    residual: float
    converged: bool
    matvecs: int
    restarts: int


def largest_eigenpair(matvec: Callable[[np.ndarray], np.ndarray], v0: np.ndarray, *, tol: float,
                      max_restarts: int, basis: int = 20) -> RitzPair:
    """Largest (algebraic) eigenpair of the symmetric operator ``matvec`` of size ``len(v0)``.

    ``tol`` is relative (see the module docstring); ``max_restarts`` bounds the number of Krylov
    bases built (each of at most ``basis`` vectors), as ARPACK's ``maxiter`` does. When it runs
    out, the best Ritz pair is returned with ``converged=False``: callers decide what an
    unconverged estimate is worth. An invariant subspace (the operator has fewer distinct
    eigenvalues than the basis) ends the search with the exact eigenpair.
    """
    v0 = np.asarray(v0, dtype=float).ravel()
    n = v0.size
    norm0 = float(np.linalg.norm(v0))
    if n == 0 or not np.isfinite(norm0) or norm0 == 0.0:
        raise ValueError("start vector must be a non-zero finite vector")
    if max_restarts < 1:
        raise ValueError(f"max_restarts must be >= 1, got {max_restarts}")
    m = max(2, min(basis, n))
    keep = max(1, m // 2)
    V = np.empty((m + 1, n))      # rows are the orthonormal basis vectors
    T = np.zeros((m, m))
    V[0] = v0 / norm0
    k = 0                         # number of kept Ritz vectors at the start of this basis
    matvecs = 0
    best: RitzPair | None = None
    for restart in range(max_restarts):
        for j in range(k, m):
            w = np.asarray(matvec(V[j]), dtype=float).ravel()
            matvecs += 1
            h = V[: j + 1] @ w
            w -= h @ V[: j + 1]
            h2 = V[: j + 1] @ w             # second pass: keeps the basis orthogonal to working precision
            w -= h2 @ V[: j + 1]
            h += h2
            T[: j + 1, j] = h
            T[j, : j + 1] = h
            beta = float(np.linalg.norm(w))
            scale = max(float(np.abs(h).max()), np.finfo(float).tiny)
            invariant = beta <= 64 * np.finfo(float).eps * scale or j + 1 == n
            if invariant:
                beta = 0.0                   # invariant subspace: the Ritz values are exact
            else:
                V[j + 1] = w / beta
                if j + 1 < m:
                    T[j, j + 1] = T[j + 1, j] = beta
            # Convergence is checked at every step (a (j+1)-square eigh, negligible next to a
            # product): the certificate's operator has a well-separated top eigenvalue that
            # converges in a few steps, long before the basis is full.
            theta, Y = np.linalg.eigh(T[: j + 1, : j + 1])
            j_end = j + 1
            residual = abs(beta * float(Y[j, -1]))
            if invariant or residual <= tol * abs(float(theta[-1])):
                break
        value = float(theta[-1])
        converged = bool(invariant or residual <= tol * abs(value))
        if best is None or converged or residual < best.residual:
            best = RitzPair(value, Y[:, -1] @ V[:j_end], residual, converged, matvecs, restart + 1)
        if converged:
            return RitzPair(best.value, best.vector, best.residual, True, matvecs, restart + 1)
        # Thick restart: the largest Ritz vectors, then the residual direction V[m].
        k = min(keep, j_end - 1)
        top = Y[:, j_end - k:]
        V[:k] = top.T @ V[:j_end]
        V[k] = V[j_end]
        T[:] = 0.0
        T[np.arange(k), np.arange(k)] = theta[j_end - k:]
        T[k, :k] = T[:k, k] = beta * Y[j_end - 1, j_end - k:]
    assert best is not None   # max_restarts >= 1
    return RitzPair(best.value, best.vector, best.residual, best.converged, matvecs, max_restarts)
