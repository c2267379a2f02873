"""SE-Sync data matrices built from a PoseGraph, and the reduced objective applied as an operator.

Notation (Rosen et al., SE-Sync, IJRR 2019, section 4; docs/design.md#solver). With
``X = [t R]`` (d x (n + dn)) the maximum-likelihood objective is

    F(t, R) = sum_e kappa_e ||R_j - R_i R~_e||_F^2 + tau_e ||t_j - t_i - R_i t~_e||^2
            = tr(M X^T X),   M = [[L(W^tau), V], [V^T, L(G^rho) + Sigma]],

(no factor 1/2, SE-Sync's convention; the second equality needs orthogonal R~, see below).
Eliminating the translations in closed form gives ``F*(R) = tr(Q R^T R)`` with the Schur complement

    Q = L(G^rho) + Sigma - V^T L(W^tau)^+ V.

Rotation term, exactly as SE-Sync's data matrix defines it: ``L(G^rho)`` has ``kappa I_d`` on
both diagonal blocks of an edge and ``-kappa R~`` off the diagonal, so its edge term is

    kappa (||R_i||_F^2 + ||R_j||_F^2 - 2 tr(R_j^T R_i R~))
        = kappa ||R_j - R_i R~||_F^2 + kappa tr(R_i (I - R~ R~^T) R_i^T).

For an orthogonal R~ the last term vanishes and this is the usual chordal residual. A
measured R~ that is NOT orthogonal (SE-Sync builds 3D measurements from unnormalised
quaternions; ``load(..., quaternions="raw")``) keeps it: on SO(d)^n or St(d, r)^n it is the
constant ``kappa tr(I - R~ R~^T)``, which leaves the minimisers and the Riemannian gradient
alone but makes the objective value SE-Sync's ``tr(M X^T X)``. The objective is summed in the
right-hand form: the residual is computed directly and the defect term is small, so nothing
cancels (the left-hand form would lose ``eps * 2d kappa`` per edge to cancellation).

Q is dense, so it is never formed: ``Q Z = C Z - V^T L_red^{-1} V_red Z`` uses one
CHOLMOD factor of the anchored translation Laplacian ``L_red``. Everything here works
in the "row" layout: a point of St(d, r)^n is ``Z = Y^T`` of shape (dn, r) whose
i-th d x r block is ``Z_i = Y_i^T`` (so for a rotation estimate, ``Z_i = R_i^T``).

The same Schur-complement identity gives cheap inverses: the rotation block of
``M_red(s)^{-1}`` with ``M_red(s) = [[L_red, V_red], [V_red^T, C - Lambda + s I]]`` is
``(Q - Lambda + s I)^{-1}``. M_red(s) is SPARSE, so both the trust-region
preconditioner (Lambda = 0) and the certificate test ``Q - Lambda + eta I > 0``
(one sparse Cholesky, SE-Sync's first verification step) never see a dense matrix.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from sksparse.cholmod import Factor

from ..core.errors import InternalError
from ..core.graph import PoseGraph
from ..linalg.cholesky import SymbolicCholesky, cholesky, solve_tail
from ..linalg.laplacian import reduced_laplacian
from ..linalg.ordering import auto_ordering, pose_permutation, solver_symbolic
from ..linalg.threads import factorization_threads, solve_threads

# CHOLMOD's simplicial factorization for the solver's block matrices (M_red, the chordal
# initialisation's connection Laplacian) when the pose-level fill is low: ``b * sum c_j^2 / sum c_j``
# below this, with c_j the column counts of the translation Laplacian's factor (one row per pose)
# and b the rows per pose of the matrix factored. That quotient estimates the factorization's
# flops per factor entry, CHOLMOD's own supernodal criterion (its switch, 40, is tuned for the
# factorization alone). Here a solve is one process: a handful of factorizations, each serving
# tens to hundreds of triangular solves with r <= 5 right-hand sides. Kernel by kernel after a
# warm-up the supernodal factorization is the cheaper one from fill 150 on, but the whole first
# solve of a fresh process, which is what a user runs, is faster simplicial up to fill ~170
# (cubicle 152, the 2D grid of 10,000 poses 157, sphere2500 168) and slower from ~220 on
# (sphere_bignoise 226, torus3D 232: supernodal kept), so the switch sits between
# (docs/decisions/solver-preconditioners.md). The 2D 10^5-pose grid (fill 400) and the 3D grids
# (>= 271) are above.
SIMPLICIAL_MAX_FLOPS_PER_ENTRY = 200.0

# CHOLMOD's default supernodal switch (Common->supernodal_switch): with its automatic choice, a
# factor whose flops per entry reach this is supernodal.
CHOLMOD_SUPERNODAL_SWITCH = 40.0

# An edge's R~ counts as orthogonal when max |I - R~ R~^T| is at the rounding level of a
# rotation computed in floating point (normalised quaternions measure up to ~10 eps on the
# shared datasets); its defect term is then dropped, so orthogonal data give exactly the
# residual-form objective.
ORTHOGONALITY_TOL = 64 * np.finfo(float).eps


def orthogonality_defect(rot: np.ndarray, tol: float = ORTHOGONALITY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """(edges, E) with ``E_e = I - R~_e R~_e^T`` for the edges whose R~ is not orthogonal within ``tol``."""
    d = rot.shape[-1]
    E = np.eye(d) - rot @ np.swapaxes(rot, 1, 2)
    edges = np.flatnonzero(np.abs(E).max(axis=(1, 2)) > tol)
    return edges, np.ascontiguousarray(E[edges])


def connection_laplacian(n: int, d: int, src: np.ndarray, dst: np.ndarray, rot: np.ndarray,
                         kappa: np.ndarray) -> sp.csr_matrix:
    """L(G^rho) (dn x dn): diagonal blocks sum kappa I_d, block (i, j) = -kappa R~_ij, (j, i) its transpose.

    ``tr(L(G^rho) Z Z^T) = sum kappa ||R_j - R_i R~_ij||_F^2`` for ``Z_i = R_i^T``.
    """
    a, b = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")           # (d, d) row/col offsets
    off_r = (src[:, None, None] * d + a).ravel()
    off_c = (dst[:, None, None] * d + b).ravel()
    off_v = -(kappa[:, None, None] * rot).ravel()
    diag_nodes = np.concatenate([src, dst])
    diag_r = (diag_nodes[:, None] * d + np.arange(d)).ravel()
    diag_v = np.repeat(np.concatenate([kappa, kappa]), d)
    rows = np.concatenate([off_r, off_c, diag_r])
    cols = np.concatenate([off_c, off_r, diag_r])
    vals = np.concatenate([off_v, off_v, diag_v])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n * d, n * d))


def _factor_kind(rows_per_pose: int, fill: float) -> str:
    """CHOLMOD's factorization kind for a solver matrix with ``rows_per_pose`` rows per pose of a
    graph of pose-level fill ``fill`` (``SIMPLICIAL_MAX_FLOPS_PER_ENTRY``)."""
    return "simplicial" if rows_per_pose * fill < SIMPLICIAL_MAX_FLOPS_PER_ENTRY else "supernodal"


def _column_fill(factor: Factor) -> float:
    """``sum c_j^2 / sum c_j`` over the column counts c_j of a factor. LD() is the simplicial LDL'
    factor's own storage; a supernodal factor is converted in place to a simplicial one with the
    supernodes' pattern, padding included (the measure the thresholds above were set with)."""
    counts = np.diff(factor.LD().indptr).astype(float)
    return float(np.dot(counts, counts) / max(counts.sum(), 1.0))


@dataclass(frozen=True, eq=False)
class RotationBlockFactor:
    """A Cholesky factor of ``C + s I``, the rotation block of M (``C = L(G^rho) + Sigma``, dn x dn)
    without the translations' coupling: ``C + s I = Q + s I + V^T L(W^tau)^+ V >= Q + s I``.

    The solver's base preconditioner of large 3D graphs (posecrb.solver.preconditioners,
    ``PreconditionerSettings.base``): d rows per pose instead of M_red's d + 1, so on graphs with
    dense separators its factorization takes about (d / (d + 1))^3 of M_red's flops and each solve
    reads a smaller factor (docs/decisions/solver-preconditioners.md). ``threaded``: its solves
    share CHOLMOD's BLAS threads, as the factorizations of such graphs do.
    """

    factor: Factor
    shift: float
    threaded: bool

    def solve(self, W: np.ndarray) -> np.ndarray:
        """``(C + s I)^{-1} W`` for W of shape (dn, k)."""
        with solve_threads() if self.threaded else contextlib.nullcontext():
            return np.asarray(self.factor(np.asarray(W, dtype=float)))


@dataclass
class Problem:
    """Sparse data of one pose graph in SE-Sync's simplified (translation-eliminated) form."""

    graph: PoseGraph
    n: int
    d: int
    conlap: sp.csr_matrix          # L(G^rho), dn x dn
    C: sp.csr_matrix               # L(G^rho) + Sigma
    V: sp.csr_matrix               # n x dn translational coupling
    Vred: sp.csr_matrix            # V without the translation anchor's row
    VredT: sp.csr_matrix
    Lred: sp.csc_matrix            # reduced translation Laplacian L(W^tau)
    Lfactor: Factor
    tau: np.ndarray
    kappa: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    rot: np.ndarray                # (m, d, d) R~
    rotT: np.ndarray               # (m, d, d) R~^T
    trans: np.ndarray              # (m, d) t~
    defect_edges: np.ndarray       # edges whose R~ is not orthogonal (see module docstring)
    defect: np.ndarray             # (k, d, d) I - R~ R~^T on those edges
    _full_symbolic: SymbolicCholesky | None = field(default=None, repr=False)
    _full_pattern: sp.csc_matrix | None = field(default=None, repr=False)
    _full_base: np.ndarray | None = field(default=None, repr=False)
    _full_diag_pos: np.ndarray | None = field(default=None, repr=False)
    _full_lam_pos: np.ndarray | None = field(default=None, repr=False)
    _fill: float | None = field(default=None, repr=False)
    _pose_order: np.ndarray | None = field(default=None, repr=False)
    _defect_const: float | None = field(default=None, repr=False)
    # C and V_red^T in CSC for the products Q Z (every Hessian-vector product): scipy's CSC
    # kernel multiplies these by an (nd, r) block faster than the CSR kernel
    # (docs/decisions/solver-preconditioners.md).
    _C_csc: sp.csc_matrix | None = field(default=None, repr=False)
    _VredT_csc: sp.csc_matrix | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self._C_csc = self.C.tocsc()
        self._VredT_csc = self.Vred.T.tocsc()

    # ---- construction ------------------------------------------------------
    @classmethod
    def from_graph(cls, graph: PoseGraph) -> Problem:
        n, d = graph.n, graph.dim
        src, dst = np.asarray(graph.src, np.int64), np.asarray(graph.dst, np.int64)
        tau = np.asarray(graph.tau, float)
        kappa = np.asarray(graph.kappa, float)
        rot = np.asarray(graph.rot, float)
        tt = np.asarray(graph.trans, float)
        conlap = connection_laplacian(n, d, src, dst, rot, kappa)
        # Sigma: block i += tau t~ t~^T over edges leaving i.
        a, b = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
        sr = (src[:, None, None] * d + a).ravel()
        sc = (src[:, None, None] * d + b).ravel()
        sv = (tau[:, None, None] * tt[:, :, None] * tt[:, None, :]).ravel()
        sigma = sp.csr_matrix((sv, (sr, sc)), shape=(n * d, n * d))
        # V = sum_e tau (e_j - e_i)(-E_i t~)^T: row j gets -tau t~^T, row i +tau t~^T, in block i.
        cols = (src[:, None] * d + np.arange(d)).ravel()
        vv = (tau[:, None] * tt).ravel()
        V = sp.csr_matrix(
            (np.concatenate([-vv, vv]), (np.concatenate([np.repeat(dst, d), np.repeat(src, d)]),
                                        np.concatenate([cols, cols]))), shape=(n, n * d))
        Lred = reduced_laplacian(n, src, dst, tau, anchor=0)
        name = "reduced translation Laplacian L(W^tau)"
        Lfactor = cholesky(Lred, name=name)
        fill = _column_fill(Lfactor) if n > 1 else 1.0
        if fill >= CHOLMOD_SUPERNODAL_SWITCH and _factor_kind(1, fill) == "simplicial":
            # CHOLMOD factored L(W^tau) supernodal, and reading its column counts converted it to a
            # simplicial factor with the supernodes' padding (1.4-1.7x the entries). This factor
            # serves a solve per Hessian-vector product: a simplicial factorization of its own
            # solves faster, without the padding, for one more factorization of a one-row-per-pose
            # matrix (docs/decisions/solver-preconditioners.md).
            Lfactor = SymbolicCholesky(Lred, mode="simplicial").factor(Lred, name=name)
        Vred = V[1:].tocsr()
        defect_edges, defect = orthogonality_defect(rot)
        return cls(graph=graph, n=n, d=d, conlap=conlap, C=(conlap + sigma).tocsr(), V=V,
                   Vred=Vred, VredT=Vred.T.tocsr(), Lred=Lred, Lfactor=Lfactor, tau=tau, kappa=kappa,
                   src=src, dst=dst, rot=rot, rotT=np.ascontiguousarray(np.swapaxes(rot, 1, 2)), trans=tt,
                   defect_edges=defect_edges, defect=defect, _fill=fill)

    def pose_fill(self) -> float:
        """``sum c_j^2 / sum c_j`` over the column counts c_j of CHOLMOD's first factor of L(W^tau)
        (computed once, in :meth:`from_graph`): the flops per factor entry of a one-row-per-pose
        factorization of the pose graph."""
        if self._fill is None:  # set by from_graph
            raise InternalError("pose fill not measured")
        return self._fill

    def factor_mode(self, rows_per_pose: int) -> str:
        """CHOLMOD mode for a solver matrix with ``rows_per_pose`` rows per pose
        (``SIMPLICIAL_MAX_FLOPS_PER_ENTRY``): "simplicial" or "supernodal"."""
        return _factor_kind(rows_per_pose, self.pose_fill())

    def pose_order(self) -> np.ndarray | None:
        """The pose graph's fill-reducing ordering for the solver's matrices under ``auto``'s rule
        (nested dissection on large graphs, posecrb.linalg.ordering.auto_ordering), computed once
        and shared by the analyses of the chordal initialisation's connection Laplacian and of
        M_red; None where ``auto`` keeps CHOLMOD's own ordering."""
        method = auto_ordering(self.d, self.n, "solver")
        if method == "amd" or self.n < 2:
            return None
        if self._pose_order is None:
            edges = sp.csc_matrix((np.ones(self.src.size), (self.src, self.dst)), shape=(self.n, self.n))
            self._pose_order = pose_permutation(edges + edges.T, method)
        return self._pose_order

    # ---- the objective -----------------------------------------------------
    def translations(self, Z: np.ndarray) -> np.ndarray:
        """Optimal relaxed translations (n, r) for Z (dn, r); pose 0's is zero: L p = -V Z."""
        rhs = -(self.Vred @ Z)
        p = np.zeros((self.n, Z.shape[1]))
        p[1:] = self.Lfactor(rhs)
        return p

    def Q_product(self, Z: np.ndarray) -> np.ndarray:
        """Q Z for Z of shape (dn, k), through the L(W^tau) factor (never forming Q)."""
        w = self.Lfactor(self.Vred @ Z)
        return self._C_csc @ Z - self._VredT_csc @ w

    def Q_product_and_translations(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = self.Lfactor(self.Vred @ Z)
        p = np.zeros((self.n, Z.shape[1]))
        p[1:] = -w
        return self._C_csc @ Z - self._VredT_csc @ w, p

    def objective_from_translations(self, Z: np.ndarray, p: np.ndarray) -> float:
        """F(Y, p) = tr(X^T M X) summed edge by edge (no cancellation between the large terms of
        tr(Z^T Q Z)); the rotation term in the residual + defect form of the module docstring.
        Z is a point of St(d, r)^n (its defect term is then :meth:`defect_constant`)."""
        n, d = self.n, self.d
        Zb = Z.reshape(n, d, -1)
        # np.take along the first axis gathers the same rows as fancy indexing, several times
        # faster for these (m, d, r) and (m, r) gathers (docs/decisions/solver-preconditioners.md)
        Zi = np.take(Zb, self.src, axis=0)
        # rotation residual, transposed: Z_j - R~^T Z_i  (d x r)
        rr = np.take(Zb, self.dst, axis=0) - self.rotT @ Zi
        # translation residual: p_j - p_i - Z_i^T t~  (r,)
        tr = np.take(p, self.dst, axis=0) - np.take(p, self.src, axis=0) - np.einsum("ea,ear->er", self.trans, Zi)
        f = float(np.dot(self.kappa, np.einsum("eab,eab->e", rr, rr))
                  + np.dot(self.tau, np.einsum("er,er->e", tr, tr)))
        return f + self.defect_constant()

    def defect_constant(self) -> float:
        """The defect term at any point of St(d, r)^n: with Z_i Z_i^T = I_d,
        ``tr(Z_i^T E Z_i) = tr(E Z_i Z_i^T) = tr(E)``, so it is ``sum kappa tr(I - R~ R~^T)``
        (computed once; the per-edge sum cost a tenth of an objective evaluation on 3D raw data)."""
        if self._defect_const is None:
            self._defect_const = float(np.dot(self.kappa[self.defect_edges],
                                              np.trace(self.defect, axis1=1, axis2=2)))
        return self._defect_const

    def defect_term(self, Zi: np.ndarray) -> float:
        """sum kappa tr(Z_i^T (I - R~ R~^T) Z_i) over the non-orthogonal edges (Zi: their (k, d, r) source blocks)."""
        if self.defect_edges.size == 0:
            return 0.0
        return float(np.dot(self.kappa[self.defect_edges], np.einsum("kab,kar,kbr->k", self.defect, Zi, Zi)))

    def objective(self, Z: np.ndarray) -> float:
        return self.objective_from_translations(Z, self.translations(Z))

    # ---- full sparse (translations kept) matrix: preconditioner and certificate --------
    def _full_parts(self) -> None:
        """Pattern, symbolic analysis and value map of M_red(s), computed once per problem.

        Every M_red(Lambda, s) has the pattern of ``[[L_red, V_red], [V_red^T, C + blockdiag]]``;
        its values are ``base + s (lower diagonal) - Lambda (lower block diagonal)``, so each
        factorization only writes O(nnz) numbers into a fixed CSC layout instead of assembling
        sparse matrices (scipy's construction overhead dominated small problems).
        """
        if self._full_symbolic is not None:
            return
        n, d = self.n, self.d
        dn = n * d
        N = n - 1 + dn
        # Block-diagonal d x d pattern of the rotation block (Lambda lives there).
        i = np.arange(n)
        a, b = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
        rr = (i[:, None, None] * d + a).ravel() + (n - 1)
        cc = (i[:, None, None] * d + b).ravel() + (n - 1)
        # [[L_red, V_red], [V_red^T, C]] as one COO list (scipy's bmat costs more than the rest
        # of a small problem's set-up); with the block diagonal it gives the analysed pattern.
        blocks = [(self.Lred.tocoo(), 0, 0), (self.Vred.tocoo(), 0, n - 1), (self.VredT.tocoo(), n - 1, 0),
                  (self.C.tocoo(), n - 1, n - 1)]
        brow = np.concatenate([blk.row.astype(np.int64) + r0 for blk, r0, _ in blocks] + [rr])
        bcol = np.concatenate([blk.col.astype(np.int64) + c0 for blk, _, c0 in blocks] + [cc])
        bval = np.concatenate([blk.data for blk, _, _ in blocks] + [np.zeros(rr.size)])
        # scipy sums duplicates (the block diagonal's explicit zeros onto C's diagonal blocks) and
        # keeps explicit zeros: the values of [[L_red, V_red], [V_red^T, C]] on the analysed pattern.
        pattern = sp.csc_matrix((bval, (brow, bcol)), shape=(N, N))
        pattern.sum_duplicates()
        pattern.sort_indices()
        # Only the diagonal and the block diagonal are rewritten per factorization: locate them.
        keys = np.repeat(np.arange(N, dtype=np.int64), np.diff(pattern.indptr)) * N + pattern.indices

        def positions(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
            k = cols.astype(np.int64) * N + rows
            pos = np.searchsorted(keys, k)
            if not np.array_equal(keys[np.minimum(pos, keys.size - 1)], k):
                raise InternalError("entry outside the analysed pattern")
            return pos

        self._full_base = pattern.data.copy()
        diag = np.arange(n - 1, N)
        self._full_diag_pos = positions(diag, diag)
        self._full_lam_pos = positions(rr, cc)
        self._full_pattern = pattern
        # pose-level nested dissection on large graphs; simplicial or supernodal by the fill (factor_mode)
        self._full_symbolic = solver_symbolic(pattern, d, n, mode=self.factor_mode(d + 1),
                                              pose_order=self.pose_order())

    def full_matrix(self, lam_blocks: np.ndarray | None, shift: float) -> sp.csc_matrix:
        """M_red(s) = [[L_red, V_red], [V_red^T, C - Lambda + s I]] (sparse, (n-1+dn) square)."""
        self._full_parts()
        if self._full_base is None or self._full_pattern is None:  # set by _full_parts
            raise InternalError("M_red: pattern not analysed")
        data = self._full_base.copy()
        data[self._full_diag_pos] += shift
        if lam_blocks is not None:
            data[self._full_lam_pos] -= lam_blocks.ravel()
        P = self._full_pattern
        M = sp.csc_matrix((data, P.indices, P.indptr), shape=P.shape, copy=False)
        M.has_sorted_indices = True
        return M

    def factor_full(self, lam_blocks: np.ndarray | None, shift: float, name: str) -> Factor:
        """Cholesky of M_red(shift) with the shared symbolic analysis; raises NotPositiveDefinite."""
        self._full_parts()
        if self._full_symbolic is None:  # set by _full_parts
            raise InternalError("M_red: pattern not analysed")
        with factorization_threads():
            return self._full_symbolic.factor(self.full_matrix(lam_blocks, shift), name=name)

    def factor_rotation_block(self, shift: float, name: str) -> RotationBlockFactor:
        """Cholesky of ``C + shift I`` (:class:`RotationBlockFactor`) with the pose graph's ordering
        that M_red and the chordal initialisation share (``pose_order``); raises NotPositiveDefinite."""
        n, d = self.n, self.d
        C = (self._C_csc + shift * sp.identity(n * d, format="csc")).tocsc()
        C.sort_indices()
        symbolic = solver_symbolic(C, d, n, mode=self.factor_mode(d), pose_of_row=np.repeat(np.arange(n), d),
                                   pose_order=self.pose_order())
        with factorization_threads():
            factor = symbolic.factor(C, name=name)
        return RotationBlockFactor(factor, float(shift), symbolic.threaded)

    def schur_solve(self, factor: Factor, W: np.ndarray) -> np.ndarray:
        """(Q - Lambda + s I)^{-1} W, the rotation block of M_red(s)^{-1} [0; W]. For a large 3D graph
        (one whose factorizations take CHOLMOD's threads, ``SymbolicCholesky.threaded``) CHOLMOD's
        BLAS shares the solve's dense triangles out over the cores other processes leave free
        (``solve_threads``): on large 3D graphs the top separators are dense triangles of thousands
        of rows, which two threads share; 2D graphs' separators are a few hundred rows, where a second
        thread only spins, so they keep one (docs/decisions/solver-preconditioners.md)."""
        threaded = self.d == 3 and self._full_symbolic is not None and self._full_symbolic.threaded
        with solve_threads() if threaded else contextlib.nullcontext():
            return solve_tail(factor, self.n - 1, W)

    def gershgorin_max(self) -> float:
        """Upper bound on lambda_max(Q) <= lambda_max(C) (Q = C - PSD term)."""
        return float(np.max(np.asarray(abs(self.C).sum(axis=1)).ravel()))
