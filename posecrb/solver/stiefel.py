"""The product manifold St(d, r)^n, vectorised over (n, d, r) arrays.

A point is stored in the transposed "row" layout ``Z`` with blocks ``Z_i = Y_i^T``
(d x r, ``Z_i Z_i^T = I_d``); reshaping (n, d, r) <-> (dn, r) is free, which is the
layout the sparse data matrices act on (SE-Sync, section 4.1; Absil et al. 2008
for the Stiefel geometry with the embedded metric).
"""
from __future__ import annotations

import numpy as np


def sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def sym_block_diag_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, d, d) blocks sym(A_i B_i^T)."""
    return sym(a @ np.swapaxes(b, -1, -2))


def project(Z: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Orthogonal projection of W onto the tangent space at Z: W_i - sym(W_i Z_i^T) Z_i."""
    return W - sym_block_diag_product(W, Z) @ Z


def retract(Z: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Polar retraction: the orthonormal polar factor (A A^T)^{-1/2} A of A = Z + W, per block."""
    A = Z + W
    s, U = np.linalg.eigh(A @ np.swapaxes(A, -1, -2))
    inv_sqrt = (U * (1.0 / np.sqrt(s))[..., None, :]) @ np.swapaxes(U, -1, -2)
    return inv_sqrt @ A


def inner(a: np.ndarray, b: np.ndarray) -> float:
    # einsum, not BLAS dot: no thread start-up cost on these mid-sized vectors.
    return float(np.einsum("i,i->", a.ravel(), b.ravel()))


def random_point(n: int, d: int, r: int, rng: np.random.Generator) -> np.ndarray:
    """A random point of St(d, r)^n (QR of Gaussian blocks)."""
    g = rng.standard_normal((n, r, d))
    q, _ = np.linalg.qr(g)
    return np.ascontiguousarray(np.swapaxes(q, -1, -2))


def lift(Z: np.ndarray, r: int) -> np.ndarray:
    """Pad each block with zero columns up to rank r (stays on the manifold)."""
    n, d, r0 = Z.shape
    out = np.zeros((n, d, r))
    out[:, :, :r0] = Z
    return out


def gram_eigh(Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-decomposition (ev, U) of the r x r Gram matrix G = Z^T Z (Z as (dn, r))."""
    Zf = Z.reshape(-1, Z.shape[-1])
    return np.linalg.eigh(Zf.T @ Zf)


def remove_vertical(Z: np.ndarray, W: np.ndarray, gram: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Project a tangent vector off the vertical space {Z Omega : Omega in so(r)}.

    The relaxed objective is invariant under Y -> O Y (O in O(r)), so vertical directions
    carry no information; removing them keeps a preconditioner that amplifies the
    (near-)kernel of S = Q - Lambda from spending trust-region steps on the gauge.
    Solves G Omega + Omega G = 2 skew(Z^T W) with G = Z^T Z (least squares, then W - Z Omega).
    ``gram`` is ``gram_eigh(Z)`` when the caller reuses it across vectors at one point.
    """
    n, d, r = Z.shape
    Zf = Z.reshape(n * d, r)
    Wf = W.reshape(n * d, r)
    A = Zf.T @ Wf
    ev, U = gram_eigh(Z) if gram is None else gram
    K = U.T @ (A - A.T) @ U
    den = ev[:, None] + ev[None, :]
    tiny = den <= 1e-12 * max(float(ev[-1]), 1e-300)
    Om = np.where(tiny, 0.0, K / np.where(tiny, 1.0, den))
    Omega = U @ Om @ U.T
    return W - (Zf @ Omega).reshape(n, d, r)
