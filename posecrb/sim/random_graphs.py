"""Random connected pose graphs with the ground truth attached, for tests and benchmarks
(docs/design.md#datasets): a random spanning tree plus extra edges, random information matrices
(isotropic, block or full), exact or noisy measurements."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.errors import UsageError
from ..core.graph import PoseGraph, rotation_dimension
from ..core.noise import isotropic_information
from ..lie.so import so2_exp, so3_exp
from .generators import assemble_graph, uniform_rotations
from .sampling import isotropic_noise


def _random_spd(rng: np.random.Generator, m: int, k: int, lo: float, hi: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """(m, k, k) SPD matrices Q diag(e) Q^T with log-uniform eigenvalues in [lo, hi], and their square roots."""
    q, r = np.linalg.qr(rng.standard_normal((m, k, k)))
    q = q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    e = np.exp(rng.uniform(np.log(lo), np.log(hi), (m, k)))
    qt = np.swapaxes(q, 1, 2)
    a, s = (q * e[:, None, :]) @ qt, (q * np.sqrt(e)[:, None, :]) @ qt
    # Exactly symmetric, as a file's upper triangle will make them anyway.
    return (a + np.swapaxes(a, 1, 2)) / 2, (s + np.swapaxes(s, 1, 2)) / 2


def random_information(rng: np.random.Generator, m: int, dim: int, kind: str = "full",
                       tau_range: tuple[float, float] = (10.0, 1e3),
                       kappa_range: tuple[float, float] = (50.0, 5e3)) -> np.ndarray:
    """(m, q, q) g2o-order information matrices.

    ``kind``: ``"isotropic"`` (SE-Sync diagonal form with tau, kappa log-uniform in
    the ranges), ``"block"`` (anisotropic SPD translation and rotation blocks, eigenvalues
    in ``tau_range`` resp. ``kappa_range``, no cross terms) or ``"full"`` (the blocks plus
    cross terms ``rho B_t^{1/2} W B_r^{1/2}``, ``||W||_2 = 1``, ``rho < 0.6``: positive
    definite by the Schur complement since ``rho^2 < 1``).
    """
    r = rotation_dimension(dim)
    q = dim + r
    if kind == "isotropic":

        (lo_t, hi_t), (lo_k, hi_k) = np.log(tau_range), np.log(kappa_range)
        tau = np.exp(rng.uniform(lo_t, hi_t, m))
        kappa = np.exp(rng.uniform(lo_k, hi_k, m))
        return isotropic_information(tau, kappa, dim)
    if kind not in ("block", "full"):
        raise UsageError(f"kind must be isotropic, block or full, got {kind!r}")
    bt, st = _random_spd(rng, m, dim, *tau_range)
    br, sr = _random_spd(rng, m, r, *kappa_range)
    info = np.zeros((m, q, q))
    info[:, :dim, :dim] = bt
    info[:, dim:, dim:] = br
    if kind == "full":
        w = rng.standard_normal((m, dim, r))
        w /= np.linalg.norm(w, ord=2, axis=(1, 2))[:, None, None]
        x = rng.uniform(0.0, 0.6, m)[:, None, None] * (st @ w @ sr)
        info[:, :dim, dim:] = x
        info[:, dim:, :dim] = np.swapaxes(x, 1, 2)
    return info


def random_graph(rng: np.random.Generator, n: int, m: int, dim: int, *, info: str = "full",
                 parallel: bool = True, id_gaps: bool = True, noise: str = "none",
                 scale: float = 5.0, tau_range: tuple[float, float] = (10.0, 1e3),
                 kappa_range: tuple[float, float] = (50.0, 5e3)) -> PoseGraph:
    """A random connected pose graph with the ground truth attached (for tests).

    A random spanning tree (each pose joined to a random earlier pose of a random
    order) plus ``m - n + 1`` random extra edges; with ``parallel`` at least one extra
    edge repeats a tree edge (when ``m >= n``). Edge directions are random. Ids are
    sorted distinct non-negative integers with gaps (``id_gaps``) or 0..n-1. Truth:
    Haar-uniform rotations, Gaussian positions of std ``scale``. Information: see
    ``random_information`` (``info`` = isotropic | block | full). ``noise``:
    ``"none"`` (exact measurements), ``"isotropic"`` (eq. 80 with the graph's own
    SE-Sync (tau, kappa)), or ``"gaussian"`` (``xi ~ N(0, inv(info))`` in g2o's
    (translation, rotation) tangent order, applied as ``t + xi_t`` and ``R Exp(xi_r)``).
    """
    if dim not in (2, 3):
        raise UsageError(f"dimension must be 2 or 3, got {dim}")
    if n < 2 or m < n - 1:
        raise UsageError(f"need n >= 2 and m >= n - 1 for a connected graph (n={n}, m={m})")
    perm = rng.permutation(n)
    parent = perm[np.floor(rng.random(n - 1) * np.arange(1, n)).astype(np.int64)]
    a, b = [perm[1:]], [parent]
    extra = m - (n - 1)
    if parallel and extra > 0:
        k = rng.integers(0, n - 1)
        a.append(perm[1:][k: k + 1])
        b.append(parent[k: k + 1])
        extra -= 1
    if extra > 0:
        i = rng.integers(0, n, extra)
        j = (i + rng.integers(1, n, extra)) % n  # never a self-loop
        a.append(i)
        b.append(j)
    a_all, b_all = np.concatenate(a), np.concatenate(b)
    flip = rng.random(m) < 0.5
    src, dst = np.where(flip, b_all, a_all), np.where(flip, a_all, b_all)
    shuffle = rng.permutation(m)
    src, dst = src[shuffle], dst[shuffle]

    if id_gaps:
        gaps = rng.integers(1, 5, n)
        gaps[n // 2] += 2  # guarantees at least one gap whatever the draw
        ids = np.cumsum(gaps) + 2
    else:
        ids = np.arange(n)
    rot = uniform_rotations(n, dim, rng)
    trans = scale * rng.standard_normal((n, dim))
    inf = random_information(rng, m, dim, info, tau_range, kappa_range)
    graph = assemble_graph(dim, rot, trans, src, dst, 1.0, 1.0, False, None, ids=ids, info=inf)
    if noise == "none":
        return graph

    if noise == "isotropic":
        mrot, mtrans = isotropic_noise(graph.rot, graph.trans, graph.tau, graph.kappa, dim, rng)
    elif noise == "gaussian":
        chol = np.linalg.cholesky(inf)
        # xi = L^{-T} z has covariance (L L^T)^{-1} = inv(info).
        xi = np.linalg.solve(np.swapaxes(chol, 1, 2), rng.standard_normal((m, inf.shape[1]))[..., None])[..., 0]
        xt, xr = xi[:, :dim], xi[:, dim:]
        mtrans = graph.trans + xt
        mrot = graph.rot @ (so2_exp(xr[:, 0]) if dim == 2 else so3_exp(xr))
    else:
        raise UsageError(f"noise must be none, isotropic or gaussian, got {noise!r}")
    return replace(graph, rot=mrot, trans=mtrans)


__all__ = ["random_graph", "random_information"]
