"""What a line format is: its record kinds (tag, family, dimension, vertex or edge, field count)
and, per format, how numeric fields become rotations and information matrices
(docs/design.md#formats). The tables themselves live with each format (``g2o.py``,
``toro.py``); ``formats.py`` registers them.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..core.graph import PoseGraph


@dataclass(frozen=True)
class RecordKind:
    tag: str
    family: str   # "g2o" | "toro"
    dim: int
    kind: str     # "vertex" | "edge"
    fields: int   # numeric fields after the tag (the ids included)

    @property
    def n_ids(self) -> int:
        """Leading integer id fields: 1 (vertex id) or 2 (edge endpoints)."""
        return 1 if self.kind == "vertex" else 2


# (path, record kind, values after the ids, 1-based line numbers, normalise quaternions)
# -> (rotations (k, d, d), information upper triangles (k, q(q+1)/2) row by row in g2o order)
EdgeDecoder = Callable[[str, RecordKind, np.ndarray, np.ndarray, bool], tuple[np.ndarray, np.ndarray]]
# (path, record kind, values after the id, 1-based line numbers) -> rotations (k, d, d)
VertexDecoder = Callable[[str, RecordKind, np.ndarray, np.ndarray], np.ndarray]
# (graph, path, vertex rotations or None, vertex translations or None) -> None
Writer = Callable[["PoseGraph", str, "np.ndarray | None", "np.ndarray | None"], None]


@dataclass(frozen=True)
class Format:
    """A pose-graph file format: its tags, the decoders of its fields, its writer.

    Reading is shared (``posecrb.io.reader``): translations are always the first d values
    after the ids; a format says how the rest becomes rotations and information matrices.
    ``suffixes`` name the files ``posecrb.io.save`` writes in this format; reading never looks
    at the suffix (the tags decide, ``sniff``).
    """

    name: str
    suffixes: tuple[str, ...]
    records: Mapping[str, RecordKind]
    decode_edges: EdgeDecoder
    decode_vertices: VertexDecoder
    write: Writer

    def sniff(self, tags: Iterable[str]) -> bool:
        """Whether any of ``tags`` (a file's record tags) belongs to this format."""
        return any(tag in self.records for tag in tags)


# Tags that are legal in these files but carry nothing for a pose graph: skipped
# with one summary warning (count per tag). Anything else unknown is an error.
SKIPPED_TAGS = frozenset({
    "FIX", "EQUIV", "BR",
    # landmark / point / sensor-parameter records (g2o and TORO variants)
    "VERTEX_XY", "EDGE_SE2_XY", "VERTEX_POINT_XY", "EDGE_SE2_POINT_XY", "EDGE_BEARING_SE2_XY",
    "VERTEX_TRACKXYZ", "EDGE_SE3_TRACKXYZ", "VERTEX_POINT_XYZ", "EDGE_SE3_POINT_XYZ",
    "PARAMS_SE3OFFSET", "PARAMS_CAMERACALIB", "CACHE_SE3_OFFSET", "LANDMARK", "POINT",
})
