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
from .stiefel import to_components


def so_basis(d: int) -> np.ndarray:
    """(k, d, d) basis G_a of the skew-symmetric d x d matrices, each of Frobenius norm sqrt 2."""
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]
    G = np.zeros((len(pairs), d, d))
    for a, (i, j) in enumerate(pairs):
        G[a, j, i], G[a, i, j] = 1.0, -1.0
    return G


def generator_entries(G: np.ndarray) -> list[list[tuple[int, int, float]]]:
    """For each generator G_a, its entries (x, u, s) with ``G_a[x, u] = s``: ``(G_a Z)[x] = s Z[u]``
    summed over them (:func:`so_basis` gives two per generator, +-1)."""
    return [[(int(x), int(u), float(G[a, x, u])) for x, u in zip(*np.nonzero(G[a]), strict=True)]
            for a in range(G.shape[0])]


def generator_traces(entries: list[list[tuple[int, int, float]]], left: np.ndarray, right: np.ndarray,
                     middle: np.ndarray) -> np.ndarray:
    """(k, k, nb) ``tr((G_a L_n)^T M_n (G_b R_n))`` for blocks L, R and M given component-major
    (posecrb.solver.stiefel.to_components): ``left``, ``right`` (d, r, nb), ``middle`` (d, d, nb).

    With ``P_n = L_n R_n^T`` it is ``sum G_a[x, u] G_b[y, v] M[x, y] P[u, v]``: four terms per pair
    of generators (``entries``, :func:`generator_entries`), each a product of two length-nb
    vectors, instead of the products through G_a L and G_b R, whose blocks are k times the size
    (docs/decisions/solver-preconditioners.md).
    """
    d, nb = left.shape[0], left.shape[2]
    P = np.empty((d, d, nb))
    for u in range(d):
        for v in range(d):
            np.einsum("cn,cn->n", left[u], right[v], out=P[u, v])
    k = len(entries)
    out = np.zeros((k, k, nb))
    for a, ea in enumerate(entries):
        for b, eb in enumerate(entries):
            for x, u, sa in ea:
                for y, v, sb in eb:
                    out[a, b] += (sa * sb) * (middle[x, y] * P[u, v])
    return out


@dataclass
class TangentSystem:
    """The pattern, symbolic analysis and value map of K (module docstring) for one problem."""

    basis: np.ndarray              # (k, d, d)
    entries: list[list[tuple[int, int, float]]]   # generator_entries(basis)
    symbolic: SymbolicCholesky
    pattern: sp.csc_matrix
    first: int                     # rows of K before the tangent coordinates: (n - 1) d
    lt_values: np.ndarray          # L(W^tau) (x) I_d, in the order of lt_pos
    lt_pos: np.ndarray
    # The per-block data below is stored component-major (block index last, as
    # posecrb.solver.stiefel.to_components): the kernels of ``matrix`` are length-nb vector operations.
    b_pos: np.ndarray              # (k, d, nb) positions of B's blocks, and of B^T's
    bt_pos: np.ndarray
    v_blocks: np.ndarray           # (d, nb) V_red[t, i*d:(i+1)*d] per block (t, i)
    v_pose: np.ndarray             # i of each block
    d_pos: np.ndarray              # (k, k, nc) positions of D's blocks, one per d x d block of C
    c_blocks: np.ndarray           # (d, d, nc) the blocks of C
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
        return cls(basis=G, entries=generator_entries(G), symbolic=symbolic, pattern=pattern, first=first,
                   lt_values=lt_values, lt_pos=pos[:nl],
                   b_pos=to_components(pos[nl:nl + nbk].reshape(b_r.shape).transpose(0, 2, 1)),
                   bt_pos=to_components(pos[nl + nbk:nl + 2 * nbk].reshape(b_r.shape).transpose(0, 2, 1)),
                   v_blocks=to_components(v_blocks), v_pose=v_pose,
                   d_pos=to_components(pos[nl + 2 * nbk:].reshape(d_r.shape)), c_blocks=to_components(cb.data),
                   c_row=c_row, c_col=c_col, diag_block=diag)

    def tangent_blocks(self, Z: np.ndarray) -> np.ndarray:
        """(n, k, d, r) the columns of E at Z (n, d, r): ``G_a Z_i``.

        Each row of G_a has one nonzero, +-1 (:func:`so_basis`), so the product copies rows of Z_i
        with a sign. Written that way it has the product's digits and skips the contraction over
        the zeros, which runs at every preconditioner application
        (docs/decisions/solver-preconditioners.md).
        """
        n, d, r = Z.shape
        out = np.zeros((n, len(self.entries), d, r))
        for a, generator in enumerate(self.entries):     # k <= 3 generators, two entries each
            for x, u, sign in generator:
                out[:, a, x] += sign * Z[:, u]
        return out

    def matrix(self, Z: np.ndarray, lam: np.ndarray | None, shift: float) -> sp.csc_matrix:
        """K at the point Z (n, d, d) with Lambda's blocks ``lam`` (None: without Lambda) and shift s."""
        entries = self.entries
        Zt = to_components(Z)                               # (d, d, n)
        data = np.empty(self.pattern.nnz)
        data[self.lt_pos] = self.lt_values
        # B[(t, c), (i, a)] = sum_x V_red[t, i d + x] (G_a Z_i)[x, c] = sum_(x, u, s) s V_red[t, i d + x] Z_i[u, c]
        Zv = Zt[:, :, self.v_pose]
        blocks = np.zeros((len(entries),) + Zv.shape[1:])   # (k, c, nb)
        for a, ea in enumerate(entries):
            for x, u, sign in ea:
                blocks[a] += (sign * self.v_blocks[x]) * Zv[u]
        data[self.b_pos] = blocks
        data[self.bt_pos] = blocks
        # D[(i, a), (j, b)] = tr((G_a Z_i)^T C_ij (G_b Z_j)), minus Lambda's and plus the shift's on the diagonal
        dblk = generator_traces(entries, Zt[:, :, self.c_row], Zt[:, :, self.c_col], self.c_blocks)
        diag = self.diag_block
        if lam is not None:
            dblk[:, :, diag] -= generator_traces(entries, Zt, Zt, to_components(lam))
        dblk[:, :, diag] += shift * np.einsum("axy,bxy->ab", self.basis, self.basis)[:, :, None]
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
        G = self.basis
        n, k, d = Z.shape[0], G.shape[0], G.shape[1]
        omega = np.matmul(np.matmul(Z[:, None], G[None]), np.swapaxes(Z, 1, 2)[:, None])   # (n, b, x, w)
        # coordinate a of Omega_b at pose i: <G_a, Omega_b> / 2 (every G_a has Frobenius norm sqrt 2)
        coords = 0.5 * np.swapaxes(np.matmul(omega.reshape(n, k, d * d), G.reshape(k, d * d).T), 1, 2)
        return np.linalg.qr(coords.reshape(n * k, k))[0]

    def diagonal_mean(self, Z: np.ndarray, lam: np.ndarray) -> float:
        """Mean diagonal of ``2 E^T (C - Lambda) E`` at Z (n, d, r): the scale of the Hessian on the
        tangent coordinates before the translations are eliminated."""
        Zt = to_components(Z)
        cl = self.c_blocks[:, :, self.diag_block] - to_components(lam)
        traces = generator_traces(self.entries, Zt, Zt, cl)
        return 2.0 * float(np.mean(np.diagonal(traces)))
