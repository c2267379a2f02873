"""Noise sampling: exact isotropic Langevin rotations, Gaussian translations, measurement
regeneration by eq. (80) and the thesis's left se(d) noise (4.3)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt
from scipy.special import gamma as gamma_fn
from scipy.special import gammainc, gammaincinv

from ..core.choices import NOISE_SCALES
from ..core.errors import InternalError, UsageError
from ..core.graph import PoseGraph
from ..core.noise import isotropic_information
from ..lie.se import relative_poses, se_compose, se_exp
from ..lie.so import so2_exp, so3_exp

_SMALL_C = 1e-3        # below this concentration the piece-1 proposal drops e^{-cu}
_MAX_ROUNDS = 10_000   # acceptance is >= ~0.3 for every c, so this is never reached


def _concentrations(kappa: npt.ArrayLike, size: int) -> np.ndarray:
    k = np.broadcast_to(np.asarray(kappa, dtype=float), (size,)).copy()
    if not np.all(np.isfinite(k)) or np.any(k <= 0):
        raise UsageError("Langevin concentration kappa must be finite and > 0")
    return k


def _sample_versine(a: float, c: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Exact draws of ``u = 1 - cos t`` with density ``u^(a-1) e^(-c u) (2-u)^(-1/2)`` on (0, 2).

    Returns ``(u, v)`` with ``v = 2 - u`` kept separately (accurate near t = pi).
    This is the law of the rotation angle's versine for the von Mises angle
    (a = 1/2) and for the SO(3) Langevin angle (a = 3/2), c = 2 kappa.

    Acceptance-rejection from a two-piece envelope:
    on (0, 1] ``(2-u)^(-1/2) <= 1``, so ``g1 = u^(a-1) e^(-cu)`` (a truncated gamma,
    drawn by inverting its CDF with ``gammaincinv``; acceptance >= 1/sqrt 2);
    on (1, 2) ``u^(a-1) e^(-cu) <= M2 e^(-c)``, so ``g2 = M2 e^(-c) (2-u)^(-1/2)``
    (drawn as ``2 - V^2``). Both envelope masses are closed-form, the
    pieces are picked with probability proportional to them, and no term overflows:
    ``e^(-c)`` underflows to 0 for huge c exactly where piece 2 is unreachable.
    """

    n = c.shape[0]
    u = np.empty(n)
    v = np.empty(n)
    m2 = max(1.0, 2.0 ** (a - 1.0))
    small = c < _SMALL_C
    cs = np.where(small, 1.0, c)
    p1 = gammainc(a, cs)
    # Envelope masses: piece 1 = integral_0^1 u^(a-1) e^(-cu) du (for tiny c, of u^(a-1)).
    w1 = np.where(small, 1.0 / a, gamma_fn(a) * cs ** (-a) * p1)
    w2 = 2.0 * m2 * np.exp(-c)
    prob2 = w2 / (w1 + w2)
    pending = np.arange(n)
    for _ in range(_MAX_ROUNDS):
        k = pending.size
        if k == 0:
            return u, v
        pick2 = rng.random(k) < prob2[pending]
        x = rng.random(k)
        acc = rng.random(k)
        cp = c[pending]
        # piece 1: truncated gamma on (0, 1] by inverse CDF
        uu = np.where(small[pending], x ** (1.0 / a),
                      gammaincinv(a, x * p1[pending]) / cs[pending])
        uu = np.minimum(uu, 1.0)
        ratio1 = (2.0 - uu) ** -0.5 * np.where(small[pending], np.exp(-cp * uu), 1.0)
        # piece 2: u = 2 - V^2 on (1, 2)
        vv = x * x
        u2 = 2.0 - vv
        ratio2 = u2 ** (a - 1.0) / m2 * np.exp(-cp * (u2 - 1.0))
        ok = acc < np.where(pick2, ratio2, ratio1)
        idx = pending[ok]
        u[idx] = np.where(pick2, u2, uu)[ok]
        v[idx] = np.where(pick2, vv, 2.0 - uu)[ok]
        pending = pending[~ok]
    raise InternalError("Langevin sampler did not terminate")  # pragma: no cover


def _angle_from_versine(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """t in [0, pi] with 1 - cos t = u and 1 + cos t = v, accurate at both ends."""
    return np.where(u <= 1.0, 2.0 * np.arcsin(np.sqrt(u / 2.0)),
                    np.pi - 2.0 * np.arcsin(np.sqrt(np.minimum(v, 2.0) / 2.0)))


def sample_langevin_angle_so2(kappa: npt.ArrayLike, size: int, rng: np.random.Generator) -> np.ndarray:
    """(size,) signed angles of Z ~ Lang(I, kappa) on SO(2) (density prop. to exp(kappa tr Z), eq. 5).

    ``tr Z = 2 cos t``, so the angle is von Mises with concentration ``2 kappa``.
    Exact for any kappa > 0 (no normal approximation at large kappa).
    """
    c = 2.0 * _concentrations(kappa, size)
    u, v = _sample_versine(0.5, c, rng)
    sign = np.where(rng.random(size) < 0.5, -1.0, 1.0)
    return sign * _angle_from_versine(u, v)


def sample_langevin_so2(kappa: npt.ArrayLike, size: int, rng: np.random.Generator) -> np.ndarray:
    """(size, 2, 2) draws of Z ~ Lang(I, kappa) on SO(2) (paper eq. 5)."""

    return so2_exp(sample_langevin_angle_so2(kappa, size, rng))


def sample_langevin_angle_so3(kappa: npt.ArrayLike, size: int, rng: np.random.Generator) -> np.ndarray:
    """(size,) rotation angles t in [0, pi] of Z ~ Lang(I, kappa) on SO(3).

    By the Weyl integration formula (paper Appendix C) the angle has density
    proportional to ``exp(2 kappa cos t) (1 - cos t)`` on [0, pi].
    """
    c = 2.0 * _concentrations(kappa, size)
    u, v = _sample_versine(1.5, c, rng)
    return _angle_from_versine(u, v)


def sample_langevin_so3(kappa: npt.ArrayLike, size: int, rng: np.random.Generator) -> np.ndarray:
    """(size, 3, 3) draws of Z ~ Lang(I, kappa) on SO(3) (density prop. to exp(kappa tr Z), eq. 5).

    Class function: the angle comes from ``sample_langevin_angle_so3`` and the
    axis is uniform on the sphere, independent of the angle.
    """

    t = sample_langevin_angle_so3(kappa, size, rng)
    axis = rng.standard_normal((size, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return so3_exp(axis * t[:, None])


def sample_langevin(kappa: npt.ArrayLike, size: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """(size, d, d) Langevin rotations on SO(2) or SO(3)."""
    if dim == 2:
        return sample_langevin_so2(kappa, size, rng)
    if dim == 3:
        return sample_langevin_so3(kappa, size, rng)
    raise UsageError(f"dimension must be 2 or 3, got {dim}")


def sample_isotropic_gaussian(tau: npt.ArrayLike, size: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """(size, d) draws of y ~ N(0, I / tau) (paper eq. 3, tau = delta^-2)."""
    tau = np.broadcast_to(np.asarray(tau, dtype=float), (size,))
    if np.any(tau <= 0) or not np.all(np.isfinite(tau)):
        raise UsageError("translation precision tau must be finite and > 0")
    return rng.standard_normal((size, dim)) / np.sqrt(tau)[:, None]





def scaled_precisions(graph: PoseGraph, kc: float = 1.0, scale: str = "both", tau: npt.ArrayLike | None = None,
                      kappa: npt.ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(tau, kappa) per edge of the Monte Carlo noise model of eq. (80).

    ``tau`` / ``kappa`` (scalar or (m,)) replace the graph's own precisions (the
    paper's Fig. 6 uses kappa = 150, tau = 140 on CSAIL). ``kc`` multiplies kappa;
    with ``scale="both"`` (default) it multiplies tau as well, so that k_c scales the
    whole information (the SNR); ``scale="rotation"`` is eq. (80) as printed, where
    only the Langevin concentration carries k_c.
    """
    if scale not in NOISE_SCALES:
        raise UsageError(f"scale must be one of {NOISE_SCALES}, got {scale!r}")
    if not (np.isfinite(kc) and kc > 0):
        raise UsageError(f"k_c must be > 0, got {kc}")
    m = graph.m
    t = np.broadcast_to(np.asarray(graph.tau if tau is None else tau, dtype=float), (m,))
    k = np.broadcast_to(np.asarray(graph.kappa if kappa is None else kappa, dtype=float), (m,))
    return (kc * t if scale == "both" else t.copy()), kc * k


def noise_model_graph(graph: PoseGraph, kc: float = 1.0, scale: str = "both", tau: npt.ArrayLike | None = None,
                      kappa: npt.ArrayLike | None = None) -> PoseGraph:
    """The graph with its information matrices replaced by the isotropic noise model of eq. (80).

    Same measurements; use it to evaluate the FIM/CRLB of the Monte Carlo model.
    """

    t, k = scaled_precisions(graph, kc, scale, tau, kappa)
    return replace(graph, info=isotropic_information(t, k, graph.dim))


def isotropic_noise(rot: np.ndarray, trans: np.ndarray, tau: npt.ArrayLike, kappa: npt.ArrayLike, dim: int,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (80) applied to noise-free measurements ``(rot, trans)`` ((m, d, d), (m, d)).

    ``R~ = rot Z``, ``Z ~ Lang(I, kappa)`` (right-multiplied, the g2o / SE-Sync model), and
    ``t~ = trans + y``, ``y ~ N(0, I / tau)``; ``tau``, ``kappa`` scalar or (m,). The Langevin
    draws come first, then the Gaussian ones, from the one ``rng`` (fixes the stream per seed).
    """
    m = rot.shape[0]
    z = sample_langevin(kappa, m, dim, rng)
    y = sample_isotropic_gaussian(tau, m, dim, rng)
    return rot @ z, trans + y


def perturb_measurements(graph: PoseGraph, rot_true: np.ndarray, trans_true: np.ndarray, rng: np.random.Generator,
                         kc: float = 1.0, scale: str = "both", tau: npt.ArrayLike | None = None,
                         kappa: npt.ArrayLike | None = None) -> PoseGraph:
    """A new PoseGraph with measurements regenerated from a ground truth by eq. (80).

    Rotation: ``R~_ij = R_i^T R_j Z_ij``, ``Z_ij ~ Lang(I, k_c kappa_ij)``: the model of g2o /
    SE-Sync files (edge (i, j) measures ``X_i^{-1} X_j``), whose Fisher information is the
    ``"consistent"`` variant of ``posecrb.models.paper.fim``. The paper's eq. (4), ``H_ij = Z_ij R_j R_i^T``,
    is a different law in general: conjugation invariance of Lang(I, kappa) only moves the noise
    to the other side of the same matrix (``Z R_j R_i^T = R_j R_i^T Z'``, ``Z' ~ Lang(I, kappa)``),
    and ``R_j R_i^T != R_i^T R_j`` unless the rotations commute (2D). Translation:
    ``t~_ij = R_i^T (x_j - x_i) + y_ij``, ``y_ij ~ N(0, I / tau'_ij)``
    with ``tau' = k_c tau`` (``scale="both"``) or ``tau`` (``scale="rotation"``).
    The information matrices encode (tau', k_c kappa) under SE-Sync's convention
    (``isotropic_information``), so solving the returned graph gives the MLE.
    Vertices are dropped (a solver must not start at the truth).
    """

    t, k = scaled_precisions(graph, kc, scale, tau, kappa)
    rot_true = np.asarray(rot_true, dtype=float)
    trans_true = np.asarray(trans_true, dtype=float)
    rel_rot, rel_trans = relative_poses(rot_true, trans_true, graph.src, graph.dst)
    rot, trans = isotropic_noise(rel_rot, rel_trans, t, k, graph.dim, rng)
    return replace(graph, rot=rot, trans=trans, info=isotropic_information(t, k, graph.dim),
                   vertex_rot=None, vertex_trans=None, format="synthetic", sha256=None, edge_lines=None)


def sample_se_noise(cov: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(m, q) draws xi_ij ~ N(0, Sigma_ij) in se(d) coordinates (thesis 4.3; rotation first)."""
    cov = np.asarray(cov, dtype=float)
    chol = np.linalg.cholesky(cov)
    z = rng.standard_normal(cov.shape[:-1])
    return np.einsum("mab,mb->ma", chol, z)


def perturb_left(rot: np.ndarray, trans: np.ndarray, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Left-multiplicative se(d) noise of the thesis (4.3): ``H = Exp(xi^) T_i T_j^{-1}``.

    ``(rot, trans)``: (m, d, d), (m, d) noise-free ``T_i T_j^{-1}``; ``xi``: (m, q),
    rotation first (thesis sec. 6.2). Returns ``H`` as (rot, trans).
    """

    er, et = se_exp(np.asarray(xi, dtype=float))
    return se_compose(er, et, np.asarray(rot, dtype=float), np.asarray(trans, dtype=float))
