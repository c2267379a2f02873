"""Compiled kernels of the round greedy's local model (``posecrb.selection.rounds``): a chosen
candidate's potential in its ball (``posecrb.selection._ballsolve``), scaled to its exact ``H``, and
one round's greedy steps with the gains corrected by those potentials.

Compiled with numba (``cache=True``) like ``posecrb.selection._kernels``; numba's cache is keyed on
this file only, so after a change to what it calls (``_ballsolve``, ``_kernels``,
``posecrb.linalg.pathchol``) the cache of this module must be cleared too (``__pycache__/*.nbi``,
``*.nbc``).
"""
from __future__ import annotations

import math

import numpy as np

from ..linalg.pathchol import logdet_eye_plus, njit
from ._ballsolve import ball, ball_system, pcg, sift_down, tree_factor
from ._kernels import sandwich_subtract


@njit(cache=True, nogil=True)
def potential(f, ends, us, h0, poses, par, pose_rows, indptr, indices, data, loc, tol, maxit):  # pragma: no cover
    """Candidate f's potential ``Phi`` (rows, blocks, r) in its ball (``poses``, tree ``par``) for
    every block b: ``M_b[ball]^{-1} U_f`` (the ball's principal submatrix: the boundary held at
    zero) by ``pcg``, times ``(U_f^T Phi)^{-1} H_f`` with ``H_f`` exact for the same matrix
    (``h0``), which gives back the ``H_f`` the grounded boundary lowers and keeps the potential's
    shape. Returns (lrow, Phi, iterations, unconverged)."""
    nb, _, p, r = us.shape
    rpp = p // 2
    lrow, ptr, cols, where = ball_system(poses, pose_rows, indptr, indices, loc)
    nrows = ptr.shape[0] - 1
    phi = np.zeros((nrows, nb, r))
    its = 0
    bad = 0
    side_row = np.full(2, -1, np.int64)
    for t in range(min(2, poses.shape[0])):         # f's end poses settle first
        for side in range(2):
            if poses[t] == ends[f, side]:
                side_row[side] = lrow[t]
    for b in range(nb):
        vals = np.empty(where.shape[0])
        for q in range(where.shape[0]):
            vals[q] = data[b, where[q]]
        pivinv, up, ok = tree_factor(lrow, par, rpp, ptr, cols, vals)
        if not ok:                          # pragma: no cover - the tree's matrix is positive definite
            bad += r
            continue
        for c in range(r):
            rhs = np.zeros(nrows)
            for side in range(2):
                if side_row[side] >= 0:
                    for s in range(rpp):
                        rhs[side_row[side] + s] += us[b, f, side * rpp + s, c]
            x, it, ok = pcg(ptr, cols, vals, lrow, par, pivinv, up, rhs, tol, maxit)
            its += it
            bad += 0 if ok else 1
            for i in range(nrows):
                phi[i, b, c] = x[i]
        # scale: U_f^T Phi -> H_f
        loc_h = np.zeros((r, r))
        for side in range(2):
            if side_row[side] >= 0:
                for s in range(rpp):
                    for a in range(r):
                        for c in range(r):
                            loc_h[a, c] += us[b, f, side * rpp + s, a] * phi[side_row[side] + s, b, c]
        loc_h = 0.5 * (loc_h + loc_h.T)
        if r == 1:
            if loc_h[0, 0] > 0.0:
                scale = h0[b, f, 0, 0] / loc_h[0, 0]
                for i in range(nrows):
                    phi[i, b, 0] *= scale
        elif np.linalg.cond(loc_h) < 1e12:
            tr = np.linalg.solve(loc_h, 0.5 * (h0[b, f] + h0[b, f].T))
            for i in range(nrows):
                row = phi[i, b].copy()
                for c in range(r):
                    v = 0.0
                    for a in range(r):
                        v += row[a] * tr[a, c]
                    phi[i, b, c] = v
    return lrow, phi, its, bad


@njit(cache=True, nogil=True)
def round_steps(keys, hs, us, mult, ends, radius, cap, inc_ptr, inc_cand, adj_ptr, adj_to, adj_len, pose_rows,
                indptr, indices, data, take, tol, maxit):  # pragma: no cover - compiled
    """One round's ``take`` choices among the candidates of gains ``keys`` (their ``H`` per block
    ``hs`` (blocks, c, r, r), changed in place, as ``keys``; a corrected gain is
    ``posecrb.linalg.pathchol.logdet_eye_plus``'s, never below 0), greedily: the candidate of largest
    gain (ties: the first), then, unless it is the round's last, its ``potential`` in its ball (the
    poses within ``radius[f]`` of its end poses, at most ``cap`` of them, ``ball``) corrects every
    alive candidate g with both end poses in the ball: ``H_g -= C (I + H_f)^{-1} C^T``,
    ``C = U_g^T Phi_f`` per block.

    ``inc_ptr``/``inc_cand``: the candidates at each pose (CSR); the graph (adj_*) is the current
    one; ``data`` (blocks, nnz) the values of the blocks' matrices on their common CSC pattern
    (indptr, indices). Returns (chosen positions in order, [local solves, ball poses, largest ball,
    corrections, CG iterations, unconverged solves])."""
    nb, c, r, _ = hs.shape
    p = us.shape[2]
    rpp = p // 2
    n = pose_rows.shape[0]
    stats = np.zeros(6, np.int64)
    chosen = np.empty(take, np.int64)
    h0 = hs.copy()                       # the round's exact H: the balls' potentials are of its matrix
    heap = np.empty(c, np.int64)                          # a heap by (-gain, position)
    hkey = np.empty(c)
    order = np.argsort(-keys, kind="mergesort")          # stable: ties keep the first; sorted is a heap
    for i in range(c):
        heap[i] = order[i]
        hkey[i] = -keys[order[i]]
    size = c
    alive = np.ones(c, np.bool_)
    dist = np.full(n, np.inf)
    tpar = np.empty(n, np.int64)
    spos = np.empty(n, np.int64)
    loc = np.full(pose_rows.max() + 1, -1, np.int64)
    stamp = np.zeros(n, np.int64)
    sloc = np.zeros(n, np.int64)
    gstamp = np.zeros(c, np.int64)
    invs = np.empty((nb, r, r))
    cm = np.empty((r, r))
    tmp = np.empty((r, r))
    eye = np.eye(r)
    nchosen = 0
    while nchosen < take and size > 0:
        f = heap[0]
        if hkey[0] != -keys[f]:          # stale: gains only decrease
            sift_down(hkey, heap, size, -keys[f], f)
            continue
        size -= 1
        if size > 0:
            sift_down(hkey, heap, size, hkey[size], heap[size])
        alive[f] = False
        chosen[nchosen] = f
        nchosen += 1
        if nchosen == take:
            break
        poses, par = ball(ends[f, 0], ends[f, 1], radius[f], cap, adj_ptr, adj_to, adj_len, dist, tpar, spos)
        lrow, phi, its, bad = potential(f, ends, us, h0, poses, par, pose_rows, indptr, indices, data, loc, tol,
                                        maxit)
        stats[0] += 1
        stats[1] += poses.shape[0]
        stats[2] = max(stats[2], poses.shape[0])
        stats[4] += its
        stats[5] += bad
        for b in range(nb):
            invs[b] = np.linalg.inv(eye + 0.5 * (hs[b, f] + hs[b, f].T))
        sid = nchosen
        for t in range(poses.shape[0]):
            stamp[poses[t]] = sid
            sloc[poses[t]] = lrow[t]
        for t in range(poses.shape[0]):
            for q in range(inc_ptr[poses[t]], inc_ptr[poses[t] + 1]):
                g = inc_cand[q]
                if not alive[g] or gstamp[g] == sid:
                    continue
                e0, e1 = ends[g, 0], ends[g, 1]
                if stamp[e0] != sid or stamp[e1] != sid:
                    continue
                gstamp[g] = sid
                key = 0.0
                for b in range(nb):
                    for i in range(r):
                        for j in range(r):
                            cm[i, j] = 0.0
                    for a in range(p):
                        lr = sloc[e0] if a < rpp else sloc[e1]
                        if lr < 0:
                            continue
                        row = lr + a % rpp
                        for i in range(r):
                            ug = us[b, g, a, i]
                            if ug != 0.0:
                                for j in range(r):
                                    cm[i, j] += ug * phi[row, b, j]
                    sandwich_subtract(hs[b, g], cm, invs[b], tmp)
                    key += mult[b] * (math.log1p(max(hs[b, g, 0, 0], 0.0)) if r == 1
                                      else logdet_eye_plus(hs[b, g:g + 1])[0])
                keys[g] = key
                stats[3] += 1
    return chosen[:nchosen], stats
