"""Selected inversion (posecrb.linalg.selinv) against numpy's dense inverse."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from posecrb.core.errors import NotPositiveDefinite
from posecrb.linalg.cholesky import cholesky
from posecrb.linalg.selinv import diagonal_inverse, inverse_block_diagonal, trace_inverse

from ..numerics import assert_within, inverse_entry_atol, trace_inverse_rtol


def random_sparse_spd(rng: np.random.Generator, n: int, density: float) -> sp.csc_matrix:
    """A random sparse SPD matrix: B B^T + shift, B sparse with random pattern."""
    b = sp.random(n, n, density=density, random_state=np.random.RandomState(rng.integers(2**31)),
                  data_rvs=lambda k: rng.normal(size=k))
    a = (b @ b.T + sp.identity(n) * 0.5).tocsc()
    return a


def dense_blocks(a: np.ndarray, block: int) -> np.ndarray:
    inv = np.linalg.inv(a)
    return np.array([inv[k:k + block, k:k + block] for k in range(0, a.shape[0], block)])


@pytest.mark.parametrize("n,density,block", [(30, 0.05, 3), (60, 0.03, 6), (90, 0.02, 3), (12, 0.3, 4)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_block_diagonal_matches_dense_inverse(n, density, block, seed):
    a = random_sparse_spd(np.random.default_rng(seed), n, density)
    got = inverse_block_diagonal(a, block)
    assert_within(got, dense_blocks(a.toarray(), block), inverse_entry_atol(a.toarray()), "blocks")


def test_trace_and_diagonal():
    a = random_sparse_spd(np.random.default_rng(5), 80, 0.04)
    inv = np.linalg.inv(a.toarray())
    assert trace_inverse(a) == pytest.approx(np.trace(inv), rel=trace_inverse_rtol(a.toarray()))
    assert_within(diagonal_inverse(a), np.diag(inv), inverse_entry_atol(a.toarray()), "diagonal")


def test_large_dense_supernode():
    # a dense 150 x 150 SPD matrix is one supernode wider than the forward-substitution
    # threshold, exercising the LAPACK branch
    rng = np.random.default_rng(3)
    b = rng.normal(size=(150, 150))
    a = b @ b.T / 150 + np.eye(150)
    got = inverse_block_diagonal(sp.csc_matrix(a), 5)
    assert_within(got, dense_blocks(a, 5), inverse_entry_atol(a), "blocks")


def test_block_tridiagonal_chain():
    # a long chain (Laplacian of a path + identity) kron a dense 3 x 3 block: many small supernodes
    n = 200
    lap = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    blk = np.array([[2.0, 0.5, 0.1], [0.5, 1.0, 0.2], [0.1, 0.2, 3.0]])
    a = (sp.kron(lap, blk) + sp.identity(3 * n) * 0.01).tocsc()
    got = inverse_block_diagonal(a, 3)
    assert_within(got, dense_blocks(a.toarray(), 3), inverse_entry_atol(a.toarray()), "blocks")


def test_reuses_given_factor_and_pads_when_pattern_lacks_blocks():
    # diagonal matrix: its factor has no off-diagonal entries, so the block entries must
    # come from a padded refactorization (zeros here)
    a = sp.diags(np.arange(1.0, 13.0)).tocsc()
    f = cholesky(a)
    got = inverse_block_diagonal(a, 3, factor=f)
    # diagonal: 1/a_ii, correctly rounded up to the square root and division of the factor
    np.testing.assert_allclose(got, dense_blocks(a.toarray(), 3), rtol=4 * np.finfo(float).eps, atol=0)
    b = random_sparse_spd(np.random.default_rng(9), 40, 0.2)
    got = inverse_block_diagonal(b, 4, factor=cholesky(b))
    assert_within(got, dense_blocks(b.toarray(), 4), inverse_entry_atol(b.toarray()), "blocks")


def test_not_positive_definite():
    a = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(NotPositiveDefinite):
        inverse_block_diagonal(a, 3, name="test matrix")
    with pytest.raises(NotPositiveDefinite):
        trace_inverse(a)


def test_shape_must_be_a_multiple_of_the_block():
    with pytest.raises(ValueError):
        inverse_block_diagonal(sp.identity(10, format="csc"), 3)


@pytest.mark.slow
@pytest.mark.parametrize("name,stride", [("intel.g2o", 97), ("parking-garage.g2o", 83)])
def test_real_fim_blocks_match_sparse_lu_solves(shared_datasets, name, stride):
    """Per-pose blocks of a real FIM's inverse against columns from an independent sparse LU."""
    from scipy.sparse.linalg import splu

    from posecrb.io import load
    from posecrb.models.paper.fim import paper_fim

    g = load(shared_datasets / name)
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, layout="poses")
    q = fim.q
    blocks = inverse_block_diagonal(fim.matrix, q)
    lu = splu(fim.matrix.tocsc())
    poses = np.arange(0, fim.n_free, stride)
    rhs = np.zeros((fim.size, poses.size * q))
    for t, k in enumerate(poses):
        rhs[k * q:(k + 1) * q, t * q:(t + 1) * q] = np.eye(q)
    cols = lu.solve(rhs)
    for t, k in enumerate(poses):
        ref = cols[k * q:(k + 1) * q, t * q:(t + 1) * q]
        # both sides carry rounding of order cond(F) eps relative to the block's scale
        np.testing.assert_allclose(blocks[k], ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max())


def test_empty_matrix():
    assert inverse_block_diagonal(sp.csc_matrix((0, 0)), 3).shape == (0, 3, 3)
    assert trace_inverse(sp.csc_matrix((0, 0))) == 0.0


def _dense_absolute_terms(factor) -> float:
    """``sum_ij |Z_ij| (|L| |L^T|)_ij`` densely, Z the inverse of L L^T (the factor's ordering)."""
    lower = factor.L().toarray()
    z = np.linalg.inv(lower @ lower.T)
    return float(np.sum(np.abs(z) * (np.abs(lower) @ np.abs(lower).T)))


# numpy's block kernels (None), or the compiled ones with every supernode through LAPACK, the
# default split, none through LAPACK
@pytest.mark.parametrize("wide", [None, 1, 32, 10**9])
@pytest.mark.parametrize("case", ["random", "chain", "dense"])
def test_absolute_terms_match_the_dense_sum(monkeypatch, wide, case):
    """The log-det's componentwise condition number (posecrb.linalg.accuracy), summed supernode by
    supernode during the selected inversion, against the dense ``|Z| (|L| |L^T|)``."""
    from posecrb.linalg import selinv

    monkeypatch.setattr(selinv, "_BLOCK_MAX_STEPS", np.inf if wide is None else -1.0)
    if wide is not None:
        monkeypatch.setattr(selinv, "_WIDE", wide)
    rng = np.random.default_rng(11)
    if case == "random":
        a = random_sparse_spd(rng, 90, 0.03)
    elif case == "chain":
        n = 120
        lap = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
        a = (sp.kron(lap, np.array([[2.0, 0.5], [0.5, 1.0]])) + sp.identity(2 * n) * 0.01).tocsc()
    else:
        b = rng.normal(size=(70, 70))
        a = sp.csc_matrix(b @ b.T / 70 + np.eye(70))
    factor = cholesky(a)
    got = selinv.SelectedInverse(factor, absolute_terms=True).absolute_terms
    reference = _dense_absolute_terms(factor)
    # a sum of positive terms whose Z entries each carry the inverse's error (inverse_entry_atol)
    dense = a.toarray()
    n = dense.shape[0]
    lower = np.abs(factor.L().toarray())
    weight = float(np.sum(lower @ lower.T))
    tol = inverse_entry_atol(dense) * weight + 10 * n * n * np.finfo(float).eps * reference
    assert got is not None and abs(got - reference) <= tol
    assert selinv.SelectedInverse(factor).absolute_terms is None


@pytest.mark.parametrize("block", [False, True], ids=["compiled", "block"])
def test_large_separators_run_threaded_with_the_same_inverse(monkeypatch, block):
    """The supernodes above ``_THREADED_FLOPS`` run numpy's BLAS at the usable thread count, the rest
    at one; the inverse and the log-det's absolute terms match the dense ones either way. The
    compiled kernels take the supernodes of at least ``_WIDE`` columns through BLAS, the block
    kernels all of them."""
    from posecrb.linalg import selinv, threads

    real = threads.python_blas
    seen: list[int] = []

    class Recording:
        """numpy's BLAS controller, recording the limits set on it."""

        def __init__(self) -> None:
            self.ctl = real()

        def limit(self, limits: int):
            seen.append(limits)
            return self.ctl.limit(limits=limits)

        def __getattr__(self, name: str):
            return getattr(self.ctl, name)

    monkeypatch.setattr(threads, "python_blas", Recording)
    monkeypatch.setattr(threads, "python_blas_usable_threads", lambda: 2)
    # a 2D grid of 3x3 blocks: separators 9-12 columns wide with 30-42 rows below and a root of 60
    # columns (24,000-144,000 flops of inversion each), so that some run threaded and some not
    monkeypatch.setattr(selinv, "_WIDE", 8)
    monkeypatch.setattr(selinv, "_BLOCK_MAX_STEPS", np.inf if block else -1.0)
    wide = 0 if block else 8
    monkeypatch.setattr(selinv, "_THREADED_FLOPS", 3e4)
    side = 14
    path = sp.diags([-np.ones(side - 1), 2 * np.ones(side), -np.ones(side - 1)], [-1, 0, 1])
    grid = sp.kronsum(path, path)
    a = (sp.kron(grid, np.array([[2.0, 0.5, 0.1], [0.5, 1.0, 0.2], [0.1, 0.2, 3.0]]))
         + sp.identity(3 * side * side) * 0.01).tocsc()
    factor = cholesky(a)
    sel = selinv.SelectedInverse(factor, absolute_terms=True)
    lower = factor.L()
    indptr = lower.indptr.astype(np.int64)
    bounds = selinv.supernode_bounds(indptr, lower.indices)
    w = np.diff(bounds)
    s = indptr[bounds[:-1] + 1] - indptr[bounds[:-1]] - w
    big = int(((w >= wide) & (2.0 * s**2 * w + 3.0 * s * w**2 + 2.0 * w**3 / 3.0 >= 3e4)).sum())
    assert 0 < big < int((w >= wide).sum())    # both kinds of BLAS supernodes are exercised
    assert seen == [1] + [2] * big              # the big ones on two threads, inside one thread
    dense = a.toarray()
    assert_within(sel.diagonal(), np.diag(np.linalg.inv(dense)), inverse_entry_atol(dense), "diagonal")
    reference = _dense_absolute_terms(factor)
    lower = np.abs(factor.L().toarray())
    tol = (inverse_entry_atol(dense) * float(np.sum(lower @ lower.T))
           + 10 * dense.shape[0] ** 2 * np.finfo(float).eps * reference)
    assert sel.absolute_terms is not None and abs(sel.absolute_terms - reference) <= tol
