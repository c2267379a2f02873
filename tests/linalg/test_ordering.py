"""Fill-reducing orderings (posecrb.linalg.ordering): every number is independent of the ordering
to rounding (dense numpy references, tolerances from conditioning), and ``auto`` follows its rule."""
import json

import numpy as np
import pytest
import scipy.sparse as sp

from posecrb.linalg import ordering as ordmod
from posecrb.linalg.cholesky import SymbolicCholesky
from posecrb.linalg.ordering import (
    AUTO_ND_MIN_POSES,
    AUTO_ND_MIN_POSES_2D,
    ORDERINGS,
    anchored_logdet,
    auto_ordering,
    colamd_permutation,
    expand_permutation,
    pose_block_permutation,
    resolve_ordering,
)
from posecrb.models.paper.bounds import compute_bounds, weighted_laplacians
from posecrb.models.paper.crlb import paper_crlb
from posecrb.models.paper.fim import fim_logdet, fim_symbolic_choice, paper_fim
from posecrb.models.sed.fim import sed_fim

from ..helpers import make_random_graph
from ..models.references import dense_reference
from ..numerics import EPS, MARGIN, logdet_atol, spd_condition, trace_inverse_rtol

EXPLICIT = [o for o in ORDERINGS if o != "auto"]


def _graph(dim: int, seed: int, n: int = 40):
    rng = np.random.default_rng(seed)
    return make_random_graph(rng, n=n, extra=2 * n, dim=dim, parallel=3)


# ---------------------------------------------------------------- values independent of the ordering
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("ordering", ORDERINGS)
def test_bounds_agree_with_dense_for_every_ordering(dim, ordering):
    g = _graph(dim, 10 + dim)
    anchor = 3
    got = compute_bounds(g, anchor=anchor, ordering=ordering)
    ref = dense_reference(g, anchor)
    for key in ("lb", "ub", "ub_lambda", "lambda_min_rot"):
        assert getattr(got, key) == pytest.approx(ref[key], abs=ref["tol"][key]), key
    assert set(got.ordering) == {"lb", "ub"}


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("layout", ["blocks", "poses"])
def test_fim_logdet_agrees_with_dense_for_every_ordering(dim, layout):
    g = _graph(dim, 20 + dim)
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=5, layout=layout)
    dense = fim.matrix.toarray()
    sign, ref = np.linalg.slogdet(dense)
    assert sign > 0
    tol = logdet_atol(dense)
    for o in ORDERINGS:
        assert fim_logdet(fim, ordering=o) == pytest.approx(ref, abs=tol), o


@pytest.mark.parametrize("ordering", ORDERINGS)
def test_sed_logdet_and_anchored_logdet_agree_with_dense(ordering):
    g = _graph(3, 31, n=30)
    s = sed_fim(g, g.vertex_rot, g.vertex_trans, ordering=ordering)
    keep = np.ones(g.n, bool)
    keep[s.anchors] = False
    dofs = (np.flatnonzero(keep)[:, None] * s.q + np.arange(s.q)).ravel()
    dense = s.matrix.toarray()[np.ix_(dofs, dofs)]
    sign, ref = np.linalg.slogdet(dense)
    assert sign > 0
    tol = logdet_atol(dense)
    assert s.logdet_anchored == pytest.approx(ref, abs=tol)
    got = anchored_logdet(s.matrix, s.q, list(s.anchors), "sed", ordering=ordering, dim=3)
    assert got == pytest.approx(ref, abs=tol)


@pytest.mark.parametrize("dim", [2, 3])
def test_crlb_trace_agrees_with_dense_for_every_ordering(dim):
    g = _graph(dim, 40 + dim, n=30)
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0)
    dense = fim.matrix.toarray()
    ref = float(np.trace(np.linalg.inv(dense)))
    rtol = trace_inverse_rtol(dense)
    for o in ORDERINGS:
        got = paper_crlb(g, g.vertex_rot, g.vertex_trans, anchor=0, ordering=o).trace_crlb
        assert got == pytest.approx(ref, rel=rtol), o


def test_permuted_factor_solves_and_reports_its_permutation():
    """A user permutation: the factor of A[p][:, p] behaves as a factor of A (solve, P, L, log-det)."""
    g = _graph(3, 50)
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, anchor=0)
    a = fim.matrix
    dense = a.toarray()
    rng = np.random.default_rng(0)
    perm = rng.permutation(a.shape[0])
    f = SymbolicCholesky(a, permutation=perm).factor(a)
    b = rng.normal(size=(a.shape[0], 2))
    x_ref = np.linalg.solve(dense, b)
    # forward error of a backward-stable solve: kappa * eps * n * margin
    tol = MARGIN * a.shape[0] * spd_condition(dense) * EPS * np.abs(x_ref).max()
    assert np.abs(f(b) - x_ref).max() <= tol
    assert np.abs(f.solve_A(b[:, 0]) - x_ref[:, 0]).max() <= tol
    p = f.P()
    low = f.L().toarray()
    rec = low @ low.T if low.shape == dense.shape else None
    assert rec is not None
    scale = np.sqrt(np.outer(np.diag(dense), np.diag(dense)))[np.ix_(p, p)]
    assert np.all(np.abs(rec - dense[np.ix_(p, p)]) <= MARGIN * a.shape[0] * EPS * scale)
    assert np.array_equal(np.sort(p), np.arange(a.shape[0]))
    # the same matrix stored without its explicit zeros (another CSC layout: the general permutation path)
    a2 = a.copy()
    a2.eliminate_zeros()
    if a2.nnz == a.nnz:
        pytest.skip("the FIM stores no explicit zeros")
    ld_ref = np.linalg.slogdet(dense)[1]
    sym = SymbolicCholesky(a, permutation=perm)
    assert sym.factor_logdet(a2)[1] == pytest.approx(ld_ref, abs=logdet_atol(dense))
    assert sym.factor_logdet(a)[1] == pytest.approx(ld_ref, abs=logdet_atol(dense))


def test_permuted_pattern_is_the_two_sided_permutation_of_the_matrix():
    """The analysis' gather map permutes a matrix stored with the analysed pattern exactly as
    ``a[perm][:, perm]`` does, also when the CSC rows are unsorted and a column holds its diagonal alone."""
    rng = np.random.default_rng(5)
    n = 40
    dense = sp.random(n, n, density=0.15, random_state=np.random.RandomState(5)).toarray()
    dense = dense + dense.T
    dense[:, 7] = dense[7, :] = 0.0
    dense += np.diag(np.where(np.arange(n) == 7, 1.0, n))
    a = sp.csc_matrix(dense)
    order = np.concatenate([rng.permutation(np.arange(a.indptr[j], a.indptr[j + 1])) for j in range(n)])
    shuffled = sp.csc_matrix((a.data[order], a.indices[order], a.indptr), shape=a.shape)
    perm = rng.permutation(n)
    sym = SymbolicCholesky(shuffled, permutation=perm)
    permuted = sym._permuted(shuffled)
    assert permuted.has_sorted_indices
    np.testing.assert_array_equal(permuted.toarray(), dense[np.ix_(perm, perm)])


@pytest.mark.parametrize("layout", ["poses", "blocks"])
def test_pose_adjacency_is_the_dense_block_pattern(layout):
    """Poses i and j are adjacent exactly when some stored entry couples a row of i with a row of j,
    against a dense test over every pair of poses, for pose-major and split row layouts and unsorted
    rows."""
    from posecrb.linalg.ordering import pose_adjacency_of

    rng = np.random.default_rng(8)
    n_poses, q = 30, 3
    pose_of_row = (np.repeat(np.arange(n_poses), q) if layout == "poses"
                   else np.tile(np.arange(n_poses), q))
    rows = n_poses * q
    a = sp.random(rows, rows, density=0.02, random_state=np.random.RandomState(8), format="csc")
    a = sp.csc_matrix(a + a.T + sp.identity(rows))
    order = np.concatenate([rng.permutation(np.arange(a.indptr[j], a.indptr[j + 1])) for j in range(rows)])
    a = sp.csc_matrix((a.data[order], a.indices[order], a.indptr), shape=a.shape)
    stored = a.toarray() != 0
    expected = np.array([[stored[np.ix_(pose_of_row == i, pose_of_row == j)].any() for j in range(n_poses)]
                         for i in range(n_poses)])
    got = pose_adjacency_of(a, pose_of_row, n_poses)
    np.testing.assert_array_equal(got.toarray() != 0, expected)
    assert got.has_canonical_format


def test_bad_permutation_is_a_usage_error():
    from posecrb.core.errors import UsageError

    a = sp.identity(4, format="csc")
    with pytest.raises(UsageError):
        SymbolicCholesky(a, permutation=np.array([0, 1, 1, 3]))


# ---------------------------------------------------------------- the orderings themselves
def test_colamd_is_a_true_colamd_not_amd():
    """CHOLMOD's own "colamd" on a symmetric matrix is AMD; ours orders for A A^T (COLAMD of A):
    on a 2D lattice Laplacian the two give different fill."""
    side = 12
    lap = sp.csgraph.laplacian(sp.csr_matrix(_lattice_adjacency(side))).tocsc() + sp.identity(side * side)
    lap = sp.csc_matrix(lap)
    p = colamd_permutation(lap)
    assert np.array_equal(np.sort(p), np.arange(side * side))
    nnz_col = SymbolicCholesky(lap, permutation=p).factor(lap).L().nnz
    nnz_amd = SymbolicCholesky(lap, ordering_method="amd").factor(lap).L().nnz
    assert nnz_col != nnz_amd


def _lattice_adjacency(side: int) -> sp.csr_matrix:
    k = np.arange(side * side).reshape(side, side)
    a = np.concatenate([k[:, :-1].ravel(), k[:-1, :].ravel()])
    b = np.concatenate([k[:, 1:].ravel(), k[1:, :].ravel()])
    m = sp.csr_matrix((np.ones(a.size), (a, b)), shape=(side * side, side * side))
    return m + m.T


def test_pose_block_permutation_keeps_each_pose_contiguous():
    adj = _lattice_adjacency(6)
    for method in ("amd", "colamd", "metis", "nesdis"):
        perm = pose_block_permutation(adj, 3, method)
        assert np.array_equal(np.sort(perm), np.arange(36 * 3))
        blocks = perm.reshape(-1, 3)
        assert np.all(blocks // 3 == blocks[:, :1] // 3) and np.all(np.diff(blocks, axis=1) == 1)


def test_expand_permutation_for_the_blocks_layout():
    """Rows [x_1..x_n (d each); theta_1..theta_n (dr each)]: every pose's rows end up together."""
    n, d, dr = 5, 3, 3
    k = np.arange(n)
    pose_of_row = np.concatenate([np.repeat(k, d), np.repeat(k, dr)])
    pose_perm = np.array([3, 0, 4, 1, 2])
    rows = expand_permutation(pose_perm, pose_of_row)
    assert np.array_equal(pose_of_row[rows], np.repeat(pose_perm, d + dr))


# ---------------------------------------------------------------- the rule of ``auto``
def test_auto_rule():
    assert (AUTO_ND_MIN_POSES, AUTO_ND_MIN_POSES_2D) == (10000, 50000)
    for matrix in ("lb", "ub", "fim", "crlb", "solver"):
        assert auto_ordering(2, AUTO_ND_MIN_POSES_2D - 1, matrix) == "amd"  # 2D up to 5*10^4 poses
        assert auto_ordering(3, AUTO_ND_MIN_POSES - 1, matrix) == "amd"     # small 3D
    assert auto_ordering(3, 10 ** 5, "lb") == "amd"                      # the Laplacians: AMD
    assert auto_ordering(2, 10 ** 6, "lb") == "amd"
    for matrix in ("ub", "fim", "crlb", "solver"):
        assert auto_ordering(3, AUTO_ND_MIN_POSES, matrix) == "metis"    # large block matrices
        assert auto_ordering(2, AUTO_ND_MIN_POSES_2D, matrix) == "metis"
    c = resolve_ordering("auto", dim=3, poses=21952, matrix="fim")
    assert (c.method, c.pose_level, str(c)) == ("metis", True, "metis (pose graph)")
    c = resolve_ordering("colamd", dim=3, poses=21952, matrix="fim")
    assert (c.method, c.pose_level) == ("colamd", False)
    from posecrb.core.errors import UsageError

    with pytest.raises(UsageError):
        resolve_ordering("best", dim=2, poses=10, matrix="fim")


def test_auto_reports_its_choice_small_and_large(monkeypatch):
    g = _graph(3, 60)
    b = compute_bounds(g)
    assert b.ordering == {"lb": "amd", "ub": "amd"}
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans)
    assert str(fim_symbolic_choice(fim)[1]) == "amd"
    # the same small graph taken as "large": the pose-level nested dissection path, same values
    monkeypatch.setattr(ordmod, "AUTO_ND_MIN_POSES", 10)
    b2 = compute_bounds(g)
    assert b2.ordering == {"lb": "amd", "ub": "metis (pose graph)"}
    assert str(fim_symbolic_choice(fim)[1]) == "metis (pose graph)"
    ref = dense_reference(g, 0)
    assert b2.ub == pytest.approx(ref["ub"], abs=ref["tol"]["ub"])
    g2 = _graph(2, 60)
    assert compute_bounds(g2).ordering == {"lb": "amd", "ub": "amd"}
    monkeypatch.setattr(ordmod, "AUTO_ND_MIN_POSES_2D", 10)     # a 2D graph taken as large
    b3 = compute_bounds(g2)
    assert b3.ordering == {"lb": "amd", "ub": "metis (pose graph)"}
    ref2 = dense_reference(g2, 0)
    assert b3.ub == pytest.approx(ref2["ub"], abs=ref2["tol"]["ub"])


def test_lb_laplacian_pattern_is_the_pose_graph():
    """The lb Laplacians have one row per pose: pose-level and matrix-level orderings coincide."""
    g = _graph(2, 70)
    lap = weighted_laplacians(g)
    assert lap.l_tau.shape == (g.n - 1, g.n - 1)


def test_cli_choices_match_the_library():
    from posecrb.cli.options import ordering_option

    @ordering_option
    def command(ordering):
        pass

    (param,) = command.__click_params__
    assert tuple(param.type.choices) == ORDERINGS


@pytest.mark.parametrize("ordering", ["auto", "colamd", "nesdis"])
def test_bounds_and_fim_json_say_which_ordering(tmp_path, ordering):
    from click.testing import CliRunner

    from posecrb.cli import cli
    from posecrb.io import write_g2o

    g = _graph(3, 80, n=25)
    path = tmp_path / "g.g2o"
    write_g2o(g, path)
    res = CliRunner().invoke(cli, ["bounds", str(path), "--estimate", "vertices", "--repeat", "1",
                                   "--ordering", ordering, "--format", "json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)
    row = row[0] if isinstance(row, list) else row
    want = "amd" if ordering == "auto" else (ordering if ordering == "colamd" else f"{ordering} (pose graph)")
    assert row["ordering"] == {"requested": ordering, "lb": want if ordering != "nesdis" else "nesdis (pose graph)",
                               "ub": want, "fim": want}
    res = CliRunner().invoke(cli, ["fim", str(path), "--estimate", "vertices", "--ordering", ordering,
                                   "--format", "json"])
    assert res.exit_code == 0, res.output
    row = json.loads(res.stdout)
    row = row[0] if isinstance(row, list) else row
    assert row["ordering"] == {"requested": ordering, "fim": want}



@pytest.mark.parametrize("dim", [2, 3])
def test_solver_with_large_graph_ordering_same_optimum(monkeypatch, dim):
    """The solver's M_red under ``auto``'s large-graph rule (pose-level nested dissection) reaches
    the same certified optimum: the ordering changes the factor's rounding, not the iterates beyond
    the solver's stopping tolerance (relative decrease 1e-9; regress compares objectives to 1e-6)."""
    from posecrb.solver.solve import solve

    g = _graph(dim, 91, n=60)
    ref = solve(g)
    monkeypatch.setattr(ordmod, "AUTO_ND_MIN_POSES", 10)
    monkeypatch.setattr(ordmod, "AUTO_ND_MIN_POSES_2D", 10)
    assert ordmod.auto_ordering(dim, g.n, "solver") == "metis"
    res = solve(g)
    assert ref.certified and res.certified
    assert res.objective == pytest.approx(ref.objective, rel=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
def test_solver_on_a_graph_taken_as_large_shares_one_pose_ordering(monkeypatch, dim):
    """Above auto's size threshold the chordal initialisation's connection Laplacian and M_red are
    analysed with one nested dissection of the pose graph, computed once (the very ordering that
    M_red's own pose adjacency gives); the certified optimum is the one of the small-graph path."""
    from posecrb.linalg.ordering import pose_adjacency_of, pose_permutation
    from posecrb.solver import solve
    from posecrb.solver.problem import Problem

    g = _graph(dim, 60)
    small = solve(g)
    monkeypatch.setattr(ordmod, "AUTO_ND_MIN_POSES", 10)
    monkeypatch.setattr(ordmod, "AUTO_ND_MIN_POSES_2D", 10)
    import posecrb.solver.chordal as chordal_module
    import posecrb.solver.problem as problem_module

    calls, chordal_orders = [], []
    real_order, real_symbolic = ordmod.pose_permutation, chordal_module.solver_symbolic
    monkeypatch.setattr(ordmod, "pose_permutation", lambda *a: calls.append(a) or real_order(*a))
    monkeypatch.setattr(problem_module, "pose_permutation", lambda *a: calls.append(a) or real_order(*a))
    monkeypatch.setattr(chordal_module, "solver_symbolic",
                        lambda *a, **k: chordal_orders.append(k["pose_order"]) or real_symbolic(*a, **k))
    large = solve(g)
    assert len(calls) == 1                       # one ordering of the pose graph ...
    assert len(chordal_orders) == 1 and chordal_orders[0] is not None    # ... used by the chordal Laplacian too
    assert small.certified and large.certified
    # two certified runs of the trust region (stopping at a relative decrease of 1e-9 or a Newton
    # decrement of 1e-11) from initialisations that differ by rounding
    assert large.objective == pytest.approx(small.objective, rel=1e-8)
    p = Problem.from_graph(g)
    p._full_parts()
    n, d = p.n, p.d
    own = pose_permutation(pose_adjacency_of(p._full_pattern, np.concatenate([np.arange(1, n),
                                                                              np.repeat(np.arange(n), d)]), n), "metis")
    np.testing.assert_array_equal(p.pose_order(), own)
