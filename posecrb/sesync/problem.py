"""SE-Sync data matrices built from a PoseGraph, and the reduced objective applied as an operator.

Notation (Rosen et al., SE-Sync, IJRR 2019, section 4; DESIGN.md section 6). With
``X = [t R]`` (d x (n + dn)) the maximum-likelihood objective is

    F(t, R) = sum_e kappa_e ||R_j - R_i R~_e||_F^2 + tau_e ||t_j - t_i - R_i t~_e||^2
            = tr(M X^T X),   M = [[L(W^tau), V], [V^T, L(G^rho) + Sigma]],

(no factor 1/2, SE-Sync's convention). Eliminating the translations in closed form
gives ``F*(R) = tr(Q R^T R)`` with the Schur complement

    Q = L(G^rho) + Sigma - V^T L(W^tau)^+ V.

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

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from sksparse.cholmod import Factor

from ..graph import PoseGraph
from ..laplacian import reduced_laplacian
from ..linalg import SymbolicCholesky, cholesky


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
    _full_symbolic: SymbolicCholesky | None = field(default=None, repr=False)
    _full_pattern: sp.csc_matrix | None = field(default=None, repr=False)
    _blockdiag_index: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    # ---- construction ------------------------------------------------------
    @classmethod
    def from_graph(cls, graph: PoseGraph) -> "Problem":
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
        Lfactor = cholesky(Lred, name="reduced translation Laplacian L(W^tau)")
        Vred = V[1:].tocsr()
        return cls(graph=graph, n=n, d=d, conlap=conlap, C=(conlap + sigma).tocsr(), V=V,
                   Vred=Vred, VredT=Vred.T.tocsr(), Lred=Lred, Lfactor=Lfactor, tau=tau, kappa=kappa,
                   src=src, dst=dst, rot=rot, rotT=np.ascontiguousarray(np.swapaxes(rot, 1, 2)), trans=tt)

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
        return self.C @ Z - self.VredT @ w

    def Q_product_and_translations(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = self.Lfactor(self.Vred @ Z)
        p = np.zeros((self.n, Z.shape[1]))
        p[1:] = -w
        return self.C @ Z - self.VredT @ w, p

    def objective_from_translations(self, Z: np.ndarray, p: np.ndarray) -> float:
        """F(Y, p) summed edge by edge (no cancellation between the large terms of tr(Z^T Q Z))."""
        n, d = self.n, self.d
        Zb = Z.reshape(n, d, -1)
        # rotation residual, transposed: Z_j - R~^T Z_i  (d x r)
        rr = Zb[self.dst] - self.rotT @ Zb[self.src]
        # translation residual: p_j - p_i - Z_i^T t~  (r,)
        tr = p[self.dst] - p[self.src] - np.einsum("ea,ear->er", self.trans, Zb[self.src])
        return float(np.dot(self.kappa, np.einsum("eab,eab->e", rr, rr))
                     + np.dot(self.tau, np.einsum("er,er->e", tr, tr)))

    def objective(self, Z: np.ndarray) -> float:
        return self.objective_from_translations(Z, self.translations(Z))

    # ---- full sparse (translations kept) matrix: preconditioner and certificate --------
    def _full_parts(self) -> None:
        if self._full_symbolic is not None:
            return
        n, d = self.n, self.d
        dn = n * d
        # Block-diagonal d x d pattern of the rotation block (Lambda lives there).
        i = np.arange(n)
        a, b = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
        rr = (i[:, None, None] * d + a).ravel()
        cc = (i[:, None, None] * d + b).ravel()
        self._blockdiag_index = (rr + (n - 1), cc + (n - 1))
        bd = sp.csc_matrix((np.ones(rr.size), (rr, cc)), shape=(dn, dn))
        pattern = sp.bmat([[self.Lred, self.Vred], [self.VredT, abs(self.C) + bd]], format="csc")
        self._full_pattern = pattern
        self._full_symbolic = SymbolicCholesky(pattern)

    def full_matrix(self, lam_blocks: np.ndarray | None, shift: float) -> sp.csc_matrix:
        """M_red(s) = [[L_red, V_red], [V_red^T, C - Lambda + s I]] (sparse, (n-1+dn) square)."""
        self._full_parts()
        n, d = self.n, self.d
        dn = n * d
        lower = self.C + sp.identity(dn, format="csr") * shift
        if lam_blocks is not None:
            i = np.arange(n)
            a, b = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
            rr = (i[:, None, None] * d + a).ravel()
            cc = (i[:, None, None] * d + b).ravel()
            lower = lower - sp.csr_matrix((lam_blocks.ravel(), (rr, cc)), shape=(dn, dn))
        return sp.bmat([[self.Lred, self.Vred], [self.VredT, lower]], format="csc")

    def factor_full(self, lam_blocks: np.ndarray | None, shift: float, name: str) -> Factor:
        """Cholesky of M_red(shift) with the shared symbolic analysis; raises NotPositiveDefinite."""
        self._full_parts()
        return self._full_symbolic.factor(self.full_matrix(lam_blocks, shift), name=name)

    def schur_solve(self, factor: Factor, W: np.ndarray) -> np.ndarray:
        """(Q - Lambda + s I)^{-1} W, the rotation block of M_red(s)^{-1} [0; W]."""
        rhs = np.zeros((self.n - 1 + W.shape[0], W.shape[1]))
        rhs[self.n - 1:] = W
        return factor(rhs)[self.n - 1:]

    def gershgorin_max(self) -> float:
        """Upper bound on lambda_max(Q) <= lambda_max(C) (Q = C - PSD term)."""
        return float(np.max(np.asarray(abs(self.C).sum(axis=1)).ravel()))
