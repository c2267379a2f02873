"""Line formats of g2o and TORO (README "Conventions", datasets/SOURCES.md).

Each record kind maps a file tag to: format family, dimension, vertex or edge,
and the number of numeric fields after the tag.
"""
from __future__ import annotations

from dataclasses import dataclass


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


RECORDS: dict[str, RecordKind] = {r.tag: r for r in [
    RecordKind("VERTEX_SE2", "g2o", 2, "vertex", 4),          # id x y theta
    RecordKind("EDGE_SE2", "g2o", 2, "edge", 11),             # i j dx dy dth + I11 I12 I13 I22 I23 I33
    RecordKind("VERTEX_SE3:QUAT", "g2o", 3, "vertex", 8),     # id x y z qx qy qz qw
    RecordKind("EDGE_SE3:QUAT", "g2o", 3, "edge", 30),        # i j x y z qx qy qz qw + 21
    RecordKind("VERTEX2", "toro", 2, "vertex", 4),            # id x y theta
    RecordKind("EDGE2", "toro", 2, "edge", 11),               # i j dx dy dth + I11 I12 I22 I33 I13 I23
    RecordKind("VERTEX3", "toro", 3, "vertex", 7),            # id x y z roll pitch yaw
    RecordKind("EDGE3", "toro", 3, "edge", 29),               # i j x y z roll pitch yaw + 21
]}

# Tags that are legal in these files but carry nothing for a pose graph: skipped
# with one summary warning (count per tag). Anything else unknown is an error.
SKIPPED_TAGS = frozenset({
    "FIX", "EQUIV", "BR",
    # landmark / point / sensor-parameter records (g2o and TORO variants)
    "VERTEX_XY", "EDGE_SE2_XY", "VERTEX_POINT_XY", "EDGE_SE2_POINT_XY", "EDGE_BEARING_SE2_XY",
    "VERTEX_TRACKXYZ", "EDGE_SE3_TRACKXYZ", "VERTEX_POINT_XYZ", "EDGE_SE3_POINT_XYZ",
    "PARAMS_SE3OFFSET", "PARAMS_CAMERACALIB", "CACHE_SE3_OFFSET", "LANDMARK", "POINT",
})

# TORO's EDGE2 stores the information matrix as I11 I12 I22 I33 I13 I23 (TORO's
# posegraph2.cpp); position in that list of each upper-triangular entry (r, c).
TORO2_INFO_ORDER = {(0, 0): 0, (0, 1): 1, (1, 1): 2, (2, 2): 3, (0, 2): 4, (1, 2): 5}
