"""Compiled kernel of the timeline: batched rank-one updates of Cholesky factors with one fixed
pattern, along elimination-tree paths, returning each update's log-determinant increment.

For ``P A P^T = L L^T`` and a vector ``v``, the update ``A + v v^T`` (Gill, Golub, Murray and
Saunders 1974, method C1, as in ``posecrb.linalg.pathchol``) rewrites only the columns on the
elimination-tree path of v's nonzeros. Column j's diagonal grows by the factor ``sqrt(1 + t_j^2)``
with ``t_j = w_j / l_jj`` (w the partly transformed vector), so

    log det(A + v v^T) - log det A = sum_j log1p(t_j^2) = log1p(prod_j (1 + t_j^2) - 1),

the matrix determinant lemma read off the update itself, with no separate solve (the product is
accumulated minus one, ``g <- g + t^2 + g t^2``, a sum of positive terms, so a small increment keeps
its relative accuracy; one log per update instead of one per column). The updates of
one batch share one traversal of the union of their paths (Davis and Hager's multiple-rank
update): column j applies them in order, each seeing the column the previous one left, which is
exactly the sequential order, so every update's increment is its sequential one. Several factors
with the same pattern (the translation and rotation Laplacians of one graph, say) are updated in
the same traversal: their values are the columns of ``lval``.
"""
from __future__ import annotations

import numpy as np

from ..linalg.pathchol import _reach, njit


@njit(cache=True, nogil=True)
def path_updates(indptr, indices, lval, parent, rows, vals, fam, bptr, mark, work):  # pragma: no cover - compiled
    """Apply the batches of rank-one updates in order; return each update's log-det increment.

    indptr, indices: the CSC pattern of the lower factors (diagonal first in every column);
    lval (nnz, F): the values of F factors with that pattern, updated in place; parent (n,): the
    elimination tree; rows (V, p): permuted rows of each update vector (-1: no entry); vals (V, p)
    its values; fam (V,): the factor (column of lval) it updates; bptr (B + 1,): batch b is the
    updates ``bptr[b]:bptr[b + 1]``, at most ``work.shape[0]`` of them; mark (n,) and work (R, n)
    all zero on entry, and left so.
    """
    nv, p = rows.shape
    nf = lval.shape[1]
    inc = np.zeros(nv)
    grow = np.zeros(nv)          # prod_j (1 + t_j^2) - 1 so far, flushed into inc before it overflows
    r_max = work.shape[0]
    starts = np.empty(r_max * p, np.int64)
    cs = np.empty(r_max)
    ic = np.empty(r_max)
    sn = np.empty(r_max)
    act = np.empty(r_max, np.int64)
    actf = np.empty(r_max, np.int64)
    diag = np.empty(nf)
    stamp = mark.max()
    for b in range(bptr.shape[0] - 1):
        v0 = bptr[b]
        r = bptr[b + 1] - v0
        ns = 0
        for c in range(r):
            for a in range(p):
                row = rows[v0 + c, a]
                if row >= 0:
                    starts[ns] = row
                    ns += 1
                    work[c, row] += vals[v0 + c, a]
        if ns == 0:
            continue
        stamp += 1
        path = _reach(parent, starts[:ns], mark, stamp)
        for j in path:
            q0 = indptr[j]
            for f in range(nf):
                diag[f] = lval[q0, f]
            na = 0
            for c in range(r):
                wj = work[c, j]
                if wj == 0.0:
                    continue
                f = fam[v0 + c]
                t = wj / diag[f]
                t2 = t * t
                g = grow[v0 + c]
                g = g + t2 + g * t2                # (1 + g)(1 + t2) - 1: positive terms, no cancellation
                if g > 1e200:
                    inc[v0 + c] += np.log1p(g)
                    g = 0.0
                grow[v0 + c] = g
                root = np.sqrt(1.0 + t2)
                cs[na] = root
                ic[na] = 1.0 / root
                sn[na] = t
                act[na] = c
                actf[na] = f
                na += 1
                diag[f] *= root
                work[c, j] = 0.0
            if na == 0:
                continue
            for f in range(nf):
                lval[q0, f] = diag[f]
            q1 = indptr[j + 1]
            if na == 1:
                c, f = act[0], actf[0]
                s0, c0, i0 = sn[0], cs[0], ic[0]
                for q in range(q0 + 1, q1):
                    i = indices[q]
                    lij = (lval[q, f] + s0 * work[c, i]) * i0
                    lval[q, f] = lij
                    work[c, i] = c0 * work[c, i] - s0 * lij
                continue
            # the updates in order, two per pass over the column: the two rotations of one entry
            # chain (the second reads what the first wrote), entries are independent, so a short
            # chain per entry keeps the loop fed while sharing the index and value loads
            k = 0
            while k + 1 < na:
                ca, fa, sa, cca, ia = act[k], actf[k], sn[k], cs[k], ic[k]
                cb, fb, sb, ccb, ib = act[k + 1], actf[k + 1], sn[k + 1], cs[k + 1], ic[k + 1]
                for q in range(q0 + 1, q1):
                    i = indices[q]
                    lij = (lval[q, fa] + sa * work[ca, i]) * ia
                    lval[q, fa] = lij
                    work[ca, i] = cca * work[ca, i] - sa * lij
                    lij = (lval[q, fb] + sb * work[cb, i]) * ib
                    lval[q, fb] = lij
                    work[cb, i] = ccb * work[cb, i] - sb * lij
                k += 2
            if k < na:
                c, f, s, ck, ik = act[k], actf[k], sn[k], cs[k], ic[k]
                for q in range(q0 + 1, q1):
                    i = indices[q]
                    lij = (lval[q, f] + s * work[c, i]) * ik
                    lval[q, f] = lij
                    work[c, i] = ck * work[c, i] - s * lij
    for j in range(mark.shape[0]):
        mark[j] = 0
    for v in range(nv):
        inc[v] += np.log1p(grow[v])
    return inc
