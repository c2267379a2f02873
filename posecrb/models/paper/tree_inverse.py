"""An upper bound of the diagonal of the paper FIM's inverse, from one spanning tree.

The paper FIM (eq. 42 / 64) is a sum over edges of positive semidefinite terms, ``J_e^T W_e J_e``.
The FIM ``B`` of a spanning tree's edges alone, at the same estimate and anchor, therefore
satisfies ``B <= F`` in the Loewner order, so ``F^{-1} <= B^{-1}`` and every diagonal entry of
``F^{-1}`` is at most the same entry of ``B^{-1}``. A tree's ``J`` is square and invertible after
the anchor is removed, and ``B^{-1}`` is the covariance of a pose propagated from the anchor
along its tree path (first order, at the estimate), which has a closed form:

* every path edge adds its translation variance ``1 / tau_e`` to each translation axis (isotropic
  noise ``R_i eps`` in the world frame);
* its rotation noise, of variance ``1 / w_e`` in the paper's rotation coordinates (``c / w_e`` as a
  world-frame angle, ``c = 1`` in 2D and ``1/2`` in 3D for the basis ``E_k = G_k / sqrt 2``), adds
  to the pose's rotation coordinates, and turns everything below the edge about a pivot: the
  child's position when the edge is measured in the parent's frame (``r = R_p^T (x_c - x_p) - t``),
  the parent's when it is measured in the child's. A pose ``x_j`` below the edge moves by
  ``a x (x_j - pivot)``, which adds ``(c / w_e) (|v|^2 - v_k^2)`` (3D; in 2D the other axis'
  ``v^2``) to axis k, ``v = x_j - pivot``.

The body-frame rotation coordinates of the ``"consistent"`` variant carry a world-frame noise
unchanged by the frame (isotropic), so the rotation entries are the path's sum of ``1 / w_e``. The
sums over a path are prefix sums along the tree, taken by pointer doubling (``log2`` of the depth
vectorised passes). ``posecrb.linalg.accuracy`` turns the diagonal into a bound of the log-det's
condition (its ``spanning_tree`` tier).
"""
from __future__ import annotations

import numpy as np

from ...core.graph import PoseGraph

EPS = float(np.finfo(float).eps)


# Rounds of the vectorised Bellman-Ford relaxation before the tree falls back on scipy's Dijkstra:
# a round costs a dozen numpy calls whatever its size, so this caps its fixed cost at about the
# load of scipy's graph routines (which import scipy.sparse.linalg and scipy.linalg). Pose graphs
# take as many rounds as their shortest paths have edges: 45-162 on the 3D SE-Sync files,
# city10000 and intel, 2,686 on ais2klinik's long trajectory.
_MAX_ROUNDS = 4096


def spanning_tree(graph: PoseGraph, root: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The shortest-path tree from ``root`` with edge lengths ``1 / tau + 1 / w`` (the edge's
    translation and rotation variances): per pose its parent (-1 at ``root``) and the edge joining
    them (of parallel edges the one of largest ``tau``; -1 at ``root``). None when the graph is not
    connected. Any spanning tree gives a valid bound; paths of small variance keep the tree's
    covariances, and so the bound, close to the graph's (a breadth-first tree can run through a
    weak edge, a maximum spanning tree through long detours). Of equally short paths any one.

    Bellman-Ford in vectorised rounds (each relaxes the edges of the poses whose distance changed
    in the last one), or scipy's Dijkstra after ``_MAX_ROUNDS`` of them."""
    n = graph.n
    lo = np.minimum(graph.src, graph.dst).astype(np.int64)
    hi = np.maximum(graph.src, graph.dst).astype(np.int64)
    strongest = np.argsort(-graph.tau, kind="stable")
    strongest = strongest[lo[strongest] != hi[strongest]]
    keys, first = np.unique(lo[strongest] * n + hi[strongest], return_index=True)
    edge_of_key = strongest[first]
    with np.errstate(divide="ignore"):
        length = 1.0 / graph.tau[edge_of_key] + 1.0 / graph.rotation_weights[edge_of_key]
    length = np.minimum(length, np.finfo(float).max)      # no information: the longest, not no edge
    tree = _relaxed_tree(n, keys // n, keys % n, length, root)
    if tree is None:
        tree = _dijkstra_tree(n, keys, length, root)
    parent, via = tree
    if np.count_nonzero(parent >= 0) != n - 1:
        return None
    edge = np.where(via >= 0, edge_of_key[np.maximum(via, 0)], -1)
    return parent, edge


def _relaxed_tree(n: int, lo: np.ndarray, hi: np.ndarray, length: np.ndarray,
                  root: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Bellman-Ford from ``root`` over the undirected edges ``(lo, hi)``: per vertex its parent and
    the index of the edge to it (-1 where unreached), or None after ``_MAX_ROUNDS`` rounds."""
    m = lo.size
    tail = np.concatenate([lo, hi])
    order = np.argsort(tail, kind="stable")
    tail, head, via_of = tail[order], np.concatenate([hi, lo])[order], np.tile(np.arange(m), 2)[order]
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(tail, minlength=n), out=indptr[1:])
    dist = np.full(n, np.inf)
    dist[root] = 0.0
    parent = np.full(n, -1, dtype=np.int64)
    via = np.full(n, -1, dtype=np.int64)
    changed = np.array([root])
    for _ in range(_MAX_ROUNDS):
        if changed.size == 0:
            return parent, via
        starts = indptr[changed]
        counts = indptr[changed + 1] - starts
        slots = np.repeat(starts - (np.cumsum(counts) - counts), counts) + np.arange(int(counts.sum()))
        a, b, e = tail[slots], head[slots], via_of[slots]
        with np.errstate(over="ignore"):      # two edges without information: unreached, no bound
            reach = dist[a] + length[e]
        better = reach < dist[b]
        a, b, e, reach = a[better], b[better], e[better], reach[better]
        best = np.lexsort((reach, b))                                   # per head, the shortest first
        keep = np.ones(best.size, dtype=bool)
        keep[1:] = b[best[1:]] != b[best[:-1]]
        best = best[keep]
        changed = b[best]
        dist[changed] = reach[best]
        parent[changed] = a[best]
        via[changed] = e[best]
    return None


def _dijkstra_tree(n: int, keys: np.ndarray, length: np.ndarray, root: int) -> tuple[np.ndarray, np.ndarray]:
    """``_relaxed_tree``'s result by scipy's Dijkstra (for paths of many edges)."""
    from scipy.sparse import csr_matrix  # noqa: PLC0415 -- loaded with the FIM already
    from scipy.sparse.csgraph import dijkstra  # noqa: PLC0415 -- lazy: start-up time

    # csgraph reads an explicit zero as no edge
    adj = csr_matrix((np.maximum(length, np.finfo(float).tiny), (keys // n, keys % n)), shape=(n, n))
    _, pred = dijkstra(adj, directed=False, indices=root, return_predecessors=True)
    parent = np.asarray(pred, dtype=np.int64)
    parent[parent < 0] = -1
    child = np.flatnonzero(parent >= 0)
    via = np.full(n, -1, dtype=np.int64)
    p = parent[child]
    via[child] = np.searchsorted(keys, np.minimum(child, p) * n + np.maximum(child, p))
    return parent, via


def tree_inverse_diagonal(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int,
                          rotation_weight: str = "eq59", variant: str = "consistent") -> np.ndarray | None:
    """An upper bound of ``diag(F^{-1})`` for the anchored paper FIM ``F`` at ``(rot, trans)``:
    the exact diagonal of the inverse of a spanning tree's FIM (``spanning_tree``) (module docstring),
    rows in the FIM's ``"blocks"`` layout (the free poses' translations, then their rotations).

    Infinite entries where a tree edge carries no information. None where the closed form does not
    apply: the ``"eq64"`` variant in 3D (its rotation coordinates of different poses are summed
    without their frames) or a disconnected graph. ``rot`` is unused beyond the checks: the
    isotropic noise makes the covariance independent of the frames.

    Examples
    --------
    >>> import numpy as np, posecrb
    >>> from posecrb.models.paper.fim import paper_fim
    >>> g = posecrb.load("intel")
    >>> z = tree_inverse_diagonal(g, g.vertex_rot, g.vertex_trans, 0)
    >>> exact = np.linalg.inv(paper_fim(g, g.vertex_rot, g.vertex_trans, 0).matrix.toarray()).diagonal()
    >>> bool(np.all(exact <= z))
    True
    """
    d = graph.dim
    if variant == "eq64" and d == 3:
        return None
    rot, trans = graph.check_estimate(rot, trans)
    tree = spanning_tree(graph, anchor)
    if tree is None:
        return None
    parent, edge = tree
    w = graph.rotation_weights_by(rotation_weight)
    child = np.flatnonzero(parent >= 0)
    e, p = edge[child], parent[child]
    # the pivot the edge's rotation noise turns the subtree about (module docstring)
    pivot = np.where((graph.src[e] == p)[:, None], trans[child], trans[p])
    with np.errstate(divide="ignore"):
        rot_var = 1.0 / w[e]
        trans_var = 1.0 / graph.tau[e]
    angle_var = rot_var * (1.0 if d == 2 else 0.5)
    # per pose, what its tree edge adds; summed along each path below
    n = graph.n
    terms = np.zeros((n, 3 + 3 * d))
    terms[child, 0] = angle_var
    terms[child, 1] = rot_var
    terms[child, 2] = trans_var
    terms[child, 3:3 + d] = angle_var[:, None] * pivot
    terms[child, 3 + d:3 + 2 * d] = angle_var[:, None] * np.abs(pivot)
    terms[child, 3 + 2 * d:] = angle_var[:, None] * pivot ** 2
    sums, passes = _path_sums(terms, parent, anchor)
    a0, r0, t0 = sums[:, 0], sums[:, 1], sums[:, 2]
    a1, a1abs, a2 = sums[:, 3:3 + d], sums[:, 3 + d:3 + 2 * d], sums[:, 3 + 2 * d:]
    # per axis k: sum_e (c / w_e) (x_k - pivot_k)^2, expanded; the expansion cancels, so the
    # rounding allowance is relative to its terms' magnitudes (the sums of positive terms take
    # ``passes`` roundings each)
    x = trans
    with np.errstate(over="ignore", invalid="ignore"):
        spread = a0[:, None] * x ** 2 - 2.0 * x * a1 + a2
        scale = a0[:, None] * x ** 2 + 2.0 * np.abs(x) * a1abs + a2
        spread = np.maximum(spread, 0.0) + (passes + 6) * EPS * scale
        if d == 2:
            axis = spread[:, ::-1]                                       # x moves with the y lever
        else:
            # |v|^2 - v_k^2 as the other two axes' sum: one rounding of two nonnegative terms (a
            # difference from the full sum would cancel where axis k dominates)
            axis = np.roll(spread, -1, axis=1) + np.roll(spread, -2, axis=1)
        grow = 1.0 + (passes + 4) * EPS
        trans_diag = (axis + t0[:, None]) * grow
        rot_diag = np.repeat(r0[:, None], 1 if d == 2 else 3, axis=1) * grow
    # an infinite variance on the path (an edge without information) leaves no bound: inf, where
    # the expansion above gave inf - inf
    trans_diag[~np.isfinite(trans_diag)] = np.inf
    rot_diag[~np.isfinite(rot_diag)] = np.inf
    free = np.delete(np.arange(n), anchor)
    return np.concatenate([trans_diag[free].ravel(), rot_diag[free].ravel()])


def _path_sums(terms: np.ndarray, parent: np.ndarray, root: int) -> tuple[np.ndarray, int]:
    """Per pose, the sum of ``terms`` over its tree path to ``root`` (itself included, ``root``'s
    own row zero), by pointer doubling; and the number of passes it took."""
    up = np.where(parent >= 0, parent, root)
    sums = terms.copy()
    sums[root] = 0.0
    passes = 0
    while np.any(up != root):
        sums = sums + sums[up]
        up = up[up]
        passes += 1
    return sums, passes


__all__ = ["spanning_tree", "tree_inverse_diagonal"]
