"""Reduced weighted Laplacians vs the incidence-matrix definition A Sigma A^T (section III-A)."""
import numpy as np
import pytest

from posecrb.linalg.laplacian import laplacian, reduced_laplacian


def _incidence(n, src, dst):
    a = np.zeros((n, src.size))
    a[src, np.arange(src.size)] = -1
    a[dst, np.arange(src.size)] = 1
    return a


@pytest.mark.parametrize("anchor", [0, 3, 6])
def test_reduced_laplacian_is_a_sigma_at(anchor):
    rng = np.random.default_rng(anchor)
    n = 7
    src = np.array([0, 1, 2, 3, 4, 5, 0, 2, 2])
    dst = np.array([1, 2, 3, 4, 5, 6, 6, 5, 5])  # (2, 5) twice: parallel edges add
    w = rng.uniform(0.1, 5, src.size)
    a0 = _incidence(n, src, dst)
    full = a0 @ np.diag(w) @ a0.T
    np.testing.assert_allclose(laplacian(n, src, dst, w).toarray(), full, atol=1e-13)
    keep = np.arange(n) != anchor
    np.testing.assert_allclose(reduced_laplacian(n, src, dst, w, anchor).toarray(),
                               full[np.ix_(keep, keep)], atol=1e-13)
