"""SE(2)/SE(3) closed forms against scipy's matrix exponential/logarithm, finite differences and mpmath."""
from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest
from scipy.linalg import expm, logm

from posecrb.lie import _series
from posecrb.lie import se as L
from posecrb.lie.so import so3_exp

from ..helpers import hat_ref
from ..numerics import EPS, MARGIN


def vee_ref(x: np.ndarray) -> np.ndarray:
    if x.shape[0] == 3:
        return np.array([x[1, 0], x[0, 2], x[1, 2]])
    return np.array([x[2, 1], x[0, 2], x[1, 0], x[0, 3], x[1, 3], x[2, 3]])


def log_ref(t: np.ndarray) -> np.ndarray:
    return vee_ref(np.real(logm(t)))


def log_fast(t: np.ndarray) -> np.ndarray:
    """The closed-form Log (checked against logm in test_log_matches_logm_on_random_poses)."""
    return L.se_log(*L.from_homogeneous(t))


def random_xi(rng, q, scale):
    xi = rng.normal(size=q) * scale
    w = xi[:1] if q == 3 else xi[:3]
    nw = np.linalg.norm(w)
    if nw > 3.0:  # keep the rotation angle inside (-pi, pi) so Log inverts Exp
        w *= 3.0 / nw
    return xi


SCALES = [0.0, 1e-9, 1e-4, 0.02, 0.3, 0.6, 1.2, 2.0]


def exp_atol(t: np.ndarray) -> float:
    """Entries of Exp(xi) (rotation entries <= 1, translation |t|): a few roundings each."""
    return MARGIN * 4 * EPS * max(1.0, float(np.abs(t).max()))


def log_atol(xi: np.ndarray) -> float:
    """Log near angle theta amplifies rounding of the matrix by about theta / sin(theta)
    (the factor of its closed form); entries of xi scale it."""
    xi = np.atleast_2d(xi)
    w = xi[:, :1] if xi.shape[-1] == 3 else xi[:, :3]
    th = np.linalg.norm(w, axis=-1).max()
    amp = th / np.sin(th) if th > 1e-8 else 1.0
    return MARGIN * 4 * EPS * amp * max(1.0, float(np.abs(xi).max()))


@pytest.mark.parametrize("q", [3, 6])
@pytest.mark.parametrize("scale", SCALES)
def test_exp_matches_expm_and_log_inverts(q, scale):
    rng = np.random.default_rng(int(scale * 1e4) + q)
    for _ in range(5):
        xi = random_xi(rng, q, scale)
        r, t = L.se_exp(xi)
        ref = expm(hat_ref(xi))
        np.testing.assert_allclose(L.to_homogeneous(r, t), ref, rtol=0, atol=exp_atol(ref))
        np.testing.assert_allclose(L.se_log(r, t), xi, rtol=0, atol=log_atol(xi))
        # hat / vee only move (and negate) entries: exact
        np.testing.assert_array_equal(L.se_hat(xi), hat_ref(xi))
        np.testing.assert_array_equal(L.se_vee(hat_ref(xi)), xi)


@pytest.mark.parametrize("q", [3, 6])
def test_log_matches_logm_on_random_poses(q):
    rng = np.random.default_rng(11)
    for _ in range(8):
        xi = random_xi(rng, q, 1.5)
        t = expm(hat_ref(xi))
        r, tr = L.from_homogeneous(t)
        np.testing.assert_allclose(L.se_log(r, tr), log_ref(t), atol=1e-10)


def test_batched_shapes():
    rng = np.random.default_rng(2)
    xi = rng.normal(size=(4, 5, 6)) * 0.5
    r, t = L.se_exp(xi)
    assert r.shape == (4, 5, 3, 3) and t.shape == (4, 5, 3)
    np.testing.assert_allclose(L.se_log(r, t), xi, rtol=0, atol=log_atol(xi.reshape(-1, 6)))
    assert L.se_jr_inv(xi).shape == (4, 5, 6, 6)
    assert L.se_adjoint(r, t).shape == (4, 5, 6, 6)
    xi2 = rng.normal(size=(7, 3))
    assert L.se_jr(xi2).shape == (7, 3, 3)


@pytest.mark.parametrize("angle_offset", [0.0, 1e-12, 1e-7, 1e-4, 0.05])
def test_so3_log_near_pi(angle_offset):
    rng = np.random.default_rng(5)
    for _ in range(10):
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        w = (np.pi - angle_offset) * a
        r = so3_exp(w)
        got = L.so3_log(r)
        # At exactly pi, +w and -w are the same rotation.
        ok = np.allclose(got, w, atol=1e-9) or (angle_offset == 0 and np.allclose(got, -w, atol=1e-9))
        assert ok, (got, w)
        np.testing.assert_allclose(so3_exp(got), r, atol=1e-12)


@pytest.mark.parametrize("q", [3, 6])
def test_adjoint_is_conjugation_and_a_homomorphism(q):
    rng = np.random.default_rng(3)
    for _ in range(10):
        g = L.se_exp(random_xi(rng, q, 2.0) * np.r_[np.ones(q // 2), 3 * np.ones(q - q // 2)])
        h = L.se_exp(random_xi(rng, q, 2.0))
        x = rng.normal(size=q)
        tg = L.to_homogeneous(*g)
        ad = L.se_adjoint(*g)
        # Ad_T(X) = T X T^{-1} (2.7)
        np.testing.assert_allclose(ad @ x, vee_ref(tg @ hat_ref(x) @ np.linalg.inv(tg)), atol=1e-12)
        # T Exp(X) T^{-1} = Exp(Ad_T X) (2.9)
        np.testing.assert_allclose(expm(hat_ref(ad @ x)), tg @ expm(hat_ref(x)) @ np.linalg.inv(tg), atol=1e-11)
        # Ad_{gh} = Ad_g Ad_h, Ad_{g^{-1}} = Ad_g^{-1} (Prop. 2.5.2)
        np.testing.assert_allclose(L.se_adjoint(*L.se_compose(*g, *h)), ad @ L.se_adjoint(*h), atol=1e-12)
        np.testing.assert_allclose(L.se_adjoint(*L.se_inverse(*g)), np.linalg.inv(ad), atol=1e-12)


@pytest.mark.parametrize("q", [3, 6])
@pytest.mark.parametrize("scale", [0.0, 1e-6, 0.03, 0.45, 0.55, 1.4, 1.6, 2.5])
def test_right_jacobian_finite_differences(q, scale):
    """Jr: Exp(xi + d) = Exp(xi) Exp(Jr d); Jr^{-1}: Log(Exp(xi) Exp(eta)) = xi + Jr^{-1} eta (expm/logm reference)."""
    rng = np.random.default_rng(int(scale * 1e3) + 7 * q)
    h = 1e-6
    for _ in range(3):
        xi = random_xi(rng, q, scale)
        e0 = expm(hat_ref(xi))
        e0inv = np.linalg.inv(e0)
        jr = np.empty((q, q))
        jri = np.empty((q, q))
        for k in range(q):
            d = np.zeros(q)
            d[k] = h
            jr[:, k] = (log_fast(e0inv @ expm(hat_ref(xi + d))) - log_fast(e0inv @ expm(hat_ref(xi - d)))) / (2 * h)
            jri[:, k] = (log_fast(e0 @ expm(hat_ref(d))) - log_fast(e0 @ expm(hat_ref(-d)))) / (2 * h)
        np.testing.assert_allclose(L.se_jr(xi), jr, atol=2e-8)
        np.testing.assert_allclose(L.se_jr_inv(xi), jri, atol=2e-8)
        a, b = L.se_jr_inv(xi), L.se_jr(xi)
        np.testing.assert_allclose(a @ b, np.eye(q), rtol=0,
                                   atol=MARGIN * q * EPS * np.linalg.norm(a, 2) * np.linalg.norm(b, 2))


def test_thesis_se2_exponential_block():
    """Sec. 6.2: Exp(omega, v) has translation V(omega) v with V = [[s/w, -(1-c)/w], [(1-c)/w, s/w]]."""
    w, v = 0.8, np.array([0.3, -1.1])
    vmat = np.array([[np.sin(w) / w, -(1 - np.cos(w)) / w], [(1 - np.cos(w)) / w, np.sin(w) / w]])
    _, t = L.se2_exp(np.r_[w, v])
    np.testing.assert_allclose(t, vmat @ v, rtol=0, atol=MARGIN * 2 * EPS * np.abs(vmat).max() * np.abs(v).max())


@pytest.mark.parametrize("name,ref", [
    ("_coef_a", lambda t: mp.sin(t) / t),
    ("_coef_b", lambda t: (1 - mp.cos(t)) / t ** 2),
    ("_coef_c", lambda t: (t - mp.sin(t)) / t ** 3),
    ("_coef_c2", lambda t: (t ** 2 + 2 * mp.cos(t) - 2) / (2 * t ** 4)),
    ("_coef_c3", lambda t: (2 * t - 3 * mp.sin(t) + t * mp.cos(t)) / (2 * t ** 5)),
    ("_coef_e", lambda t: (1 - (t / 2) * mp.cot(t / 2)) / t ** 2),
])
def test_coefficients_against_mpmath(name, ref):
    """Series/closed-form switch points included: relative error ~1e-15 over (0, pi]."""
    mp.mp.dps = 90  # the references cancel ~30 digits at th ~ 1e-7
    ts = np.concatenate([np.logspace(-7, 0, 40), np.linspace(0.45, 0.55, 11), np.linspace(1.45, 1.55, 11),
                         np.linspace(1.0, np.pi, 20)])
    got = getattr(_series, name)(ts)
    want = np.array([float(ref(mp.mpf(float(t)))) for t in ts])
    np.testing.assert_allclose(got, want, rtol=1e-14, atol=0)
