"""Noise model: SE-Sync precisions vs dense per-edge computation; eq. (59) vs mpmath."""
import mpmath as mp
import numpy as np
import pytest

from posecrb.core.noise import isotropic_precisions, omega, rotation_weights

from ..helpers import random_spd
from ..numerics import EPS, MARGIN, spd_condition


@pytest.mark.parametrize("dim", [2, 3])
def test_precisions_match_per_edge_dense(dim):
    rng = np.random.default_rng(1)
    info = random_spd(rng, 20, dim + (1 if dim == 2 else 3))
    tau, kappa = isotropic_precisions(info, dim)
    for k in range(20):
        # d / trace(inv(B)): relative error of a small inverse, ~ dim cond(B) eps per evaluation
        blk_t, blk_r = info[k, :dim, :dim], info[k, dim:, dim:]
        cov_t = np.linalg.inv(blk_t)
        assert tau[k] == pytest.approx(dim / np.trace(cov_t), rel=MARGIN * dim * spd_condition(blk_t) * EPS)
        if dim == 2:
            assert kappa[k] == info[k, 2, 2]
        else:
            assert kappa[k] == pytest.approx(3 / (2 * np.trace(np.linalg.inv(blk_r))),
                                             rel=MARGIN * 3 * spd_condition(blk_r) * EPS)


def _omega_mp(k):
    mp.mp.dps = 80
    x = 2 * mp.mpf(k)
    i = [mp.besseli(v, x) for v in range(4)]
    return k ** 2 * (2 * i[0] - i[1] - 2 * i[2] + i[3]) / (2 * i[0] - 2 * i[1])


def test_omega_matches_eq59_in_high_precision():
    # every branch: the power series (kappa < 0.05, both sides of the switch), ive, the asymptotic series
    ks = np.concatenate([np.geomspace(1e-8, 1e8, 160), 0.05 * (1 + np.array([-1e-15, 0.0, 1e-15]))])
    got = omega(ks)
    ref = np.array([float(_omega_mp(mp.mpf(float(k)))) for k in ks])
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, rtol=1e-12)


def test_omega_series_branch_is_numpy_polynomials_horner_bit_for_bit():
    # Below the switch omega is k S12(k) / S01(k) by Horner's scheme; numpy.polynomial's polyval,
    # an independent implementation of that scheme, gives the same bits at every kappa and sign.
    from posecrb.core.noise import _S01, _S12, _SERIES_BELOW

    ks = np.concatenate([np.geomspace(1e-300, _SERIES_BELOW, 5000, endpoint=False), [0.0, -0.0]])
    with np.errstate(invalid="ignore"):     # 0/0 at kappa = 0 in the reference: compared where defined
        ref = ks * np.polynomial.polynomial.polyval(ks, _S12) / np.polynomial.polynomial.polyval(ks, _S01)
    got = omega(ks)
    assert np.array_equal(got.view(np.int64), ref.view(np.int64))


def test_bessel_ratios_converge_within_the_fraction_and_need_no_scipy_special():
    """The continued fraction's tail beyond 40 terms changes no bit at 0.1 <= x < 30 (64 are used),
    its ratios match scipy's scaled Bessel functions there, and omega loads no scipy.special."""
    import subprocess
    import sys

    from scipy.special import ive

    from posecrb.core import noise

    x = np.geomspace(0.1, 30.0, 500, endpoint=False)
    full = noise._bessel_ratios(x)
    short = noise._FRACTION_TERMS
    try:
        noise._FRACTION_TERMS = 40
        assert all(np.array_equal(a, b) for a, b in zip(full, noise._bessel_ratios(x)))
    finally:
        noise._FRACTION_TERMS = short
    np.testing.assert_allclose(full[0], ive(1, x) / ive(0, x), rtol=1e-14)
    np.testing.assert_allclose(full[1], ive(2, x) / ive(1, x), rtol=1e-14)
    code = ("import sys; from posecrb.core.noise import omega; omega([0.3, 2.0, 14.0]); "
            "print('scipy.special' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.split() == ["False"]


def test_omega_limits():
    # Small kappa: omega ~ kappa^2 (leading Bessel terms); large: omega / 3 -> kappa.
    assert omega(1e-6) == pytest.approx(1e-12, rel=1e-5)
    assert omega(1e8) / 3 == pytest.approx(1e8, rel=1e-7)
    assert np.ndim(omega(2.0)) == 0


def test_rotation_weights():
    k = np.array([0.5, 10.0, 1e4])
    np.testing.assert_allclose(rotation_weights(k, 2), 2 * k)
    np.testing.assert_allclose(rotation_weights(k, 3), omega(k) / 3)
    np.testing.assert_allclose(rotation_weights(k, 3, "table2"), 0.5515 * k ** 2)
    np.testing.assert_allclose(rotation_weights(k, 2, "table2"), 2 * k)
    with pytest.raises(ValueError):
        rotation_weights(k, 3, "nope")
