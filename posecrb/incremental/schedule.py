"""The order in which a pose graph grows: steps, attaching edges, loop closures and bridges.

Poses are added in id order (internal index order, docs/design.md#ids). Step t adds pose t and
every edge between t and an older pose; the prefix after step t holds the t + 1 poses with the
smallest ids and the edges among them, anchored at pose 0. Within a step the edge to the largest
older id (the first in file order if there are parallel ones) attaches the new pose; the others are
loop closures, processed in file order.

An edge is a *bridge* when, in this processing order, it joins two poses not yet connected (the
attaching edge always is; a loop closure is when it reconnects a prefix that was split). The
bridges form a spanning forest F built greedily in processing order (Kruskal with the processing
rank as weight). For every step t the bridges not yet added are bridges of ``G_t + (F - G_t)``:
take the latest-added one on a cycle, all the rest of the cycle was present when it was added,
so it was no bridge. Hence the future poses hang off the prefix as trees joined to it by single
edges, which is what lets the timeline keep one full-size matrix whose future part is closed form
(``posecrb.incremental.compute``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.graph import PoseGraph


@dataclass(frozen=True, eq=False)
class Schedule:
    """Processing order of the edges and the per-step structure of a growing graph.

    ``order`` (m,): edge indices in processing order; ``step`` (m,): each edge's step (the index of
    its newer pose); ``attach`` (m,): the edge attaches its step's pose; ``bridge`` (m,): the edge
    joins two components when it is added; ``components`` (n,): number of connected components of
    the prefix after each step (entry 0: the single pose); ``edges`` (n,): edges in each prefix;
    ``closures`` (n,): loop closures added at each step; ``roots`` (r,): the smallest pose of every
    component of the whole graph but pose 0's (joined to pose 0 by a virtual unit edge so that
    the full-size matrices are positive definite even when the whole graph is disconnected).
    """

    n: int
    order: np.ndarray
    step: np.ndarray
    attach: np.ndarray
    bridge: np.ndarray
    components: np.ndarray
    edges: np.ndarray
    closures: np.ndarray
    roots: np.ndarray

    @property
    def closure_edges(self) -> np.ndarray:
        """Loop closures (edge indices) in processing order."""
        return self.order[~self.attach[self.order]]

    @property
    def connected(self) -> np.ndarray:
        """(n,) the prefix after each step is connected."""
        return self.components == 1


def schedule(graph: PoseGraph) -> Schedule:
    """The processing order and bridges of ``graph`` (vectorised; one minimum spanning forest)."""
    from scipy.sparse import coo_matrix  # noqa: PLC0415 -- lazy: start-up time
    from scipy.sparse.csgraph import connected_components, minimum_spanning_tree  # noqa: PLC0415

    n, m = graph.n, graph.m
    lo = np.minimum(graph.src, graph.dst).astype(np.int64)
    hi = np.maximum(graph.src, graph.dst).astype(np.int64)
    file_pos = np.arange(m)
    by_step = np.lexsort((file_pos, -lo, hi))                  # step, largest older id, file order
    first = np.ones(m, dtype=bool)
    first[1:] = hi[by_step][1:] != hi[by_step][:-1]
    attach = np.zeros(m, dtype=bool)
    attach[by_step[first]] = True
    order = np.lexsort((file_pos, ~attach, hi))                 # step, attaching edge first, file order
    rank = np.empty(m, dtype=np.int64)
    rank[order] = np.arange(m)

    # Bridges: the minimum spanning forest with the processing rank as weight (distinct weights:
    # unique, and exactly the edges Kruskal adds in processing order). Of parallel edges only the
    # first can be one, so each pair keeps its first edge (the sparse matrix would sum duplicates).
    key = lo * n + hi
    by_pair = np.lexsort((rank, key))
    first_of_pair = np.ones(m, dtype=bool)
    first_of_pair[1:] = key[by_pair][1:] != key[by_pair][:-1]
    cand = by_pair[first_of_pair]
    bridge = np.zeros(m, dtype=bool)
    if cand.size:
        weights = coo_matrix((rank[cand] + 1.0, (lo[cand], hi[cand])), shape=(n, n)).tocsr()
        forest = minimum_spanning_tree(weights).tocoo()
        bridge[order[np.rint(forest.data).astype(np.int64) - 1]] = True

    per_step_bridges = np.bincount(hi[bridge], minlength=n)
    components = np.arange(1, n + 1) - np.cumsum(per_step_bridges)
    edges = np.cumsum(np.bincount(hi, minlength=n))
    closures = np.bincount(hi[~attach], minlength=n)
    if n and components[-1] > 1:
        _, label = connected_components(coo_matrix((np.ones(m), (lo, hi)), shape=(n, n)), directed=False)
        first_pose = np.full(int(label.max()) + 1, n, dtype=np.int64)
        np.minimum.at(first_pose, label, np.arange(n))
        roots = np.sort(first_pose[first_pose != first_pose[label[0]]])
    else:
        roots = np.zeros(0, dtype=np.int64)
    return Schedule(n=n, order=order, step=hi, attach=attach, bridge=bridge, components=components,
                    edges=edges, closures=closures, roots=roots)
