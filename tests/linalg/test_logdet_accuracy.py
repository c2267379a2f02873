"""The log-det's accuracy bound (posecrb.linalg.accuracy) in its three tiers, against dense references.

The quantity bounded is ``S = sum_ij |Z_ij| (|L| |L^T|)_ij`` (Z the inverse of ``L L^T``, the
factor's ordering). The selected-inversion tier computes S itself; the lambda_min tier bounds it by
``|| |L|^T s ||^2 / lambda``, ``s = diag(A)^{-1/2}`` and ``lambda`` a certified lower bound of the
smallest eigenvalue of ``D^{-1/2} A D^{-1/2}``; the spanning_tree tier by ``|| |L|^T sqrt(z) ||^2``
for an upper bound z of ``diag(Z)``. All are compared with S and with those closed forms computed
densely (numpy's inverse and eigenvalues), on graphs whose bound stays below the warning threshold
and on graphs that cross it (anisotropic information summed on the same poses), where
``tier="auto"`` must give exactly the selected inversion's bound, status and message.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from posecrb.core.errors import UsageError
from posecrb.linalg import accuracy
from posecrb.linalg.accuracy import LOGDET_WARN, LogdetAccuracy, logdet_accuracy
from posecrb.linalg.cholesky import cholesky
from posecrb.models.paper.fim import paper_fim

from ..helpers import random_pose_graph
from ..numerics import MARGIN, inverse_entry_atol

EPS = float(np.finfo(float).eps)


def dense_reference(factor, a: sp.spmatrix) -> tuple[float, float, float]:
    """(S, || |L|^T s ||^2 / lambda_min(D^{-1/2} A D^{-1/2}), lambda_min) densely."""
    lower = factor.L().toarray()
    absl = np.abs(lower)
    weight = absl @ absl.T
    z = np.linalg.inv(lower @ lower.T)
    exact = float(np.sum(np.abs(z) * weight))
    dense = a.toarray()
    d = np.diag(dense)
    s = 1.0 / np.sqrt(d[factor.P()])
    scaled = dense / np.sqrt(np.outer(d, d))
    lam = float(np.linalg.eigvalsh(scaled)[0])
    return exact, float(s @ weight @ s) / lam, lam


def exact_tolerance(factor, a: sp.spmatrix, exact: float) -> float:
    """A sum of positive terms whose Z entries each carry the inverse's error (inverse_entry_atol)."""
    dense = a.toarray()
    absl = np.abs(factor.L().toarray())
    return inverse_entry_atol(dense) * float(np.sum(absl @ absl.T)) + 10 * dense.shape[0] ** 2 * EPS * exact


def pose_graph_fim(n: int, dim: int, seed: int, loop_closures: int | None = None) -> sp.csc_matrix:
    g, rot, trans = random_pose_graph(n, dim, np.random.default_rng(seed),
                                      loop_closures=n // 3 if loop_closures is None else loop_closures)
    return sp.csc_matrix(paper_fim(g, rot, trans).matrix)


def anisotropic_grid(side: int, ratio: float, seed: int) -> sp.csc_matrix:
    """A 2D grid's translation information, anchored at pose 0: each edge measures x with
    information ``ratio`` and y with ``1 / ratio`` or the other way round (random), so every pose sums
    information of magnitudes ``ratio^2`` apart (the scaled grids of the issue: digits lost in the
    assembly, before any factorization, once ``ratio^2 eps`` nears the printed precision)."""
    rng = np.random.default_rng(seed)
    idx = np.arange(side * side).reshape(side, side)
    src = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    dst = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    m = src.size
    flip = rng.random(m) < 0.5
    wx = np.where(flip, ratio, 1.0 / ratio) * rng.uniform(0.5, 2.0, m)
    wy = np.where(flip, 1.0 / ratio, ratio) * rng.uniform(0.5, 2.0, m)
    rows, cols, vals = [], [], []
    for axis, w in ((0, wx), (1, wy)):
        i, j = 2 * src + axis, 2 * dst + axis
        rows += [i, j, i, j]
        cols += [i, j, j, i]
        vals += [w, w, -w, -w]
    n = 2 * side * side
    a = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    keep = np.arange(2, n)
    return sp.csc_matrix(a[keep][:, keep])


def both_tiers(a: sp.spmatrix, name: str = "matrix") -> tuple[float, LogdetAccuracy, LogdetAccuracy]:
    factor = cholesky(a)
    ld = float(factor.logdet())
    return (ld, logdet_accuracy(factor, ld, name, matrix=a, tier="selected_inversion"),
            logdet_accuracy(factor, ld, name, matrix=a, tier="lambda_min"))


WELL = {"2d chain": lambda: pose_graph_fim(40, 2, 1), "3d chain": lambda: pose_graph_fim(30, 3, 2),
        "isotropic grid": lambda: anisotropic_grid(8, 1.0, 3)}
# anisotropy ratio of the scaled grids: at 1e2 both tiers prove the printed digits; at 1e4 only the
# exact one does (the lambda_min tier's bound crosses the threshold); 1e5 and 1e6 are warnings, and at
# 1e6 the scaled matrix's smallest eigenvalue is below the lambda_min tier's rounding level
CROSSING = {f"scaled grid {r:g}": (lambda r=r: anisotropic_grid(8, r, 4)) for r in (1e2, 1e4, 1e5, 1e6)}
EXPECTED_STATE = {"scaled grid 100": "ok", "scaled grid 10000": "ok", "scaled grid 100000": "warning",
                  "scaled grid 1e+06": "warning"}


@pytest.mark.parametrize("case", sorted(WELL) + sorted(CROSSING))
def test_both_tiers_bound_the_dense_sum(case):
    a = {**WELL, **CROSSING}[case]()
    factor = cholesky(a)
    exact_sum, closed, lam = dense_reference(factor, a)
    ld, exact, cheap = both_tiers(a)
    assert (exact.tier, exact.condition_kind) == ("selected_inversion", "exact")
    assert (cheap.tier, cheap.condition_kind) == ("lambda_min", "upper bound")
    assert abs(exact.condition - exact_sum) <= exact_tolerance(factor, a, exact_sum)
    gamma = (int(np.diff(factor.L().indptr).max()) + 2) * EPS
    assert exact.error_bound == pytest.approx(gamma * exact.condition, rel=1e-15)
    # the lambda_min tier: at least the closed form with the exact eigenvalue (its lambda is a
    # certified lower bound), at most that form with the Lanczos run's eigenvalue (relative
    # residual _LANCZOS_TOL: mu >= lambda_min / ((1 + 2 tol) _MU_MARGIN)) less the inertia check's rounding
    # margin (gamma (1 + gamma) x the longest row of the pattern of L + L^T, + 2 eps), hence at
    # least the exact sum
    if cheap.condition == np.inf:          # lambda_min below the rounding level of the inertia check
        assert case == "scaled grid 1e+06" and "could not be certified" in cheap.status.reason
        return
    pattern = (factor.L() != 0).toarray()
    margin = gamma * (1 + gamma) * int(np.max(pattern.sum(axis=0) + pattern.sum(axis=1) - 1)) + 2 * EPS
    mu = lam / ((1 + 4 * accuracy._LANCZOS_TOL) * accuracy._MU_MARGIN)
    assert closed * (1 - 1e-9) <= cheap.condition <= closed * lam / (mu - margin)
    assert cheap.condition >= exact_sum
    assert cheap.error_bound == pytest.approx(gamma * cheap.condition, rel=1e-15)


@pytest.mark.parametrize("case", sorted(WELL) + sorted(CROSSING))
def test_auto_keeps_the_exact_status_and_message(case, monkeypatch):
    """With the size rule off (every factor tries the lambda_min tier first), ``auto`` keeps the
    lambda_min tier only where it proves LOGDET_WARN; elsewhere its result is the selected
    inversion's, bound, status and message alike."""
    monkeypatch.setattr(accuracy, "EXACT_FIRST_STEPS", -1)
    a = {**WELL, **CROSSING}[case]()
    ld, exact, cheap = both_tiers(a)
    auto = logdet_accuracy(cholesky(a), ld, "matrix", matrix=a)
    limit = LOGDET_WARN * max(1.0, abs(ld))
    if cheap.error_bound <= limit:
        assert auto.tier == "lambda_min" and auto.status.ok and exact.status.ok
        assert auto.error_bound == pytest.approx(cheap.error_bound, rel=1e-6)
    else:
        assert auto == exact
    assert auto.status == exact.status
    assert exact.status.state == EXPECTED_STATE.get(case, "ok")
    if case == "scaled grid 10000":        # the case the lambda_min tier alone would have flagged
        assert cheap.status.state == "warning" and auto.tier == "selected_inversion"


@pytest.mark.parametrize("case", sorted(WELL) + sorted(CROSSING))
@pytest.mark.parametrize("slack", [1.0, 1e3])
def test_the_diagonal_tier_bounds_the_dense_sum_and_keeps_the_exact_status(case, slack, monkeypatch):
    """The spanning_tree tier with ``z`` = the dense inverse's diagonal (rounded up by its own error
    bound) times ``slack``: its condition is the closed form || |L|^T sqrt(z) ||^2, at least the
    exact sum; under ``auto``, tried first (TREE_FIRST_FLOPS 0), it is kept only where it proves
    LOGDET_WARN, and every status is the selected inversion's."""
    monkeypatch.setattr(accuracy, "EXACT_FIRST_STEPS", -1)
    monkeypatch.setattr(accuracy, "TREE_FIRST_FLOPS", 0.0)
    a = {**WELL, **CROSSING}[case]()
    factor = cholesky(a)
    exact_sum, _, _ = dense_reference(factor, a)
    dense = a.toarray()
    z = (np.diag(np.linalg.inv(dense)) + inverse_entry_atol(dense)) * slack
    lower = np.abs(factor.L().toarray())
    root = np.sqrt(z[factor.P()])
    closed = float(root @ (lower @ lower.T) @ root)
    ld, exact, _ = both_tiers(a)
    tree = logdet_accuracy(factor, ld, "matrix", tier="spanning_tree", inverse_diagonal=z)
    assert (tree.tier, tree.condition_kind) == ("spanning_tree", "upper bound")
    assert tree.condition == pytest.approx(closed, rel=MARGIN * a.shape[0] * EPS)
    assert tree.condition >= exact_sum - exact_tolerance(factor, a, exact_sum)
    auto = logdet_accuracy(factor, ld, "matrix", matrix=a, inverse_diagonal=z)
    if tree.error_bound <= LOGDET_WARN * max(1.0, abs(ld)):
        assert auto == tree and exact.status.ok
    else:      # the next tiers read the factor's own L again (the tree's tier took |L| in place)
        assert auto.tier != "spanning_tree"
        if auto.tier == "selected_inversion":
            assert auto == exact
    assert auto.status == exact.status


def test_the_tiers_run_in_order_of_cost(monkeypatch):
    """Below TREE_FIRST_FLOPS the lambda_min tier runs first and the spanning tree only where it
    cannot prove the digits; at or above it the spanning tree first; the diagonal is computed only
    when its tier runs."""
    a = pose_graph_fim(1500, 2, 6)
    f = cholesky(a)
    assert accuracy.factorization_flops(f.L()) < accuracy.TREE_FIRST_FLOPS
    z = np.diag(np.linalg.inv(a.toarray())) * 2.0
    calls: list[str] = []

    def diagonal():
        calls.append("diagonal")
        return z

    got = logdet_accuracy(f, f.logdet(), matrix=a, inverse_diagonal=diagonal)
    assert got.tier == "lambda_min" and calls == []
    monkeypatch.setattr(accuracy, "_lambda_min_tier", lambda *args, **kwargs: calls.append("lambda_min"))
    got = logdet_accuracy(f, f.logdet(), matrix=a, inverse_diagonal=diagonal)
    assert got.tier == "spanning_tree" and calls == ["lambda_min", "diagonal"]
    calls.clear()
    monkeypatch.setattr(accuracy, "TREE_FIRST_FLOPS", accuracy.factorization_flops(f.L()))
    got = logdet_accuracy(f, f.logdet(), matrix=a, inverse_diagonal=diagonal)
    assert got.tier == "spanning_tree" and calls == ["diagonal"]
    # a caller without a bound costs no second copy of L; a bound that does not prove the digits
    # (the tier took |L| in place) one, for the tiers after it
    copies = []
    honest_lower = accuracy._lower
    monkeypatch.setattr(accuracy, "_lower", lambda factor: copies.append(1) or honest_lower(factor))
    monkeypatch.setattr(accuracy, "_lambda_min_tier", lambda *args, **kwargs: None)
    assert logdet_accuracy(f, f.logdet(), matrix=a, inverse_diagonal=lambda: None).tier == "selected_inversion"
    assert len(copies) == 1
    copies.clear()
    loose = logdet_accuracy(f, f.logdet(), matrix=a, inverse_diagonal=z * 1e30)
    assert loose == logdet_accuracy(f, f.logdet(), tier="selected_inversion") and len(copies) == 3
    # flops = sum of squared column counts
    counts = np.diff(f.L().tocsc().indptr)
    assert accuracy.factorization_flops(f.L()) == float(np.sum(counts.astype(float) ** 2))


def test_auto_tries_the_cheap_tier_only_on_factors_worth_it():
    """Below EXACT_FIRST_STEPS steps of the selected inversion ``auto`` takes it directly (exact
    numbers at no more cost); without the matrix it is the only tier."""
    small = pose_graph_fim(10, 2, 5)
    f = cholesky(small)
    assert logdet_accuracy(f, f.logdet(), matrix=small).tier == "selected_inversion"
    large = pose_graph_fim(1500, 2, 6)
    f = cholesky(large)
    assert logdet_accuracy(f, f.logdet(), matrix=large).tier == "lambda_min"
    assert logdet_accuracy(f, f.logdet()).tier == "selected_inversion"


def test_an_eigenvalue_the_inertia_check_refutes_is_never_used(monkeypatch):
    """A Lanczos value that overstates lambda_min (as an unconverged run could) fails the factorization
    of A - mu D: the forced tier then reports no bound, and ``auto`` falls back on the exact one."""
    from posecrb.linalg import lanczos

    a = pose_graph_fim(60, 2, 7)
    f = cholesky(a)
    ld = float(f.logdet())
    honest = lanczos.largest_eigenpair

    def understated(*args, **kwargs):
        ritz = honest(*args, **kwargs)
        return lanczos.RitzPair(ritz.value / 100, ritz.vector, 0.0, True, ritz.matvecs, ritz.restarts)

    monkeypatch.setattr(lanczos, "largest_eigenpair", understated)
    forced = logdet_accuracy(f, ld, "paper FIM", matrix=a, tier="lambda_min")   # fails twice: 100 > _MU_RETRY
    assert forced.error_bound == np.inf and forced.status.state == "unavailable"
    assert "inertia check" in forced.status.reason
    monkeypatch.setattr(accuracy, "EXACT_FIRST_STEPS", -1)
    auto = logdet_accuracy(f, ld, "paper FIM", matrix=a)
    assert auto == logdet_accuracy(f, ld, "paper FIM", tier="selected_inversion")


def test_a_failed_inertia_check_is_retried_once_lower(monkeypatch):
    """A Lanczos value half the true one (a top eigenvalue the Krylov space missed): the first
    check fails, the second at mu / _MU_RETRY holds, and the bound is that much looser."""
    from posecrb.linalg import lanczos

    a = pose_graph_fim(60, 2, 7)
    f = cholesky(a)
    ld = float(f.logdet())
    _, closed, _ = dense_reference(f, a)
    honest = lanczos.largest_eigenpair

    def halved(*args, **kwargs):
        ritz = honest(*args, **kwargs)
        return lanczos.RitzPair(ritz.value / 2, ritz.vector, 0.0, True, ritz.matvecs, ritz.restarts)

    monkeypatch.setattr(lanczos, "largest_eigenpair", halved)
    retried = logdet_accuracy(f, ld, "paper FIM", matrix=a, tier="lambda_min")
    factor = 2 / (accuracy._MU_MARGIN * accuracy._MU_RETRY)       # mu over lambda_min after the retry
    assert retried.tier == "lambda_min" and retried.status.ok
    assert retried.condition == pytest.approx(closed / factor, rel=1e-3)


def test_auto_retries_where_the_bound_just_proves_the_digits(monkeypatch):
    """``auto``'s retry after a failed inertia check goes no lower than needed but as low as that:
    with the threshold where mu = lambda_min / 2 just proves the digits and a Lanczos value a quarter
    of the true one, the first check (about 3.8 lambda_min) fails, mu / _MU_RETRY (0.48 lambda_min)
    would not prove the digits, and the check at lambda_min / 2 holds: a bound at the threshold."""
    from posecrb.linalg import lanczos

    a = pose_graph_fim(60, 2, 7)
    f = cholesky(a)
    ld = float(f.logdet())
    _, closed, lam = dense_reference(f, a)
    gamma = (int(np.diff(f.L().indptr).max()) + 2) * EPS
    monkeypatch.setattr(accuracy, "LOGDET_WARN", 2 * gamma * closed / max(1.0, abs(ld)))
    monkeypatch.setattr(accuracy, "EXACT_FIRST_STEPS", -1)
    honest = lanczos.largest_eigenpair

    def quartered(*args, **kwargs):
        ritz = honest(*args, **kwargs)
        return lanczos.RitzPair(ritz.value / 4, ritz.vector, 0.0, True, ritz.matvecs, ritz.restarts)

    monkeypatch.setattr(lanczos, "largest_eigenpair", quartered)
    auto = logdet_accuracy(f, ld, "paper FIM", matrix=a)
    limit = accuracy.LOGDET_WARN * max(1.0, abs(ld))
    assert auto.tier == "lambda_min" and auto.status.ok
    assert auto.error_bound <= limit and auto.error_bound == pytest.approx(limit, rel=1e-6)
    forced = logdet_accuracy(f, ld, "paper FIM", matrix=a, tier="lambda_min")   # mu / 8: a warning
    assert forced.status.state == "warning" and forced.condition == pytest.approx(closed * 8 * 1.05 / 4, rel=1e-3)


def test_the_shifted_matrix_keeps_the_analysed_pattern():
    """``A - diag(v)`` for the inertia check: the same numbers as scipy's subtraction, in the very
    index arrays of A when A is canonical CSC (so the factor's analysis permutes it by a gather, which
    gives what two-sided slicing gives); through scipy otherwise."""
    from posecrb.linalg.cholesky import PermutedFactor, SymbolicCholesky

    a = pose_graph_fim(40, 3, 12)
    v = np.random.default_rng(0).uniform(0.0, 1e-3, a.shape[0]) * a.diagonal()
    reference = (a - sp.diags(v)).toarray()
    shifted = accuracy._diagonal_shift(a)(v)
    assert np.shares_memory(shifted.indices, a.indices) and np.shares_memory(shifted.indptr, a.indptr)
    assert np.array_equal(shifted.toarray(), reference)
    messy = sp.csc_matrix(a, copy=True)
    messy.has_canonical_format = False               # (as after an unsorted construction)
    assert np.allclose(accuracy._diagonal_shift(messy)(v).toarray(), reference, rtol=1e-15, atol=0)
    gap = sp.lil_matrix(a)
    gap[3, 3] = 0.0
    gap = sp.csc_matrix(gap)
    gap.eliminate_zeros()                            # a column without its diagonal entry
    assert np.array_equal(accuracy._diagonal_shift(gap)(v).toarray(), gap.toarray() - np.diag(v))
    perm = np.random.default_rng(1).permutation(a.shape[0])
    factor = SymbolicCholesky(a, permutation=perm).factor(a)
    assert isinstance(factor, PermutedFactor)
    fast, slow = factor.permuted(shifted), PermutedFactor(factor._inner, perm, factor._inverse_perm).permuted(shifted)
    assert np.array_equal(fast.toarray(), slow.toarray())


def test_arguments_and_the_empty_matrix():
    a = pose_graph_fim(8, 2, 8)
    f = cholesky(a)
    with pytest.raises(UsageError, match="tier must be one of"):
        logdet_accuracy(f, f.logdet(), tier="norm")
    with pytest.raises(UsageError, match="needs the factored matrix"):
        logdet_accuracy(f, f.logdet(), tier="lambda_min")
    with pytest.raises(UsageError, match="needs an upper bound of the inverse's diagonal"):
        logdet_accuracy(f, f.logdet(), tier="spanning_tree")
    with pytest.raises(UsageError, match="entries for a matrix of"):
        logdet_accuracy(f, f.logdet(), tier="spanning_tree", inverse_diagonal=np.ones(a.shape[0] + 1))
    negative = logdet_accuracy(f, f.logdet(), tier="spanning_tree", inverse_diagonal=-np.ones(a.shape[0]))
    assert negative.status.state == "unavailable" and "not positive" in negative.status.reason
    empty = logdet_accuracy(None, 0.0)
    assert (empty.condition, empty.error_bound, empty.status.ok) == (0.0, 0.0, True)
    assert set(empty.as_json()) >= {"condition", "error_bound", "tier", "condition_kind"}


def test_the_cheap_tier_loads_no_numba():
    """A factor large enough for the compiled selected-inversion kernels (posecrb.linalg.selinv: the
    3D grid of 1,728 poses) is bounded by the lambda_min tier without importing numba."""
    code = ("import sys, numpy as np, scipy.sparse as sp; from posecrb.sim.generators import grid; "
            "from posecrb.models.paper.fim import paper_fim; from posecrb.linalg.cholesky import cholesky; "
            "from posecrb.linalg.accuracy import logdet_accuracy; from posecrb.linalg import selinv; "
            "g = grid(3, 12); a = sp.csc_matrix(paper_fim(g, g.vertex_rot, g.vertex_trans).matrix); f = cholesky(a); "
            "L = f.L().tocsc(); ip = L.indptr.astype(np.int64); "
            "steps = selinv.inversion_steps(ip, selinv.supernode_bounds(ip, L.indices)); "
            "acc = logdet_accuracy(f, f.logdet(), matrix=a); "
            "print(steps > selinv._BLOCK_MAX_STEPS, acc.tier, acc.status.state, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    assert out.stdout.split() == ["True", "lambda_min", "ok", "False"]


# The tier ``auto`` takes on each SE-Sync file's paper FIM (at its vertices, or at the certified
# estimate for the files without any): the selected inversion where it is small (tinyGrid3D,
# smallGrid3D: at most EXACT_FIRST_STEPS steps); the spanning tree's bound where the factorization
# takes at least TREE_FIRST_FLOPS, or where the lambda_min bound cannot prove the digits (ais2klinik,
# parking-garage: 5.0e4 and 1.1e4 times the exact one against thresholds 21 and 44 times it); the
# lambda_min tier on the other small factors.
SESYNC_TIERS = {
    **dict.fromkeys(("CSAIL", "MIT", "intel", "kitti_05", "manhattan", "kitti_02", "kitti_00"), "lambda_min"),
    **dict.fromkeys(("city10000", "sphere2500", "sphere_bignoise_vertex3", "torus3D", "cubicle", "ais2klinik",
                     "parking-garage"), "spanning_tree"),
    **dict.fromkeys(("tinyGrid3D", "smallGrid3D"), "selected_inversion"),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SESYNC_TIERS))
def test_real_datasets_keep_their_status(shared_datasets, name):
    """On every SE-Sync file ``auto`` (with the paper FIM's spanning tree) gives the exact tier's
    status and message, and a bound at least the exact one, from the expected tier."""
    import posecrb
    from posecrb.models.paper.fim import fim_logdet_accuracy, fim_symbolic
    from posecrb.solver.estimate import get_estimate

    g = posecrb.load(shared_datasets / f"{name}.g2o")
    est = get_estimate(g, "solve" if g.vertex_rot is None else "vertices")
    fim = paper_fim(g, est.rot, est.trans)
    factor, ld = fim_symbolic(fim, "auto").factor_logdet(fim.matrix, name="paper FIM")
    exact = logdet_accuracy(factor, ld, "paper FIM", tier="selected_inversion")
    auto = fim_logdet_accuracy(fim, factor, ld, g, est.rot, est.trans)
    assert auto.tier == SESYNC_TIERS[name] and auto.status == exact.status and auto.status.ok
    assert auto.error_bound >= exact.error_bound
    if name in ("ais2klinik", "cubicle"):
        assert (accuracy.factorization_flops(factor.L()) >= accuracy.TREE_FIRST_FLOPS) == (name == "cubicle")


@pytest.mark.slow
def test_bounds_of_ais2klinik_loads_no_numba(shared_datasets):
    """ais2klinik's digits, which the lambda_min tier cannot prove, come from the spanning tree: the
    default ``bounds`` loads no compiled kernel."""
    code = ("import sys, posecrb; from posecrb.cli import main; "
            f"rc = main(['bounds', {str(shared_datasets / 'ais2klinik.g2o')!r}, '--format', 'json']); "
            "print(rc, 'numba' in sys.modules, file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False, timeout=300)
    assert out.stderr.strip().splitlines()[-1] == "0 False", out.stderr
    assert "fim_logdet_status" not in json.loads(out.stdout)
