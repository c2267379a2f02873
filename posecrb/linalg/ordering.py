"""Fill-reducing orderings for the sparse Cholesky factorizations (``--ordering``).

docs/design.md#linear-algebra. Every log-determinant and inverse of posecrb is computed from a
CHOLMOD factor ``L L^T = P A P^T``; the ordering ``P`` changes the cost (the fill nnz(L) and
the flops) and the rounding, never the value beyond rounding. The choices:

* ``amd``: CHOLMOD's approximate minimum degree on the matrix being factored.
* ``colamd``: column approximate minimum degree of the matrix, the ordering the paper's
  Algorithm 1 names (MATLAB's ``colamd(A)``: COLAMD orders the columns of ``A`` for the
  factorization of ``A^T A``). CHOLMOD applies COLAMD only to unsymmetric problems (its
  ``colamd`` choice on a symmetric matrix is AMD), so the permutation is computed here by
  CHOLMOD's COLAMD on ``A A^T`` (``analyze_AAt``; ``A`` is symmetric) and handed to the
  factorization as a user permutation. It orders for ``A^2``, not ``A``, so its fill is larger
  than AMD's on these matrices; it is offered to reproduce Algorithm 1, not for speed.
* ``metis`` / ``nesdis``: nested dissection (METIS's node nested dissection / CHOLMOD's own
  NESDIS built on METIS's graph partitioner) of the **pose graph** -- the pattern of the
  reduced Laplacian, one row per pose -- expanded to each pose's block of rows (d_r rows in the
  ``ub`` matrix, q = d + d_r in the FIM): the partitioner sees n_p vertices instead of q n_p,
  and the separators cut whole poses. For the Laplacians of ``lb`` (one row per pose) this is
  CHOLMOD's ordering of the matrix itself.
* ``auto``: ``auto_ordering``, chosen by CHOLMOD's flop counts and by timing every ordering
  (docs/decisions/orderings.md): AMD, except METIS's nested dissection of the pose graph for
  the block matrices (FIM, ``ub``, CRLB, the solver's M_red) of 3D graphs with at least
  ``AUTO_ND_MIN_POSES`` poses and 2D graphs with at least ``AUTO_ND_MIN_POSES_2D``. AMD's fill
  grows faster than nested dissection's on large graphs (3D grid of 21,952 poses, the FIM in
  its pose-major layout: 895 Gflop with AMD, 387 with ``nesdis`` and 341 with ``metis`` on the
  pose graph, 373 with CHOLMOD's nesdis of the scalar matrix, whose analysis orders the
  131,706-row matrix instead of the 21,952-node pose graph; 2D grid of 100,489 poses: 18.1 Gflop
  and 31.6M nonzeros with AMD, 10.5 Gflop and 24.0M with ``metis``, the solver's M_red 15.9
  against 10.5 Gflop), while on the 2D datasets (up to 15,115 poses) and 3D graphs up to a few
  thousand poses AMD is as good and its analysis is cheaper. The Laplacians of ``lb`` always use
  AMD (their factors are cheap whatever the ordering; nested dissection's analysis costs more
  than it saves).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from sksparse.cholmod import analyze

from ..core.choices import ORDERINGS
from ..core.errors import UsageError
from .accuracy import LogdetAccuracy, logdet_accuracy
from .cholesky import Factor, PermutedFactor, SymbolicCholesky

POSE_LEVEL = ("metis", "nesdis")
MATRICES = ("lb", "ub", "fim", "crlb", "solver")
# 3D graphs from this many poses on get nested dissection under ``auto``: on the SE-Sync 3D
# datasets (1,661-5,750 poses) and a 3D grid of 5,832 poses AMD's factorization is as fast or
# faster once nested dissection's extra ordering work is counted, on 3D grids of 10,648 and
# 21,952 poses nested dissection is clearly faster (docs/decisions/orderings.md).
AUTO_ND_MIN_POSES = 10000
# 2D graphs from this many poses on (2D grids: 30,276 poses M_red 2.0 Gflop AMD against 1.5
# metis, 100,489 poses 15.9 against 10.5; the 2D datasets, up to 15,115 poses, gain nothing;
# docs/decisions/orderings.md).
AUTO_ND_MIN_POSES_2D = 50000
# The nested dissection ``auto`` uses: METIS on the pose graph (fewest flops on the 3D grids, the
# same as nesdis on 2D grids and on M_red; both are deterministic).
AUTO_ND_METHOD = "metis"


@dataclass(frozen=True, kw_only=True)
class OrderingChoice:
    """The ordering used for one factorization: ``requested`` (what the user asked, possibly
    ``auto``), ``method`` (amd | colamd | metis | nesdis) and whether it was computed on the pose
    graph and expanded to each pose's rows (``pose_level``)."""

    requested: str
    method: str
    pose_level: bool

    def __str__(self) -> str:
        return f"{self.method} (pose graph)" if self.pose_level else self.method


def check_ordering(ordering: str) -> str:
    if ordering not in ORDERINGS:
        raise UsageError(f"ordering must be one of {', '.join(ORDERINGS)}, got {ordering!r}")
    return ordering


def auto_ordering(dim: int, poses: int, matrix: str) -> str:
    """The method ``auto`` picks for ``matrix`` (one of ``MATRICES``) of a graph with ``poses``
    poses in dimension ``dim``: ``AUTO_ND_METHOD`` for the block matrices of 3D graphs with at
    least ``AUTO_ND_MIN_POSES`` poses and of 2D graphs with at least ``AUTO_ND_MIN_POSES_2D``,
    ``amd`` otherwise (module docstring)."""
    if matrix not in MATRICES:
        raise UsageError(f"matrix must be one of {MATRICES}, got {matrix!r}")
    large = poses >= (AUTO_ND_MIN_POSES if dim == 3 else AUTO_ND_MIN_POSES_2D)
    if matrix != "lb" and large:
        return AUTO_ND_METHOD
    return "amd"


def threaded_matrix(dim: int, poses: int, matrix: str) -> bool:
    """Whether ``matrix`` of a graph is factored with CHOLMOD's BLAS on its threads (those of the
    cores no other process keeps busy, posecrb.linalg.threads): the block matrices of the graphs
    ``auto_ordering`` takes as large (3D from ``AUTO_ND_MIN_POSES`` poses, 2D from
    ``AUTO_ND_MIN_POSES_2D``), whose nested-dissection separators are dense blocks of a thousand
    rows and more, where a second thread pays (docs/decisions/blas-threads.md)."""
    if matrix not in MATRICES:
        raise UsageError(f"matrix must be one of {MATRICES}, got {matrix!r}")
    return matrix != "lb" and poses >= (AUTO_ND_MIN_POSES if dim == 3 else AUTO_ND_MIN_POSES_2D)


def resolve_ordering(ordering: str, *, dim: int, poses: int, matrix: str) -> OrderingChoice:
    """``ordering`` (``ORDERINGS``) made concrete for one matrix of a graph."""
    check_ordering(ordering)
    method = auto_ordering(dim, poses, matrix) if ordering == "auto" else ordering
    return OrderingChoice(requested=ordering, method=method, pose_level=method in POSE_LEVEL)


def colamd_permutation(a: sp.spmatrix) -> np.ndarray:
    """COLAMD column ordering of ``a`` (as MATLAB's ``colamd(a)``), by CHOLMOD's COLAMD on
    ``a a^T`` (module docstring): a permutation of ``range(a.shape[0])``."""
    from sksparse.cholmod import analyze_AAt  # noqa: PLC0415 -- CHOLMOD only where it factors

    pat = sp.csc_matrix(a, dtype=np.float64)
    return np.asarray(analyze_AAt(pat, ordering_method="colamd").P(), dtype=np.int64)


def pose_permutation(pose_adjacency: sp.spmatrix, method: str) -> np.ndarray:
    """CHOLMOD's ``method`` ordering of the pose graph (the pattern of ``pose_adjacency``,
    e.g. a reduced Laplacian), one entry per pose."""
    if method == "colamd":
        return colamd_permutation(pose_adjacency)
    if method not in ("amd", "metis", "nesdis"):
        raise UsageError(f"pose-graph ordering must be amd, colamd, metis or nesdis, got {method!r}")
    pat = sp.csc_matrix(pose_adjacency, dtype=np.float64)
    pat = sp.csc_matrix((np.ones(pat.nnz), pat.indices, pat.indptr), shape=pat.shape)
    # the symbolic analysis needs a diagonal; the pattern is all that is analysed
    pat = (pat + sp.identity(pat.shape[0], format="csc")).tocsc()
    return np.asarray(analyze(pat, ordering_method=method).P(), dtype=np.int64)


def expand_permutation(pose_perm: np.ndarray, pose_of_row: np.ndarray) -> np.ndarray:
    """Rows ordered pose by pose in the order ``pose_perm`` (rows of one pose keep their
    relative order). ``pose_of_row[k]`` is the pose (0..n_p-1) that row k belongs to."""
    rank = np.empty(pose_perm.size, dtype=np.int64)
    rank[pose_perm] = np.arange(pose_perm.size)
    return np.argsort(rank[np.asarray(pose_of_row)], kind="stable").astype(np.int64)


def pose_block_permutation(pose_adjacency: sp.spmatrix, block_size: int, method: str) -> np.ndarray:
    """The pose graph's ``method`` ordering expanded to a pose-major matrix with ``block_size``
    rows per pose (rows ``k * block_size .. k * block_size + block_size - 1`` belong to pose k)."""
    p = pose_permutation(pose_adjacency, method)
    return (p[:, None] * block_size + np.arange(block_size)[None, :]).ravel()


def pose_adjacency_of(a: sp.spmatrix, pose_of_row: np.ndarray, n_poses: int) -> sp.csc_matrix:
    """Pattern of the pose graph of a matrix whose rows belong to poses (``pose_of_row``):
    poses i and j are adjacent when some entry couples a row of i with a row of j.

    Read from the compressed columns directly: an entry whose (row pose, column pose) repeats the
    entry before it (the rows of one pose lie next to each other in a column of a pose-major
    matrix) is left out before the pairs are sorted, so the sort sees a fraction of the entries."""
    a = sp.csc_matrix(a) if not sp.isspmatrix_csc(a) else a
    pr = np.asarray(pose_of_row, dtype=np.int64)
    rows = pr[a.indices]
    cols = np.repeat(pr, np.diff(a.indptr))
    new = np.ones(rows.size, dtype=bool)
    new[1:] = (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])
    m = sp.csc_matrix((np.ones(int(new.sum())), (rows[new], cols[new])), shape=(n_poses, n_poses))
    m.sum_duplicates()
    return m


def ordered_symbolic(a: sp.spmatrix, ordering: str, *, dim: int, poses: int, matrix: str,
                     pose_of_row: np.ndarray | None = None, n_poses: int | None = None,
                     pose_adjacency: sp.spmatrix | None = None, pose_order: np.ndarray | None = None,
                     mode: str = "auto") -> tuple[SymbolicCholesky, OrderingChoice]:
    """A ``SymbolicCholesky`` of ``a`` with ``ordering`` (``ORDERINGS``) and the choice made.

    ``pose_of_row`` (default: one row per pose) maps rows to poses 0..n_poses-1; the pose graph is
    ``pose_adjacency`` when given (e.g. the reduced Laplacian lb already built), otherwise it is
    read from ``a``'s own pattern. ``auto`` decides from ``dim``, the graph's pose count ``poses``
    and ``matrix``. ``pose_order``: the pose graph's ordering when the caller already has it (from
    ``pose_permutation`` with the method ``ordering`` resolves to), so that matrices of one graph
    share it instead of ordering the pose graph again."""

    rows = a.shape[0]
    if pose_of_row is None:
        pose_of_row = np.arange(rows)
        n_poses = rows
    n_poses = int(n_poses if n_poses is not None else (int(np.max(pose_of_row)) + 1 if rows else 0))
    choice = resolve_ordering(ordering, dim=dim, poses=poses, matrix=matrix)
    threaded = threaded_matrix(dim, poses, matrix)
    if rows == 0 or choice.method == "amd":
        return SymbolicCholesky(a, mode=mode, ordering_method="amd", threaded=threaded), choice
    if choice.method == "colamd":
        return SymbolicCholesky(a, mode=mode, permutation=colamd_permutation(a), threaded=threaded), choice
    if n_poses == rows and pose_adjacency is None:
        return SymbolicCholesky(a, mode=mode, ordering_method=choice.method, threaded=threaded), choice
    if pose_order is None:
        adj = pose_adjacency if pose_adjacency is not None else pose_adjacency_of(a, pose_of_row, n_poses)
        pose_order = pose_permutation(adj, choice.method)
    perm = expand_permutation(pose_order, pose_of_row)
    return SymbolicCholesky(a, mode=mode, permutation=perm, threaded=threaded), choice


def block_cholesky(a: sp.spmatrix, ordering: str, *, dim: int, poses: int, matrix: str, block: int,
                   name: str = "matrix") -> Factor | PermutedFactor:
    """Cholesky factor of a pose-major matrix (``block`` rows per pose) with ``ordering``;
    raises NotPositiveDefinite as ``posecrb.linalg.cholesky`` does."""
    nb = a.shape[0] // block
    sym, _ = ordered_symbolic(a, ordering, dim=dim, poses=poses, matrix=matrix,
                              pose_of_row=np.repeat(np.arange(nb), block), n_poses=nb)
    return sym.factor(a, name=name)


def anchored_logdet(matrix: sp.spmatrix, q: int, anchors: list[int], name: str, *, ordering: str = "auto",
                    dim: int | None = None) -> float:
    """log det of a pose-major (q per pose) FIM with the anchored poses' rows/columns removed,
    factored with ``ordering`` (``dim`` defaults from q = 3 | 6); raises NotPositiveDefinite."""
    return anchored_logdet_accuracy(matrix, q, anchors, name, ordering=ordering, dim=dim, accuracy=False)[0]


def anchored_logdet_accuracy(matrix: sp.spmatrix, q: int, anchors: list[int], name: str, *,
                             ordering: str = "auto", dim: int | None = None,
                             accuracy: bool = True) -> tuple[float, LogdetAccuracy | None]:
    """``anchored_logdet`` and, with ``accuracy``, its ``posecrb.linalg.accuracy.logdet_accuracy``
    (from the same factor: no second factorization)."""
    n = matrix.shape[0] // q
    keep = np.ones(n, bool)
    keep[anchors] = False
    dofs = (np.flatnonzero(keep)[:, None] * q + np.arange(q)).ravel()
    a = matrix[dofs][:, dofs].tocsc()
    if a.shape[0] == 0:
        return 0.0, (logdet_accuracy(None, 0.0, name) if accuracy else None)
    nb = a.shape[0] // q
    sym, _ = ordered_symbolic(a, ordering, dim=dim or (2 if q == 3 else 3), poses=n, matrix="fim",
                              pose_of_row=np.repeat(np.arange(nb), q), n_poses=nb)
    factor, ld = sym.factor_logdet(a, name=name)
    return ld, (logdet_accuracy(factor, ld, name, matrix=a, overwrite_factor=True) if accuracy else None)


def solver_symbolic(pattern: sp.spmatrix, dim: int, n: int, mode: str = "auto",
                    pose_of_row: np.ndarray | None = None,
                    pose_order: np.ndarray | None = None) -> SymbolicCholesky:
    """The symbolic analysis of a solver matrix: by default M_red = [[L_red, V_red], [V_red^T, C + ...]]
    (posecrb.solver.problem: n - 1 translation rows for poses 1..n-1, then d rotation rows per pose
    0..n-1), or any matrix whose rows belong to poses as ``pose_of_row`` says (the chordal
    initialisation's connection Laplacian); ``pose_order``: the pose graph's ordering, when the
    caller computed it once for several matrices (``ordered_symbolic``).
    Under ``auto``'s rule for large graphs (``auto_ordering``): nested dissection of the
    pose graph expanded to each pose's rows (docs/decisions/orderings.md: M_red's factorization
    faster than with CHOLMOD's default choice on a 3D grid of 21,952 poses; 10.5 instead of 15.9
    Gflop and 24.0M instead of 29.8M nonzeros on a 2D grid of 100,489 poses); otherwise CHOLMOD's
    default ordering, as before. ``mode``: CHOLMOD's factorization kind
    (auto | simplicial | supernodal; the solver picks it, posecrb.solver.problem)."""

    method = auto_ordering(dim, n, "solver")
    if method == "amd" or n < 2:
        return SymbolicCholesky(pattern, mode=mode)
    if pose_of_row is None:
        pose_of_row = np.concatenate([np.arange(1, n), np.repeat(np.arange(n), dim)])
    return ordered_symbolic(pattern, method, dim=dim, poses=n, matrix="solver", pose_of_row=pose_of_row,
                            n_poses=n, pose_order=pose_order, mode=mode)[0]
