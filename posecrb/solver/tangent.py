"""The first staircase level's preconditioner: the exact inverse of the Riemannian Hessian on the tangent space.

docs/design.md#solver. At the first level the point is n orthogonal d x d blocks Z_i (row layout,
``Z_i = R_i^T``). Its tangent vectors are ``V_i = Omega_i Z_i`` with Omega_i skew, i.e. ``V = E theta``
with ``theta`` the k = d(d-1)/2 coordinates of every Omega_i in a basis G_a of so(d) (each of
Frobenius norm sqrt 2, so ``E^T E = 2 I``). The Riemannian Hessian is ``2 Proj(S V)`` with
``S = Q - Lambda`` (SE-Sync, eq. 46), so on the tangent space its inverse is

    P r = E (2 E^T (S + s I) E)^{-1} E^T r,

exact for s = 0: a truncated-CG run preconditioned with it is a Newton step after one or two
products. The solver's other preconditioner, ``Proj (Q - Lambda + s I)^{-1} Proj`` through M_red,
inverts S on all d x d entries of a block, d(d+1)/2 of which are normal to the manifold, and
truncated CG then needs 11-44 products per trust-region iteration.

Q is dense, but ``E^T (S + s I) E`` is the Schur complement of the sparse matrix

    K = [[L(W^tau) (x) I_d,   (V_red (x) I_d) E],
         [E^T (V_red (x) I_d)^T,   E^T ((C - Lambda) (x) I_d) E + 2 s I]],

which keeps one copy of the reduced translations per column of Z, as M_red keeps one for
``Q - Lambda + s I`` (problem.py): ``(n - 1) d + n k`` rows, 3 per pose in 2D (M_red: 3), 6 in 3D
(M_red: 4). Its pattern depends on the graph only; every factorization writes new values into it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from sksparse.cholmod import Factor

from ..core.errors import InternalError
from ..linalg.cholesky import SymbolicCholesky, solve_tail
from ..linalg.ordering import solver_symbolic
from ..linalg.threads import factorization_threads
from .problem import Problem


def so_basis(d: int) -> np.ndarray:
    """(k, d, d) basis G_a of the skew-symmetric d x d matrices, each of Frobenius norm sqrt 2."""
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]
    G = np.zeros((len(pairs), d, d))
    for a, (i, j) in enumerate(pairs):
        G[a, j, i], G[a, i, j] = 1.0, -1.0
    return G


@dataclass
class TangentSystem:
    """The pattern, symbolic analysis and value map of K (module docstring) for one problem."""

    basis: np.ndarray              # (k, d, d)
    symbolic: SymbolicCholesky
    pattern: sp.csc_matrix
    first: int                     # rows of K before the tangent coordinates: (n - 1) d
    lt_values: np.ndarray          # L(W^tau) (x) I_d, in the order of lt_pos
    lt_pos: np.ndarray
    b_pos: np.ndarray              # (nb, d, k) positions of B's blocks, (nb, k, d) of B^T's
    bt_pos: np.ndarray
    v_blocks: np.ndarray           # (nb, d) V_red[t, i*d:(i+1)*d] per block (t, i)
    v_pose: np.ndarray             # i of each block
    d_pos: np.ndarray              # (nc, k, k) positions of D's blocks, one per d x d block of C
    c_blocks: np.ndarray           # (nc, d, d) the blocks of C
    c_row: np.ndarray              # pose pair (i, j) of each block
    c_col: np.ndarray
    diag_block: np.ndarray         # index into the C blocks of each pose's diagonal block

    @classmethod
    def build(cls, problem: Problem) -> TangentSystem:
        n, d = problem.n, problem.d
        G = so_basis(d)
        k = G.shape[0]
        first = (n - 1) * d
        size = first + n * k
        # L(W^tau) (x) I_d: row (t, c) -> t d + c
        lred = problem.Lred.tocoo()
        c = np.arange(d)
        lt_r = (lred.row.astype(np.int64)[:, None] * d + c).ravel()
        lt_c = (lred.col.astype(np.int64)[:, None] * d + c).ravel()
        lt_values = np.repeat(lred.data, d)
        # B: one d x k block per nonzero 1 x d block (t, i) of V_red
        vb = problem.Vred.tobsr(blocksize=(1, d))
        vb.sort_indices()
        v_row = np.repeat(np.arange(vb.shape[0]), np.diff(vb.indptr))
        v_pose = vb.indices.astype(np.int64)
        v_blocks = vb.data.reshape(-1, d).copy()
        a = np.arange(k)
        b_r = v_row[:, None, None] * d + c[None, :, None]                  # (nb, d, 1)
        b_c = first + v_pose[:, None, None] * k + a[None, None, :]          # (nb, 1, k)
        b_r, b_c = np.broadcast_arrays(b_r, b_c)
        # D: one k x k block per d x d block (i, j) of C (every pose has its diagonal block)
        cb = problem.C.tobsr(blocksize=(d, d))
        cb.sort_indices()
        c_row = np.repeat(np.arange(n), np.diff(cb.indptr))
        c_col = cb.indices.astype(np.int64)
        diag = np.flatnonzero(c_row == c_col)
        if diag.size != n or not np.array_equal(c_row[diag], np.arange(n)):
            raise InternalError("C lacks a diagonal block")
        d_r = first + c_row[:, None, None] * k + a[None, :, None]
        d_c = first + c_col[:, None, None] * k + a[None, None, :]
        d_r, d_c = np.broadcast_arrays(d_r, d_c)
        rows = np.concatenate([lt_r, b_r.ravel(), b_c.ravel(), d_r.ravel()])
        cols = np.concatenate([lt_c, b_c.ravel(), b_r.ravel(), d_c.ravel()])
        keys = cols * size + rows
        order = np.argsort(keys, kind="stable")
        if np.any(keys[order][1:] == keys[order][:-1]):
            raise InternalError("K: an entry is assembled twice")
        pos = np.empty(keys.size, dtype=np.int64)
        pos[order] = np.arange(keys.size)
        indptr = np.searchsorted(cols[order], np.arange(size + 1)).astype(np.int64)
        pattern = sp.csc_matrix((np.ones(keys.size), rows[order], indptr), shape=(size, size))
        nl, nbk = lt_r.size, b_r.size
        pose_of_row = np.concatenate([np.repeat(np.arange(1, n), d), np.repeat(np.arange(n), k)])
        symbolic = solver_symbolic(pattern, d, n, mode=problem.factor_mode(d + k), pose_of_row=pose_of_row,
                                   pose_order=problem.pose_order())
        return cls(basis=G, symbolic=symbolic, pattern=pattern, first=first,
                   lt_values=lt_values, lt_pos=pos[:nl], b_pos=pos[nl:nl + nbk].reshape(b_r.shape),
                   bt_pos=pos[nl + nbk:nl + 2 * nbk].reshape(b_r.shape), v_blocks=v_blocks, v_pose=v_pose,
                   d_pos=pos[nl + 2 * nbk:].reshape(d_r.shape), c_blocks=cb.data.copy(), c_row=c_row, c_col=c_col,
                   diag_block=diag)

    def tangent_blocks(self, Z: np.ndarray) -> np.ndarray:
        """(n, k, d, d) the columns of E at Z: ``G_a Z_i``."""
        return np.einsum("axy,nyc->naxc", self.basis, Z)

    def matrix(self, Z: np.ndarray, lam: np.ndarray | None, shift: float) -> sp.csc_matrix:
        """K at the point Z (n, d, d) with Lambda's blocks ``lam`` (None: without Lambda) and shift s."""
        GZ = self.tangent_blocks(Z)
        data = np.empty(self.pattern.nnz)
        data[self.lt_pos] = self.lt_values
        # B[(t, c), (i, a)] = sum_x V_red[t, i d + x] (G_a Z_i)[x, c]
        blocks = np.einsum("bx,baxc->bca", self.v_blocks, GZ[self.v_pose])
        data[self.b_pos] = blocks
        data[self.bt_pos] = blocks
        # D[(i, a), (j, b)] = tr((G_a Z_i)^T C_ij (G_b Z_j)), minus Lambda's and plus the shift's on the diagonal
        dblk = np.einsum("naxc,nxy,nbyc->nab", GZ[self.c_row], self.c_blocks, GZ[self.c_col])
        diag = self.diag_block
        if lam is not None:
            dblk[diag] -= np.einsum("naxc,nxy,nbyc->nab", GZ, lam, GZ)
        dblk[diag] += shift * np.einsum("axy,bxy->ab", self.basis, self.basis)
        data[self.d_pos] = dblk
        P = self.pattern
        K = sp.csc_matrix((data, P.indices, P.indptr), shape=P.shape, copy=False)
        K.has_sorted_indices = True
        return K

    def factor(self, Z: np.ndarray, lam: np.ndarray | None, shift: float, name: str) -> Factor:
        """Cholesky of K; raises NotPositiveDefinite (S + s I not positive definite on the tangent space)."""
        with factorization_threads():
            return self.symbolic.factor(self.matrix(Z, lam, shift), name=name)

    def apply(self, factor: Factor, Z: np.ndarray, R: np.ndarray,
              gauge: tuple[np.ndarray, float] | None = None) -> np.ndarray:
        """``E (2 E^T (S + s I) E)^{-1} E^T R`` for R (n, d, r) through a factor of K, with E at Z (n, d, r).

        ``gauge = (U, c)``: U (n k, k) orthonormal coordinates of the directions the factor's
        Schur complement holds only through its shift (:meth:`gauge_modes`); on them the inverse is
        replaced by ``1 / c``, on their complement it is projected (``Pi A^{-1} Pi``).
        """
        GZ = self.tangent_blocks(Z)
        n, k = Z.shape[0], self.basis.shape[0]
        rhs = np.einsum("naxc,nxc->na", GZ, R).reshape(n * k, 1)
        if gauge is None:
            theta = 0.5 * solve_tail(factor, self.first, rhs)
        else:
            U, c = gauge
            along = U @ (U.T @ rhs)
            theta = solve_tail(factor, self.first, rhs - along)
            theta -= U @ (U.T @ theta)
            theta = 0.5 * theta + along / c
        return np.einsum("na,naxc->nxc", theta.reshape(n, k), GZ)

    def gauge_modes(self, Z: np.ndarray) -> np.ndarray:
        """(n k, k) orthonormal coordinates of the directions ``Z_i H`` (H in so(d)), i.e.
        ``Omega_i = Z_i H Z_i^T``, at a first-level point Z (n, d, d): the rotation of every pose at
        once, along which ``S Z = 0`` leaves K's Schur complement only its shift 2 s."""
        n, k = Z.shape[0], self.basis.shape[0]
        omega = np.einsum("nxy,byz,nwz->bnxw", Z, self.basis, Z)
        coords = 0.5 * np.einsum("axw,bnxw->nab", self.basis, omega).reshape(n * k, k)
        return np.linalg.qr(coords)[0]

    def diagonal_mean(self, Z: np.ndarray, lam: np.ndarray) -> float:
        """Mean diagonal of ``2 E^T (C - Lambda) E`` at Z (n, d, r): the scale of the Hessian on the
        tangent coordinates before the translations are eliminated."""
        GZ = self.tangent_blocks(Z)
        cl = self.c_blocks[self.diag_block] - lam
        return 2.0 * float(np.mean(np.einsum("naxc,nxy,nayc->na", GZ, cl, GZ)))
