"""Compiled kernels of a ball's Dirichlet problem for the round greedy (``posecrb.selection.rounds``):
the ball of the current graph around a candidate edge (bounded Dijkstra, with its shortest-path
tree), the ball's principal submatrix of a block's matrix, and its solution by conjugate gradients
preconditioned with that matrix restricted to the tree (factored from the leaves up in one pass).

Compiled with numba (``cache=True``) like ``posecrb.selection._kernels``.
"""
from __future__ import annotations

import numpy as np

from ..linalg.pathchol import njit


@njit(cache=True, nogil=True, inline="always")
def _first(ka, a, kb, b):  # pragma: no cover - compiled
    """Whether entry (ka, a) comes before (kb, b) in a heap: the smaller key, then the smaller id."""
    return ka < kb or (ka == kb and a < b)


@njit(cache=True, nogil=True, inline="always")
def sift_up(hk, hv, j, k, v):  # pragma: no cover - compiled
    """Place (k, v) at the free slot j of the binary heap (hk keys, hv ids; ``_first`` on top)."""
    while j > 0 and _first(k, v, hk[(j - 1) >> 1], hv[(j - 1) >> 1]):
        hk[j], hv[j] = hk[(j - 1) >> 1], hv[(j - 1) >> 1]
        j = (j - 1) >> 1
    hk[j], hv[j] = k, v


@njit(cache=True, nogil=True, inline="always")
def sift_down(hk, hv, size, k, v):  # pragma: no cover - compiled
    """Place (k, v) at the root of the binary heap of ``size`` entries (its root slot free)."""
    j = 0
    c = 1
    while c < size:
        if c + 1 < size and _first(hk[c + 1], hv[c + 1], hk[c], hv[c]):
            c += 1
        if not _first(hk[c], hv[c], k, v):
            break
        hk[j], hv[j] = hk[c], hv[c]
        j = c
        c = 2 * j + 1
    hk[j], hv[j] = k, v


@njit(cache=True, nogil=True)
def ball(v0, v1, radius, cap, adj_ptr, adj_to, adj_len, dist, tpar, spos):  # pragma: no cover - compiled
    """The poses within distance ``radius`` of the poses v0 and v1 in the graph (adj_ptr, adj_to,
    adj_len) (CSR over the poses, edge lengths), at most the ``cap`` nearest, in the order Dijkstra
    settles them (v0 and v1 first), and each one's parent in the shortest-path tree as a position
    in that order (-1 for v0 and v1). ``dist`` (all inf), ``tpar`` and ``spos`` are work arrays
    over the poses; ``dist`` is left all inf."""
    hd = np.empty(256)
    hv = np.empty(256, np.int64)
    poses = np.empty(256, np.int64)
    par = np.empty(256, np.int64)
    size = 0
    k = 0
    for s in (v0, v1):
        if dist[s] > 0.0:
            dist[s] = 0.0
            tpar[s] = -1
            sift_up(hd, hv, size, 0.0, s)
            size += 1
    while size > 0:
        d, v = hd[0], hv[0]
        size -= 1
        if size > 0:
            sift_down(hd, hv, size, hd[size], hv[size])
        if d > dist[v]:
            continue
        if k == cap:                       # full: what is still queued stays out
            dist[v] = np.inf
            for t in range(size):
                if dist[hv[t]] >= 0.0:     # tentative (settled poses hold -1)
                    dist[hv[t]] = np.inf
            break
        dist[v] = -1.0                     # settled
        if k == poses.shape[0]:
            grown = np.empty(2 * k, np.int64)
            grown[:k] = poses
            poses = grown
            grown = np.empty(2 * k, np.int64)
            grown[:k] = par
            par = grown
        poses[k] = v
        spos[v] = k
        par[k] = spos[tpar[v]] if tpar[v] >= 0 else -1     # the parent settled before v
        k += 1
        for q in range(adj_ptr[v], adj_ptr[v + 1]):
            w = adj_to[q]
            nd = d + adj_len[q]
            if nd <= radius and nd < dist[w]:
                dist[w] = nd
                tpar[w] = v
                if size == hd.shape[0]:
                    grown_d = np.empty(2 * size)
                    grown_d[:size] = hd
                    hd = grown_d
                    grown = np.empty(2 * size, np.int64)
                    grown[:size] = hv
                    hv = grown
                sift_up(hd, hv, size, nd, w)
                size += 1
    for t in range(k):                     # the other poses with a distance were reset above
        dist[poses[t]] = np.inf
    return poses[:k], par[:k]


@njit(cache=True, nogil=True)
def ball_system(poses, pose_rows, indptr, indices, loc):  # pragma: no cover - compiled
    """The ball's rows and its principal submatrix's pattern: per ball pose its first local row (-1
    for the anchor, which has none), and the local CSR (ptr, cols, positions of the values in the
    global CSC (indptr, indices), symmetric with both triangles). ``loc`` (global row -> local row)
    is -1 on entry and left so."""
    rpp = pose_rows.shape[1]
    k = poses.shape[0]
    lrow = np.empty(k, np.int64)
    nrows = 0
    for t in range(k):
        if pose_rows[poses[t], 0] >= 0:
            lrow[t] = nrows
            for s in range(rpp):
                loc[pose_rows[poses[t], s]] = nrows + s
            nrows += rpp
        else:
            lrow[t] = -1
    ptr = np.zeros(nrows + 1, np.int64)
    for t in range(k):
        if lrow[t] >= 0:
            for s in range(rpp):
                g = pose_rows[poses[t], s]
                cnt = 0
                for q in range(indptr[g], indptr[g + 1]):
                    if loc[indices[q]] >= 0:
                        cnt += 1
                ptr[lrow[t] + s + 1] = cnt
    for i in range(nrows):
        ptr[i + 1] += ptr[i]
    cols = np.empty(ptr[nrows], np.int64)
    where = np.empty(ptr[nrows], np.int64)
    for t in range(k):
        if lrow[t] >= 0:
            for s in range(rpp):
                g = pose_rows[poses[t], s]
                cnt = ptr[lrow[t] + s]
                for q in range(indptr[g], indptr[g + 1]):
                    j = loc[indices[q]]
                    if j >= 0:
                        cols[cnt] = j
                        where[cnt] = q
                        cnt += 1
    for t in range(k):
        if lrow[t] >= 0:
            for s in range(rpp):
                loc[pose_rows[poses[t], s]] = -1
    return lrow, ptr, cols, where


@njit(cache=True, nogil=True)
def _inv_spd(a, out):  # pragma: no cover - compiled
    """``out = a^{-1}`` of a small symmetric positive definite matrix (Gauss-Jordan, no pivoting);
    returns False when a pivot is not positive."""
    m = a.shape[0]
    w = a.copy()
    for i in range(m):
        for j in range(m):
            out[i, j] = 1.0 if i == j else 0.0
    for c in range(m):
        d = w[c, c]
        if not d > 0.0:
            return False
        for j in range(m):
            w[c, j] /= d
            out[c, j] /= d
        for i in range(m):
            if i != c:
                f = w[i, c]
                if f != 0.0:
                    for j in range(m):
                        w[i, j] -= f * w[c, j]
                        out[i, j] -= f * out[c, j]
    return True


@njit(cache=True, nogil=True)
def tree_factor(lrow, par, rpp, ptr, cols, vals):  # pragma: no cover - compiled
    """The preconditioner: the ball's matrix with every off-diagonal block dropped but those between a
    pose and its parent in the shortest-path tree (positive definite: a sum of the edges' positive
    semidefinite terms and their diagonal blocks), factored from the leaves up. Returns per pose
    the inverse of its pivot block and its block towards the parent (rows of the pose, columns of
    the parent; zero for a root or when the parent has no rows), and whether every pivot was
    positive."""
    k = lrow.shape[0]
    pivinv = np.zeros((k, rpp, rpp))
    up = np.zeros((k, rpp, rpp))
    acc = np.zeros((k, rpp, rpp))
    for t in range(k):
        if lrow[t] < 0:
            continue
        pt = par[t]
        for s in range(rpp):
            i = lrow[t] + s
            for q in range(ptr[i], ptr[i + 1]):
                j = cols[q]
                if lrow[t] <= j < lrow[t] + rpp:
                    acc[t, s, j - lrow[t]] += vals[q]
                elif pt >= 0 and lrow[pt] >= 0 and lrow[pt] <= j < lrow[pt] + rpp:
                    up[t, s, j - lrow[pt]] += vals[q]
    tmp = np.zeros((rpp, rpp))
    for t in range(k - 1, -1, -1):         # children settle after their parents
        if lrow[t] < 0:
            continue
        if rpp == 1:
            if not acc[t, 0, 0] > 0.0:
                return pivinv, up, False
            pivinv[t, 0, 0] = 1.0 / acc[t, 0, 0]
        elif not _inv_spd(acc[t], pivinv[t]):
            return pivinv, up, False
        pt = par[t]
        if pt >= 0 and lrow[pt] >= 0:
            for a in range(rpp):           # acc[pt] -= up[t]^T pivinv[t] up[t]
                for c in range(rpp):
                    v = 0.0
                    for e in range(rpp):
                        v += pivinv[t, a, e] * up[t, e, c]
                    tmp[a, c] = v
            for a in range(rpp):
                for c in range(rpp):
                    v = 0.0
                    for e in range(rpp):
                        v += up[t, e, a] * tmp[e, c]
                    acc[pt, a, c] -= v
    return pivinv, up, True


@njit(cache=True, nogil=True)
def tree_solve(lrow, par, pivinv, up, r, z, y, w):  # pragma: no cover - compiled
    """``z = P^{-1} r`` with the tree preconditioner of ``tree_factor`` (one column; y and w are work
    vectors of the same size)."""
    k = lrow.shape[0]
    rpp = pivinv.shape[1]
    for i in range(r.shape[0]):
        y[i] = r[i]
    for t in range(k - 1, -1, -1):
        b = lrow[t]
        if b < 0:
            continue
        for a in range(rpp):
            v = 0.0
            for c in range(rpp):
                v += pivinv[t, a, c] * y[b + c]
            w[b + a] = v
        pt = par[t]
        if pt >= 0 and lrow[pt] >= 0:
            bp = lrow[pt]
            for a in range(rpp):
                v = 0.0
                for c in range(rpp):
                    v += up[t, c, a] * w[b + c]
                y[bp + a] -= v
    for t in range(k):
        b = lrow[t]
        if b < 0:
            continue
        pt = par[t]
        if pt >= 0 and lrow[pt] >= 0:
            bp = lrow[pt]
            for a in range(rpp):           # z_t = w_t - pivinv_t up_t z_parent
                v = 0.0
                for c in range(rpp):
                    u = 0.0
                    for e in range(rpp):
                        u += up[t, c, e] * z[bp + e]
                    v += pivinv[t, a, c] * u
                z[b + a] = w[b + a] - v
        else:
            for a in range(rpp):
                z[b + a] = w[b + a]


@njit(cache=True, nogil=True)
def pcg(ptr, cols, vals, lrow, par, pivinv, up, rhs, tol, maxit):  # pragma: no cover - compiled
    """Conjugate gradients on the ball's matrix (ptr, cols, vals) for one right-hand side,
    preconditioned by the tree (``tree_factor``), until the residual is below ``tol`` times the
    right-hand side's norm or after ``maxit`` iterations. Returns (solution, iterations, converged)."""
    n = rhs.shape[0]
    x = np.zeros(n)
    res = rhs.copy()
    bnorm2 = 0.0
    for i in range(n):
        bnorm2 += rhs[i] * rhs[i]
    if bnorm2 == 0.0:
        return x, 0, True
    z = np.empty(n)
    y = np.empty(n)
    w = np.empty(n)
    ap = np.empty(n)
    tree_solve(lrow, par, pivinv, up, res, z, y, w)
    p = z.copy()
    rz = 0.0
    for i in range(n):
        rz += res[i] * z[i]
    stop = tol * tol * bnorm2
    for it in range(1, maxit + 1):
        pap = 0.0
        for i in range(n):
            v = 0.0
            for q in range(ptr[i], ptr[i + 1]):
                v += vals[q] * p[cols[q]]
            ap[i] = v
            pap += p[i] * v
        if not pap > 0.0:
            return x, it, False
        alpha = rz / pap
        rr = 0.0
        for i in range(n):
            x[i] += alpha * p[i]
            res[i] -= alpha * ap[i]
            rr += res[i] * res[i]
        if rr <= stop:
            return x, it, True
        tree_solve(lrow, par, pivinv, up, res, z, y, w)
        rz_new = 0.0
        for i in range(n):
            rz_new += res[i] * z[i]
        beta = rz_new / rz
        for i in range(n):
            p[i] = z[i] + beta * p[i]
        rz = rz_new
    return x, maxit, False
