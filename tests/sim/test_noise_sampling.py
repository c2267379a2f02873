"""Langevin / Gaussian samplers and eq. (80) measurement regeneration.

References are independent of the samplers: numerically integrated angle
densities (scipy quad, cross-checked against the Bessel closed forms of the
normalisers), eq. (59) through posecrb.sim.sampling.omega (itself tested against mpmath),
and plain moment identities.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, stats
from scipy.special import ive

from posecrb.core.graph import PoseGraph
from posecrb.core.noise import isotropic_information, isotropic_precisions, omega
from posecrb.lie.so import so2_exp, so2_log
from posecrb.sim.sampling import (
    noise_model_graph,
    perturb_measurements,
    sample_isotropic_gaussian,
    sample_langevin_angle_so2,
    sample_langevin_angle_so3,
    sample_langevin_so2,
    sample_langevin_so3,
    sample_se_noise,
    scaled_precisions,
)

KAPPAS = [1e-2, 0.3, 2.0, 15.0, 400.0, 1e4, 1e6]


def _density(kappa: float, group: str):
    """Unnormalised density of the (absolute) rotation angle on [0, pi], scaled by e^{-2 kappa}."""
    # 1 - cos t written as 2 sin^2(t/2): no cancellation at the tiny angles of kappa = 1e6
    if group == "so3":
        return lambda t: np.exp(-4 * kappa * np.sin(t / 2) ** 2) * 2 * np.sin(t / 2) ** 2
    return lambda t: np.exp(-4 * kappa * np.sin(t / 2) ** 2)


def _exact_cdf(samples: np.ndarray, kappa: float, group: str) -> np.ndarray:
    """CDF at every sample by adaptive quadrature between consecutive sorted samples."""
    f = _density(kappa, group)
    s = 1 / np.sqrt(kappa)
    pts = [p for p in (s, 4 * s, 16 * s) if p < np.pi]
    total = integrate.quad(f, 0, np.pi, points=pts or None, epsabs=0, epsrel=1e-11, limit=200)[0]
    # The normalisers have Bessel closed forms: an independent check of the quadrature.
    closed = np.pi * (ive(0, 2 * kappa) - ive(1, 2 * kappa)) if group == "so3" else np.pi * ive(0, 2 * kappa)
    assert total == pytest.approx(closed, rel=1e-8)
    order = np.argsort(samples)
    x = np.concatenate([[0.0], samples[order]])
    pieces = np.array([integrate.quad(f, a, b, epsabs=0, epsrel=1e-10)[0] for a, b in zip(x[:-1], x[1:])])
    cdf = np.empty_like(samples)
    cdf[order] = np.cumsum(pieces) / total
    return cdf


@pytest.mark.parametrize("kappa", KAPPAS)
def test_so3_angle_ks_against_exact_density(kappa):
    rng = np.random.default_rng(int(1000 * np.log10(kappa) + 5000))
    t = sample_langevin_angle_so3(kappa, 3000, rng)
    assert np.all((t >= 0) & (t <= np.pi))
    cdf = _exact_cdf(t, kappa, "so3")
    p = stats.kstest(cdf, "uniform").pvalue
    assert p > 1e-3, f"kappa={kappa}: KS p-value {p}"


@pytest.mark.parametrize("kappa", KAPPAS)
def test_so2_angle_ks_against_exact_density(kappa):
    rng = np.random.default_rng(int(1000 * np.log10(kappa) + 7000))
    a = sample_langevin_angle_so2(kappa, 3000, rng)
    assert np.all(np.abs(a) <= np.pi)
    cdf = _exact_cdf(np.abs(a), kappa, "so2")
    assert stats.kstest(cdf, "uniform").pvalue > 1e-3
    # the sign is symmetric
    assert abs(np.mean(a > 0) - 0.5) < 4 * 0.5 / np.sqrt(a.size)


@pytest.mark.parametrize("kappa", [0.05, 1.0, 12.5, 300.0, 5e4, 1e6])
def test_so3_skew_moment_matches_eq59(kappa):
    """kappa^2 E ||skew Z||_F^2 = omega(kappa) (Appendix C, eq. 95-97)."""
    rng = np.random.default_rng(11)
    z = sample_langevin_so3(kappa, 100_000, rng)
    skew = 0.5 * (z - np.swapaxes(z, 1, 2))
    vals = kappa ** 2 * np.sum(skew ** 2, axis=(1, 2))
    se = vals.std() / np.sqrt(vals.size)
    assert abs(vals.mean() - omega(kappa)) < 5 * se
    # Lemma 2: the three coordinates <skew Z, E_k> share the variance equally
    phi = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], 1) * np.sqrt(2)  # <skew Z, G_k/sqrt2>
    var = (phi ** 2).mean(0)
    assert np.allclose(var, var.mean(), rtol=0.05)


@pytest.mark.parametrize("kappa", [0.05, 1.0, 150.0, 1e6])
def test_so2_skew_moment_closed_form(kappa):
    """kappa^2 E||skew Z||^2 = 2 kappa^2 E sin^2 = kappa I1(2 kappa) / I0(2 kappa) (paper, after eq. 38)."""
    rng = np.random.default_rng(12)
    z = sample_langevin_so2(kappa, 100_000, rng)
    vals = kappa ** 2 * 2 * z[:, 1, 0] ** 2
    expected = kappa * ive(1, 2 * kappa) / ive(0, 2 * kappa)
    assert abs(vals.mean() - expected) < 5 * vals.std() / np.sqrt(vals.size)


def test_so3_draws_are_isotropic_rotations():
    rng = np.random.default_rng(3)
    z = sample_langevin_so3(np.full(50_000, 2.0), 50_000, rng)
    assert np.allclose(z @ np.swapaxes(z, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(z), 1.0)
    mean = z.mean(0)
    # E[Z] = (E tr Z / 3) I: off-diagonal entries vanish, diagonal entries agree
    off = mean - np.diag(np.diag(mean))
    assert np.max(np.abs(off)) < 0.01
    assert np.ptp(np.diag(mean)) < 0.01


def test_per_sample_concentrations_and_extremes():
    rng = np.random.default_rng(4)
    kappa = np.array([1e-2, 1e6] * 5000)
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        t = sample_langevin_angle_so3(kappa, kappa.size, rng)
        a = sample_langevin_angle_so2(kappa, kappa.size, rng)
    assert np.median(t[1::2]) < 5e-3 < 1.0 < np.median(t[0::2])
    assert np.median(np.abs(a[1::2])) < 5e-3
    with pytest.raises(ValueError):
        sample_langevin_so3(0.0, 3, rng)
    with pytest.raises(ValueError):
        sample_langevin_so2(np.array([1.0, -1.0]), 2, rng)


def test_gaussian_and_se_noise_covariances():
    rng = np.random.default_rng(5)
    y = sample_isotropic_gaussian(np.full(200_000, 25.0), 200_000, 3, rng)
    assert np.allclose(np.cov(y.T), np.eye(3) / 25.0, atol=3e-4)
    cov = np.array([[[0.006, 0.001, 0.0], [0.001, 0.002, 0.0], [0.0, 0.0, 0.008]]])
    xi = sample_se_noise(np.repeat(cov, 100_000, 0), rng)
    assert np.allclose(np.cov(xi.T), cov[0], atol=1.5e-4)


@pytest.mark.parametrize("dim", [2, 3])
def test_isotropic_information_round_trip(dim):
    rng = np.random.default_rng(6)
    tau, kappa = rng.uniform(1, 100, 7), rng.uniform(1, 1000, 7)
    t2, k2 = isotropic_precisions(isotropic_information(tau, kappa, dim), dim)
    assert np.allclose(t2, tau) and np.allclose(k2, kappa)


def _parallel_graph(dim: int, m: int) -> PoseGraph:
    q = 3 if dim == 2 else 6
    info = np.repeat(np.eye(q)[None], m, 0) * 50.0
    eye = np.repeat(np.eye(dim)[None], m, 0)
    return PoseGraph(dim=dim, ids=np.array([0, 1]), src=np.zeros(m, int), dst=np.ones(m, int),
                     rot=eye, trans=np.zeros((m, dim)), info=info, format="synthetic")


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("scale", ["both", "rotation"])
def test_perturb_measurements_follows_eq80(dim, scale):
    rng = np.random.default_rng(7)
    m, kc = 40_000, 4.0
    g = _parallel_graph(dim, m)
    if dim == 2:
        rot_true = so2_exp(np.array([0.3, -1.1]))
    else:
        from posecrb.lie.so import so3_exp
        rot_true = so3_exp(np.array([[0.2, -0.4, 0.9], [-1.0, 0.3, 0.1]]))
    trans_true = rng.normal(size=(2, dim))
    p = perturb_measurements(g, rot_true, trans_true, rng, kc=kc, scale=scale)
    tau0, kappa0 = g.tau[0], g.kappa[0]
    tau_exp = kc * tau0 if scale == "both" else tau0
    assert np.allclose(p.tau, tau_exp) and np.allclose(p.kappa, kc * kappa0)
    assert p.vertex_rot is None
    rel_rot = rot_true[0].T @ rot_true[1]
    rel_t = rot_true[0].T @ (trans_true[1] - trans_true[0])
    resid = p.trans - rel_t
    assert np.allclose(resid.mean(0), 0, atol=5 / np.sqrt(tau_exp * m))
    assert np.allclose(resid.var(0), 1 / tau_exp, rtol=0.03)
    z = rel_rot.T @ p.rot                      # right noise R~ = R_ij Z
    if dim == 2:
        ang = np.abs(so2_log(z))
        ref = sample_langevin_angle_so2(kc * kappa0, m, np.random.default_rng(8))
    else:
        ang = np.arccos(np.clip((np.trace(z, axis1=1, axis2=2) - 1) / 2, -1, 1))
        ref = sample_langevin_angle_so3(kc * kappa0, m, np.random.default_rng(8))
    assert stats.ks_2samp(ang, np.abs(ref)).pvalue > 1e-3
    # the noise-model graph has the same measurements and the scaled information
    nm = noise_model_graph(g, kc, scale)
    assert np.allclose(nm.tau, tau_exp) and np.allclose(nm.kappa, kc * kappa0) and nm.rot is g.rot


def test_scaled_precisions_overrides_and_validation():
    g = _parallel_graph(2, 3)
    t, k = scaled_precisions(g, 2.0, "both", tau=140.0, kappa=150.0)
    assert np.allclose(t, 280.0) and np.allclose(k, 300.0)
    with pytest.raises(ValueError):
        scaled_precisions(g, 2.0, "translation")
    with pytest.raises(ValueError):
        scaled_precisions(g, 0.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_perturb_left_is_left_multiplicative(dim):
    """H = Exp(xi) T  =>  Log(H T^{-1}) = xi (thesis 4.3, Prop. 4.3.2)."""
    from posecrb.lie.se import se_compose, se_inverse, se_log
    from posecrb.lie.so import so3_exp
    from posecrb.sim.sampling import perturb_left

    rng = np.random.default_rng(9)
    q = 3 if dim == 2 else 6
    r = so2_exp(rng.uniform(-3, 3, 5)) if dim == 2 else so3_exp(rng.normal(size=(5, 3)))
    t = rng.normal(size=(5, dim))
    xi = rng.normal(scale=0.2, size=(5, q))
    hr, ht = perturb_left(r, t, xi)
    assert np.allclose(se_log(*se_compose(hr, ht, *se_inverse(r, t))), xi)
