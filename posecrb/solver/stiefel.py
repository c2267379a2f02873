"""The product manifold St(d, r)^n, vectorised over (n, d, r) arrays.

A point is stored in the transposed "row" layout ``Z`` with blocks ``Z_i = Y_i^T``
(d x r, ``Z_i Z_i^T = I_d``); reshaping (n, d, r) <-> (dn, r) is free, which is the
layout the sparse data matrices act on (SE-Sync, section 4.1; Absil et al. 2008
for the Stiefel geometry with the embedded metric).
"""
from __future__ import annotations

import numpy as np

from ..lie.so import so_project


def sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def to_components(a: np.ndarray) -> np.ndarray:
    """(n, p, q) -> contiguous (p, q, n): the "component-major" layout of the block kernels."""
    return np.ascontiguousarray(np.moveaxis(a, 0, -1))


def from_components(a: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_components`."""
    return np.ascontiguousarray(np.moveaxis(a, -1, 0))


# The per-pose block operations below (sym(A_i B_i^T), the tangent projection, the Hessian's
# block part) act on n tiny d x r blocks (2 x 3, 3 x 4). numpy's batched matmul pays a per-block
# overhead that made them half of an HVP-heavy solve; instead they transpose once to the
# component-major layout (d, r, n) and loop over the d^2 block entries, each a contiguous
# length-n vector operation (several times faster than the batched matmul on large graphs, and as
# fast as a compiled numba kernel without numba's import and cache-load cost in every process:
# docs/decisions/fixed-costs.md).
def _sym_products(At: np.ndarray, Bt: np.ndarray) -> np.ndarray:
    """(d, d, n) entries of sym(A_i B_i^T) from component-major A, B (d, r, n)."""
    d = At.shape[0]
    S = np.empty((d, d, At.shape[2]))
    for a in range(d):
        for b in range(a, d):
            v = np.einsum("kn,kn->n", At[a], Bt[b])
            if a != b:
                v += np.einsum("kn,kn->n", At[b], Bt[a])
                v *= 0.5
                S[b, a] = v
            S[a, b] = v
    return S


def _subtract_block_product(Wt: np.ndarray, S: np.ndarray, Zt: np.ndarray) -> np.ndarray:
    """Wt - S Z per block, in place on Wt (component-major: S (d, d, n), Wt/Zt (d, r, n))."""
    d = Wt.shape[0]
    for a in range(d):
        for b in range(d):
            Wt[a] -= S[a, b] * Zt[b]
    return Wt


def sym_block_diag_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, d, d) blocks sym(A_i B_i^T)."""
    return from_components(_sym_products(to_components(a), to_components(b)))


def project(Z: np.ndarray, W: np.ndarray, Zt: np.ndarray | None = None, scale: float = 1.0) -> np.ndarray:
    """Orthogonal projection of W onto the tangent space at Z: W_i - sym(W_i Z_i^T) Z_i (times ``scale``).

    ``Zt = to_components(Z)`` when the caller reuses it across vectors at one point.
    """
    Zt = to_components(Z) if Zt is None else Zt
    Wt = to_components(W)
    if scale != 1.0:
        Wt *= scale
    return from_components(_subtract_block_product(Wt, _sym_products(Wt, Zt), Zt))


def hessian_blocks(Zt: np.ndarray, lamt: np.ndarray, V: np.ndarray, QV: np.ndarray) -> np.ndarray:
    """2 Proj_Z(QV - Lambda V) (n, d, r) from component-major Z (d, r, n) and Lambda (d, d, n)."""
    Wt = to_components(QV)
    _subtract_block_product(Wt, lamt, to_components(V))
    Wt *= 2.0
    return from_components(_subtract_block_product(Wt, _sym_products(Wt, Zt), Zt))


def _cofactors3(X: np.ndarray) -> np.ndarray:
    """Cofactor matrices of component-major 3 x 3 blocks X (3, 3, n): C with C^T = det(X) X^{-1}."""
    C = np.empty_like(X)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            C[i, j] = X[i1, j1] * X[i2, j2] - X[i1, j2] * X[i2, j1]
    return C


def nearest_rotations(m: np.ndarray) -> np.ndarray:
    """The rotation nearest (Frobenius) to each (n, d, d) block: ``lie.so.so_project`` up to rounding,
    without a batched LAPACK SVD (whose per-block cost was the bulk of chordal initialisation and
    rounding: docs/decisions/fixed-costs.md).

    d = 2: the maximiser of tr(R^T M) over SO(2) in closed form, the angle atan2(M_10 - M_01,
    M_00 + M_11). d = 3: the orthogonal polar factor by Newton's iteration
    ``X <- (g X + X^{-T} / g) / 2`` with determinant scaling ``g = |det X|^{-1/3}`` until the
    quadratic phase (Higham, Functions of Matrices, 2008, section 8.6), vectorised over blocks
    with closed-form cofactors; for det M > 0 the polar factor is the nearest rotation.
    Blocks with det M <= 0 or nearly singular (relative det below 1e-8, where the nearest rotation
    is ill-determined and Newton slow), a degenerate 2D block, other d, and a
    non-converged iteration go to the SVD.
    """
    m = np.asarray(m, float)
    n, d, _ = m.shape
    if n == 0 or d not in (2, 3):
        return so_project(m)
    if d == 2:
        p = m[:, 0, 0] + m[:, 1, 1]
        q = m[:, 1, 0] - m[:, 0, 1]
        h = np.hypot(p, q)
        out = np.empty_like(m)
        bad = ~(h > 1e-12 * np.sqrt(np.einsum("nab,nab->n", m, m)))
        with np.errstate(invalid="ignore", divide="ignore"):
            c, s = p / h, q / h
        out[:, 0, 0] = c
        out[:, 0, 1] = -s
        out[:, 1, 0] = s
        out[:, 1, 1] = c
        if bad.any():
            out[bad] = so_project(m[bad])
        return out
    X = to_components(m)
    size = np.sqrt(np.einsum("abn,abn->n", X, X) / 3.0)          # ~ the scale of a near-rotation
    det = np.einsum("jn,jn->n", X[0], _cofactors3(X)[0])
    good = det > 1e-8 * size ** 3
    Xg = X[:, :, good]
    scaled, last = True, False
    for _ in range(60):
        C = _cofactors3(Xg)
        det = np.einsum("jn,jn->n", Xg[0], C[0])
        g = np.abs(det) ** (-1.0 / 3.0) if scaled else np.ones_like(det)
        Xn = 0.5 * (g * Xg + C / (g * det))
        change = float(np.max(np.abs(Xn - Xg), initial=0.0))
        Xg = Xn
        if last:
            break
        scaled = change > 1e-2          # no scaling in the quadratic phase (its rounding would stall it)
        last = change < 1e-9            # quadratic: one more step reaches the rounding level
    else:
        good[:] = False                 # not converged: SVD for every block
    out = np.empty_like(m)
    if good.any():
        out[good] = from_components(Xg)
    if not good.all():
        out[~good] = so_project(m[~good])
    return out


def _polar2(A: np.ndarray) -> np.ndarray:
    """(A A^T)^{-1/2} A for (n, 2, r) blocks in closed form (no batched eigh): for a 2 x 2 SPD G
    with s = sqrt(det G), sqrt(G) = (G + s I) / sqrt(tr G + 2 s) (Cayley-Hamilton), and its
    inverse is adj(sqrt G) / s. det G is summed as sum_{j<k} (A_0j A_1k - A_0k A_1j)^2
    (Cauchy-Binet), not as ac - b^2, which cancels for long, nearly parallel rows."""
    a = np.einsum("nr,nr->n", A[:, 0], A[:, 0])
    b = np.einsum("nr,nr->n", A[:, 0], A[:, 1])
    c = np.einsum("nr,nr->n", A[:, 1], A[:, 1])
    r = A.shape[2]
    det = np.zeros(A.shape[0])
    for j in range(r):
        for k in range(j + 1, r):
            minor = A[:, 0, j] * A[:, 1, k] - A[:, 0, k] * A[:, 1, j]
            det += minor * minor
    s = np.sqrt(det)
    t = np.sqrt(a + c + 2.0 * s)
    k = 1.0 / (s * t)
    # sqrt(G) = [[a + s, b], [b, c + s]] / t; its inverse = [[c + s, -b], [-b, a + s]] / (t s).
    out = np.empty_like(A)
    out[:, 0] = ((c + s) * k)[:, None] * A[:, 0] - (b * k)[:, None] * A[:, 1]
    out[:, 1] = ((a + s) * k)[:, None] * A[:, 1] - (b * k)[:, None] * A[:, 0]
    return out


def _polar3(A: np.ndarray) -> np.ndarray | None:
    """(A A^T)^{-1/2} A for (n, 3, r) blocks of full row rank by Newton's iteration for the polar
    factor, ``X <- (g X + (X X^T)^{-1} X / g) / 2`` (each singular value s -> (g s + 1/(g s)) / 2,
    singular vectors fixed), with determinant scaling g = det(X X^T)^{-1/6} until the quadratic
    phase (Higham, Functions of Matrices, 2008, section 8.6; the rectangular form uses the
    pseudo-inverse), vectorised in the component-major layout with closed-form 3 x 3 cofactors.
    None when it has not converged (the caller falls back to eigh)."""
    X = to_components(A)                              # (3, r, n)
    scaled, last = True, False
    for _ in range(60):
        G = np.empty((3, 3, X.shape[2]))
        for a in range(3):
            for b in range(a, 3):
                G[a, b] = np.einsum("kn,kn->n", X[a], X[b])
                G[b, a] = G[a, b]
        C = _cofactors3(G)                            # symmetric: G^{-1} = C / det
        det = np.einsum("jn,jn->n", G[0], C[0])
        if not np.all(det > 0):
            return None
        g = det ** (-1.0 / 6.0) if scaled else np.ones_like(det)
        h = 1.0 / (g * det)
        Xn = np.empty_like(X)
        for a in range(3):
            Xn[a] = (C[a, 0] * h) * X[0] + (C[a, 1] * h) * X[1] + (C[a, 2] * h) * X[2] + g * X[a]
        Xn *= 0.5
        change = float(np.max(np.abs(Xn - X), initial=0.0))
        X = Xn
        if last:
            return from_components(X)
        scaled = change > 1e-2
        last = change < 1e-9
    return None


def retract(Z: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Polar retraction: the orthonormal polar factor (A A^T)^{-1/2} A of A = Z + W, per block
    (closed form for d = 2, Newton's polar iteration for d = 3, batched eigh of the d x d Gram
    matrices otherwise or when the iteration fails)."""
    A = Z + W
    if A.shape[1] == 2:
        return _polar2(A)
    if A.shape[1] == 3 and A.shape[0] > 0:
        X = _polar3(A)
        if X is not None:
            return X
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

