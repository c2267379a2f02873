"""CHOLMOD wrapper: log-det vs numpy slogdet, shared ordering, non-PD reported."""
import numpy as np
import pytest
import scipy.sparse as sp

from posecrb.core.errors import NotPositiveDefinite
from posecrb.linalg.cholesky import SymbolicCholesky, lambda_min, logdet

from .numerics import EPS, MARGIN, logdet_atol


def _spd(rng, n, density=0.05):
    a = sp.random(n, n, density=density, random_state=np.random.RandomState(int(rng.integers(1 << 30))))
    return (a @ a.T + sp.identity(n) * 0.5).tocsc()


@pytest.mark.parametrize("n", [5, 60, 400])
def test_logdet_matches_slogdet(n):
    rng = np.random.default_rng(n)
    a = _spd(rng, n)
    sign, ref = np.linalg.slogdet(a.toarray())
    assert sign == 1
    assert logdet(a) == pytest.approx(ref, abs=logdet_atol(a.toarray()))
    shifted = a.toarray() + 2.5 * np.eye(n)
    assert logdet(a, beta=2.5) == pytest.approx(np.linalg.slogdet(shifted)[1], abs=logdet_atol(shifted))


def test_shared_symbolic_analysis_reused():
    rng = np.random.default_rng(3)
    a = _spd(rng, 200)
    b = a.copy()
    b.data = b.data * 3.0 + 0.0  # same pattern, different values
    sym = SymbolicCholesky(a)
    assert sym.factor(b).logdet() == pytest.approx(np.linalg.slogdet(b.toarray())[1], abs=logdet_atol(b.toarray()))
    with pytest.raises(ValueError):
        sym.factor(sp.identity(3, format="csc"))


@pytest.mark.parametrize("mode", ["simplicial", "supernodal"])
def test_not_positive_definite_is_reported(mode):
    a = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(NotPositiveDefinite) as exc:
        SymbolicCholesky(a, mode=mode).factor(a, name="test matrix")
    assert "test matrix" in str(exc.value)


def test_singular_laplacian_reported():
    lap = sp.csc_matrix(np.array([[1.0, -1.0], [-1.0, 1.0]]))
    with pytest.raises(NotPositiveDefinite):
        logdet(lap, name="L")


def test_lambda_min_matches_dense():
    rng = np.random.default_rng(5)
    for n in (50, 500):
        a = _spd(rng, n, density=0.01)
        ev = np.linalg.eigvalsh(a.toarray())
        # symmetric eigenvalues are perturbed by at most the backward error ~ n eps ||A||_2
        assert lambda_min(a) == pytest.approx(ev[0], abs=MARGIN * n * EPS * ev[-1])
