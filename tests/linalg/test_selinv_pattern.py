"""The selected inverse on the whole pattern of the factor against numpy's dense inverse.

Every entry the Takahashi recurrences produce (``SelectedInverse.zval``, the factor's pattern)
is compared with the same entry of ``inv(A)``, on matrices whose factors have narrow and wide
supernodes (pose-graph Laplacians of 2D/3D lattices under nested dissection, a dense matrix, a
chain), with both kernel paths forced in turn: the compiled loop for every supernode, LAPACK for
every supernode, and the default split. Plus the statuses: singular, numerically singular,
ill-conditioned.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from posecrb.core.errors import NotPositiveDefinite, NumericalError
from posecrb.linalg import selinv
from posecrb.linalg.cholesky import SymbolicCholesky
from posecrb.linalg.selinv import SelectedInverse, inverse_block_diagonal, trace_inverse

from ..numerics import EPS, assert_within, inverse_entry_atol, spd_condition

BLOCK = np.array([[2.0, 0.5, 0.1], [0.5, 1.0, 0.2], [0.1, 0.2, 3.0]])


def lattice_laplacian(shape: tuple[int, ...]) -> sp.csr_matrix:
    """Graph Laplacian of a full lattice (a pose graph's connectivity)."""
    lap = None
    for k, m in enumerate(shape):
        path = sp.diags([-np.ones(m - 1), np.r_[1.0, 2 * np.ones(m - 2), 1.0], -np.ones(m - 1)], [-1, 0, 1])
        term = path
        for j, mj in enumerate(shape):
            if j < k:
                term = sp.kron(sp.identity(mj), term)
            elif j > k:
                term = sp.kron(term, sp.identity(mj))
        lap = term if lap is None else lap + term
    return sp.csr_matrix(lap)


def lattice_fim(shape: tuple[int, ...], rng: np.random.Generator, anchor: float = 0.05) -> sp.csc_matrix:
    """``L kron B`` plus a random SPD perturbation of each pose's block and a weak anchor: the
    sparsity of a pose-graph FIM with 3 unknowns per pose."""
    n = int(np.prod(shape))
    diag = [np.eye(3) * anchor + 0.1 * (m @ m.T) for m in rng.normal(size=(n, 3, 3))]
    return sp.csc_matrix(sp.kron(lattice_laplacian(shape), BLOCK) + sp.block_diag(diag))


def chain(n: int) -> sp.csc_matrix:
    lap = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    return sp.csc_matrix(sp.kron(lap, BLOCK) + sp.identity(3 * n) * 0.01)


def dense_spd(n: int, rng: np.random.Generator) -> sp.csc_matrix:
    b = rng.normal(size=(n, n))
    return sp.csc_matrix(b @ b.T / n + np.eye(n))


def random_sparse_spd(n: int, density: float, rng: np.random.Generator) -> sp.csc_matrix:
    b = sp.random(n, n, density=density, random_state=np.random.RandomState(rng.integers(2**31)),
                  data_rvs=lambda k: rng.normal(size=k))
    return sp.csc_matrix(b @ b.T + sp.identity(n) * 0.5)


CASES = {
    "grid2d": lambda rng: lattice_fim((20, 20), rng),
    "grid3d": lambda rng: lattice_fim((6, 6, 6), rng),
    "dense": lambda rng: dense_spd(90, rng),
    "chain": lambda rng: chain(150),
    "random": lambda rng: random_sparse_spd(120, 0.02, rng),
}


def factor_of(a: sp.csc_matrix):
    # nested dissection: separators give the wide supernodes of large pose graphs at small sizes
    return SymbolicCholesky(a, ordering_method="metis").factor(a)


def supernode_widths(sel: SelectedInverse) -> np.ndarray:
    return np.diff(selinv.supernode_bounds(sel.indptr, sel.indices))


# The kernel paths: numpy's block kernels for every supernode, or the compiled kernels with
# supernodes at least ``wide`` columns through LAPACK and the rest in the compiled loop.
KERNEL_PATHS = {"block": None, "lapack-all": 1, "lapack-8": 8, "default": selinv._WIDE, "loop-all": 10**9}


def use_kernel_path(monkeypatch, path: str) -> None:
    """Force ``path`` (``KERNEL_PATHS``) on every factor, whatever its size."""
    wide = KERNEL_PATHS[path]
    monkeypatch.setattr(selinv, "_BLOCK_MAX_STEPS", np.inf if wide is None else -1.0)
    if wide is not None:
        monkeypatch.setattr(selinv, "_WIDE", wide)


def pattern_reference(sel: SelectedInverse, inv: np.ndarray) -> np.ndarray:
    """``inv`` (original ordering) at the factor's pattern, in ``zval``'s order."""
    perm = sel.perm
    cols = np.repeat(np.arange(sel.n), np.diff(sel.indptr))
    return inv[perm[np.asarray(sel.indices)], perm[cols]]


@pytest.mark.parametrize("path", sorted(KERNEL_PATHS))
@pytest.mark.parametrize("case", sorted(CASES))
def test_every_pattern_entry_matches_dense_inverse(case, path, monkeypatch):
    use_kernel_path(monkeypatch, path)
    a = CASES[case](np.random.default_rng(11))
    dense = a.toarray()
    sel = SelectedInverse(factor_of(a), case)
    ref = pattern_reference(sel, np.linalg.inv(dense))
    assert_within(sel.zval, ref, inverse_entry_atol(dense), f"{case}: selected inverse")
    assert sel.status.ok
    # the bound is a lower bound on the scaled 2-norm condition number (computed densely)
    s = 1 / np.sqrt(np.diag(dense))
    assert sel.condition_lower_bound <= spd_condition(dense * np.outer(s, s)) * (1 + 1e-8)


def test_cases_cover_narrow_and_wide_supernodes_with_rows_below():
    """The cases above exercise both kernel paths, including wide supernodes that are not the
    root (their Z_SS comes from several ancestors)."""
    rng = np.random.default_rng(11)
    widths = {}
    for case in ("grid2d", "grid3d"):
        sel = SelectedInverse(factor_of(CASES[case](rng)), case)
        bounds = selinv.supernode_bounds(sel.indptr, sel.indices)
        w = np.diff(bounds)
        below = sel.indptr[bounds[:-1] + 1] - sel.indptr[bounds[:-1]] - w
        widths[case] = (w, below)
        assert (w < selinv._WIDE).any()
        assert ((w >= selinv._WIDE) & (below > 0)).any()
    assert len(set(widths["grid3d"][0].tolist())) >= 5   # several supernode sizes


def reference_supernodes(lower: sp.csc_matrix) -> list[int]:
    """Supernode boundaries by their definition, column by column: column j + 1 continues column j's
    supernode when its structure is column j's without row j."""
    rows = [set(lower.indices[lower.indptr[j]:lower.indptr[j + 1]].tolist()) for j in range(lower.shape[0])]
    return [0] + [j + 1 for j in range(lower.shape[0] - 1) if rows[j + 1] != rows[j] - {j}] + [lower.shape[0]]


@pytest.mark.parametrize("case", sorted(CASES))
def test_supernode_bounds_follow_the_definition(case):
    sel = SelectedInverse(factor_of(CASES[case](np.random.default_rng(5))), case)
    lower = sp.csc_matrix((sel.zval, sel.indices, sel.indptr), shape=(sel.n, sel.n))
    assert selinv.supernode_bounds(sel.indptr, sel.indices).tolist() == reference_supernodes(lower)


@pytest.mark.parametrize("n", [0, 1, 2])
def test_supernode_bounds_of_tiny_factors(n):
    diagonal = sp.csc_matrix(np.eye(n))
    assert selinv.supernode_bounds(diagonal.indptr, diagonal.indices).tolist() == list(range(n + 1))
    dense = sp.csc_matrix(np.tril(np.ones((n, n))))
    assert selinv.supernode_bounds(dense.indptr, dense.indices).tolist() == ([0, n] if n else [0])


@pytest.mark.parametrize("case", ["grid2d", "grid3d", "chain"])
def test_block_kernels_are_chosen_by_their_step_count(case, monkeypatch):
    """A step per supernode and one per ``_ENTRIES_PER_STEP`` entries of the lower triangle of each
    ``Z_SS`` (``s`` rows below a supernode: ``s (s + 1) / 2``), counted here from the definition;
    the block kernels are taken exactly when that is within ``_BLOCK_MAX_STEPS``."""
    sel = SelectedInverse(factor_of(CASES[case](np.random.default_rng(5))), case)
    lower = sp.csc_matrix((sel.zval, sel.indices, sel.indptr), shape=(sel.n, sel.n))
    bounds = reference_supernodes(lower)
    entries = 0
    for first, end in zip(bounds[:-1], bounds[1:]):
        below = len([r for r in lower.indices[lower.indptr[first]:lower.indptr[first + 1]] if r >= end])
        entries += below * (below + 1) // 2
    expected = (len(bounds) - 1) + entries / selinv._ENTRIES_PER_STEP
    got = selinv.inversion_steps(sel.indptr, np.asarray(bounds))
    assert got == pytest.approx(expected, rel=1e-12)
    for budget, block in ((expected * 1.01, True), (expected * 0.99, False)):
        monkeypatch.setattr(selinv, "_BLOCK_MAX_STEPS", budget)
        kernels = selinv._inversion_kernels(sel.indptr, sel.indices, np.asarray(bounds))
        assert isinstance(kernels, selinv._BlockKernels) is block
        # a caller that inverts many factors takes the compiled kernels whatever the budget
        repeated = selinv._inversion_kernels(sel.indptr, sel.indices, np.asarray(bounds), repeated=True)
        assert repeated is selinv._kernels()


@pytest.mark.parametrize("path", ["block", "default"])
@pytest.mark.parametrize("shape", [(9, 9), (4, 4, 4)])
def test_block_diagonal_of_lattice_fims(shape, path, monkeypatch):
    use_kernel_path(monkeypatch, path)
    a = lattice_fim(shape, np.random.default_rng(2))
    inv = np.linalg.inv(a.toarray())
    got = inverse_block_diagonal(a, 3)
    ref = np.array([inv[k:k + 3, k:k + 3] for k in range(0, a.shape[0], 3)])
    assert_within(got, ref, inverse_entry_atol(a.toarray()), "blocks")
    assert trace_inverse(a) == pytest.approx(np.trace(inv), rel=a.shape[0] * 10 * spd_condition(a.toarray()) * EPS)


@pytest.mark.parametrize("path", ["block", "default"])
@pytest.mark.parametrize("shape", [(10, 10), (20, 20), (6, 6, 6)])
@pytest.mark.parametrize("ordering", ["metis", "amd"])
def test_singular_laplacian_is_never_a_silent_value(shape, ordering, path, monkeypatch):
    use_kernel_path(monkeypatch, path)
    """An unanchored pose graph: its FIM is exactly singular. Rounding lets some factorizations
    through with a pivot of the order of eps; then the status must not be ok."""
    a = sp.csc_matrix(sp.kron(lattice_laplacian(shape), BLOCK))
    try:
        factor = SymbolicCholesky(a, ordering_method=ordering).factor(a)
    except NotPositiveDefinite:
        return
    sel = SelectedInverse(factor, "singular matrix")
    assert not sel.status.ok
    assert sel.condition_lower_bound * EPS > 1e-3


def test_numerically_singular_matrix_is_unavailable():
    """[[1, 1], [1, 1 + eps]] (exact pivots 1 and eps) in a well-conditioned chain: scaled
    condition number about 4 / eps, so no digit of its inverse is right."""
    a = chain(20).tolil()
    a[0, 0], a[0, 1], a[1, 0], a[1, 1] = 1.0, 1.0, 1.0, 1.0 + EPS
    a[0, 2:] = a[2:, 0] = a[1, 2:] = a[2:, 1] = 0.0
    a = sp.csc_matrix(a)
    sel = SelectedInverse(factor_of(a), "test matrix")
    assert sel.status.state == "unavailable"
    assert "numerically singular" in sel.status.reason


@pytest.mark.parametrize("anchor", [1e-13, 1e-9, 1e-2])
def test_ill_conditioned_matrix_status_follows_its_condition(anchor):
    """A weakly anchored lattice: the status is bounded by the dense scaled condition number
    (the bound never exceeds it: ok whenever kappa is small, a warning only when kappa is large),
    and where the status is not unavailable the entries are right within kappa * eps."""
    a = sp.csc_matrix(sp.kron(lattice_laplacian((10, 10)), BLOCK) + anchor * sp.identity(300))
    dense = a.toarray()
    s = 1 / np.sqrt(np.diag(dense))
    kappa = spd_condition(dense * np.outer(s, s))
    sel = SelectedInverse(factor_of(a), "test matrix")
    assert sel.condition_lower_bound <= kappa * (1 + 1e-6)
    if kappa <= selinv.WARN_CONDITION:
        assert sel.status.ok
    if not sel.status.ok:
        assert kappa > selinv.WARN_CONDITION and "condition number" in sel.status.reason
    if anchor == 1e-13:   # kappa ~ 1e14: the bound sees it within the size of the matrix
        assert sel.status.state == "warning"
    ref = pattern_reference(sel, np.linalg.inv(dense))
    assert_within(sel.zval, ref, inverse_entry_atol(dense), "inverse")


class _GivenFactor:
    """A stand-in for a CHOLMOD factor with a given lower-triangular ``L`` and identity ordering."""

    def __init__(self, lower: np.ndarray):
        self._lower = sp.csc_matrix(lower)

    def L(self) -> sp.csc_matrix:
        return self._lower.copy()

    def P(self) -> np.ndarray:
        return np.arange(self._lower.shape[0])


@pytest.mark.parametrize("path", ["block", "lapack-all", "loop-all"])
def test_factor_pattern_not_closed_is_an_error(path, monkeypatch):
    use_kernel_path(monkeypatch, path)
    # column 0 reaches rows 1 and 2, but column 1 lacks row 2: no Cholesky factor has this pattern
    lower = np.array([[2.0, 0, 0], [0.5, 1.0, 0], [0.5, 0, 1.0]])
    with pytest.raises(NumericalError, match="not closed"):
        SelectedInverse(_GivenFactor(lower), "test matrix")


@pytest.mark.parametrize("path", ["block", "lapack-all", "loop-all"])
def test_non_finite_factor_is_an_error(path, monkeypatch):
    use_kernel_path(monkeypatch, path)
    lower = np.linalg.cholesky(np.array([[4.0, 1, 0], [1, 3, 1], [0, 1, 2]]))
    lower[2, 1] = np.inf
    with pytest.raises(NumericalError, match="not finite"):
        SelectedInverse(_GivenFactor(lower), "test matrix")


def test_given_factor_matches_dense_inverse():
    """The stand-in itself: with a true factor the entries are those of the dense inverse."""
    a = np.array([[4.0, 1, 0], [1, 3, 1], [0, 1, 2]])
    sel = SelectedInverse(_GivenFactor(np.linalg.cholesky(a)), "test matrix")
    assert_within(sel.zval, pattern_reference(sel, np.linalg.inv(a)), inverse_entry_atol(a), "inverse")
