"""What a selection returns (``SelectionResult``) and the pruned graph it keeps (fixed + selected edges)."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..core.errors import InternalError
from ..core.graph import PoseGraph
from ..io import write_g2o
from .budget import EdgeSplit
from .certificate import RatioCertificate


@dataclass(frozen=True)
class SelectionResult:
    """A selection: the K candidate edges kept (``selected``, file order), their objective value
    next to the values with the fixed edges only and with every candidate, the ratio certificate,
    and what the method did (``rounding``, ``order``, ``stats``, ``times`` in seconds)."""

    dataset: str
    path: str | None
    dim: int
    poses: int
    edges: int
    anchor_id: int
    objective: str
    method: str
    budget: int
    budget_spec: str
    split: EdgeSplit
    selected: np.ndarray          # edge indices (file order)
    selected_ids: np.ndarray      # (K, 2) pose ids
    value: float
    base_value: float
    full_value: float             # every candidate kept
    certificate: RatioCertificate
    rounding: str | None
    order: np.ndarray | None      # greedy: the edges in the order chosen
    seed: int
    stats: dict
    estimate: dict | None
    times: dict

    @property
    def upper_bound(self) -> float | None:
        return self.certificate.upper_bound

    @property
    def certified_ratio(self) -> float | None:
        """(value - base) / (upper_bound - base): the fraction of the best achievable gain
        guaranteed to be reached (1 = provably optimal)."""
        return self.certificate.ratio(self.value, self.base_value)

    @property
    def kept_edges(self) -> np.ndarray:
        return np.union1d(self.split.fixed, self.selected)

    def to_dict(self) -> dict:
        c = self.certificate
        return {
            "dataset": self.dataset, "path": self.path, "dim": self.dim, "poses": self.poses,
            "edges": self.edges, "anchor": self.anchor_id,
            "objective": self.objective, "method": self.method,
            "budget": self.budget, "budget_spec": self.budget_spec,
            "fixed": {"rule": self.split.rule, "edges": int(self.split.fixed.size),
                      "added_for_connectivity": [[int(a), int(b), int(e)] for (a, b), e in
                                                 zip(self._ids(self.split.connectivity), self.split.connectivity)]},
            "candidates": int(self.split.candidates.size),
            "selected": [[int(a), int(b), int(e)] for (a, b), e in zip(self.selected_ids, self.selected)],
            "value": self.value, "base_value": self.base_value, "full_value": self.full_value,
            "upper_bound": c.upper_bound, "certified_ratio": self.certified_ratio,
            "bounds": {"relaxation": c.relaxation_bound, "submodular": c.submodular_bound,
                       "relaxed_value": c.relaxed_value, "iterations": c.iterations,
                       "converged": c.converged, "step": c.step},
            "order": None if self.order is None else [int(e) for e in self.order],
            "rounding": self.rounding, "seed": self.seed, "stats": self.stats, "estimate": self.estimate,
            "times": self.times,
        }

    def to_row(self) -> dict:
        """``to_dict()`` without the per-edge lists (``selected``, ``order``): one row of a table."""
        return {k: v for k, v in self.to_dict().items() if k not in ("selected", "order")}

    def _ids(self, edges: np.ndarray) -> np.ndarray:
        if edges.size == 0:
            return self.selected_ids[:0]
        if self._id_pairs is None:  # select_edges always sets it
            raise InternalError("selection result without its edges' id pairs")
        return self._id_pairs[edges]

    _id_pairs: np.ndarray | None = field(default=None, repr=False)



def pruned_graph(graph: PoseGraph, keep: np.ndarray) -> PoseGraph:
    """The graph with only the edges ``keep`` (indices, file order); vertices and estimate kept."""
    keep = np.sort(np.asarray(keep, dtype=np.int64))
    lines = graph.edge_lines[keep] if graph.edge_lines is not None else None
    return replace(graph, src=graph.src[keep], dst=graph.dst[keep], rot=graph.rot[keep],
                   trans=graph.trans[keep], info=graph.info[keep], edge_lines=lines, sha256=None)


def write_pruned(graph: PoseGraph, result: SelectionResult, path: str) -> PoseGraph:
    """Write fixed + selected edges (and every vertex) as g2o, atomically (posecrb.io.write_g2o)."""

    pruned = pruned_graph(graph, result.kept_edges)
    write_g2o(pruned, path)
    return pruned
