"""Estimate files: the poses another program computed, in the formats optimizers and evaluation tools write.

``read_estimate_file(path)`` reads one file and says what it holds (``EstimateFile``);
``EstimateFile.poses_for(graph)`` puts its rows on the graph's pose ids (docs/design.md#estimate-files).
Formats, read from the content (``format="auto"``) or named:

* ``g2o`` / ``toro``: the VERTEX lines of a g2o or TORO file (what g2o, GTSAM's ``writeG2o`` and
  ``posecrb solve --out`` write); edge lines and the skipped records are ignored, so a graph file is
  its own estimate;
* ``ceres``: the plain ``id x y yaw`` (2D) and ``id x y z qx qy qz qw`` (3D) lines of Ceres' pose-graph
  examples;
* ``tum``: ``timestamp x y z qx qy qz qw`` (TUM RGB-D, evo);
* ``kitti``: 12 numbers per line, the row-major 3x4 matrix ``[R | t]`` (KITTI odometry, evo).

Ceres' 3D lines and TUM lines have the same shape: the first column is taken as pose ids when every
value is an integer and the set equals the graph's ids, else as TUM timestamps (rows in order). TUM
and KITTI rows carry no pose ids: row k is the pose with the k-th smallest id (``rows="order"``), or,
for TUM, the timestamp is the id (``rows="timestamps"``).

Precision: every number's *quantum* (a unit of its last written digit, ``10^(exponent - decimals)``;
zero for an integer written without a point or exponent) is kept, so tolerances follow from what the
file can represent (six significant digits from GTSAM's writer, seventeen from posecrb's). Rotations
are checked against it: a quaternion's norm, a matrix's orthonormality and its determinant within the
rounding its digits allow are projected onto the rotations (with a warning when the deviation exceeds
double precision's); beyond that they are an error naming the line.
"""
from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..core.choices import ESTIMATE_FORMATS, ROW_ORDERS, EstimateFormat, RowOrder
from ..core.errors import ParseError
from ..core.inputs import read_input
from ..lie.so import NotRotations, check_rotations
from .numeric_text import ID_MAX_DIGITS, NumericTable, integer_ids, numbers, scan_numeric
from .records import SKIPPED_TAGS
from .rotations import euler_to_rot, quat_to_rot

if TYPE_CHECKING:
    from ..core.graph import PoseGraph

log = logging.getLogger("posecrb")


# VERTEX records: tag -> (format, dimension, numeric fields after the id)
VERTEX_RECORDS = {"VERTEX_SE2": ("g2o", 2, 3), "VERTEX_SE3:QUAT": ("g2o", 3, 7),
                  "VERTEX2": ("toro", 2, 3), "VERTEX3": ("toro", 3, 6)}
EDGE_TAGS = frozenset({"EDGE_SE2", "EDGE_SE3:QUAT", "EDGE2", "EDGE3"})
# Headerless numeric lines: fields per line -> format
NUMERIC_SHAPES = {4: "ceres", 8: "ceres-or-tum", 12: "kitti"}

# A rotation number written with quantum u is off by at most u / 2 from what the writer had; a
# quaternion's norm or a matrix's orthonormality defect is a sum of a few such errors. A defect
# up to this many quanta (plus double precision's own rounding) is rounding of the digits, and is
# projected away; beyond it the row is not a rotation.
ROUNDING_QUANTA = 8.0
# Double precision's rounding of a rotation computed in floating point: deviations below this are
# projected silently (no warning).
FLOAT_ROTATION_TOL = 64 * np.finfo(float).eps
# 2D graphs read 3D rows (TUM, KITTI, Ceres 3D) as planar poses: z and the tilt of the rotation
# (its z-row and z-column off the axis) must vanish within the same rounding.


@dataclass(frozen=True, eq=False)
class EstimateFile:
    """The poses of an estimate file as written, before they are matched with a graph.

    Attributes
    ----------
    path : str
        The file.
    format : str
        ``"g2o"``, ``"toro"``, ``"ceres"``, ``"tum"`` or ``"kitti"``.
    dim : int
        2 or 3: the dimension of the rows as written (TUM and KITTI rows are 3D).
    keys : numpy.ndarray
        (k,) the first column as read: pose ids (int64) for g2o, TORO and Ceres, timestamps
        (float64) for TUM; empty for KITTI.
    rot, trans : numpy.ndarray
        (k, dim, dim) rotations (checked and projected, see the module docstring) and (k, dim)
        translations, in file order.
    lines : numpy.ndarray
        (k,) the 1-based line number of each row.
    rotation_quantum, translation_quantum : numpy.ndarray
        (k,) the largest quantum of each row's rotation numbers and of its translation numbers.
    ambiguous : bool
        8-column lines whose first column holds distinct integers: Ceres 3D when those are the
        graph's ids, TUM rows in order otherwise (decided by ``poses_for``).
    """

    path: str
    format: str
    dim: int
    keys: np.ndarray
    rot: np.ndarray
    trans: np.ndarray
    lines: np.ndarray
    rotation_quantum: np.ndarray
    translation_quantum: np.ndarray
    ambiguous: bool = False

    @property
    def rows(self) -> int:
        return int(self.lines.size)

    def poses_for(self, graph: PoseGraph, *, rows: RowOrder = "order") -> EstimatePoses:
        """The rows as the poses of ``graph``, row k for the pose with the k-th smallest id.

        g2o, TORO and Ceres rows are matched by id: every id of the graph exactly once, no
        other. TUM and KITTI rows are taken in file order (``rows="order"``: as many rows as
        poses), or, TUM only, by timestamp as pose id (``rows="timestamps"``). A 2D graph takes
        3D rows as planar poses. Errors are ``ParseError`` naming the file and, where there is
        one, the line."""
        if rows not in ROW_ORDERS:
            raise ParseError(self.path, None, f"rows={rows!r} is not one of {', '.join(ROW_ORDERS)}")
        if rows == "timestamps" and self.format != "tum":
            raise ParseError(self.path, None, f"timestamps as pose ids apply to TUM files; this one is {self.format}")
        ids = graph.ids
        if self.dim < graph.dim:
            raise ParseError(self.path, int(self.lines[0]), f"{_shape_name(self)} rows are 2D poses; the graph is 3D")
        if self.ambiguous and rows == "order" and not np.array_equal(np.sort(self.keys), ids):
            if self.rows != ids.size:
                missing = np.setdiff1d(ids, self.keys)
                extra = np.setdiff1d(self.keys, ids)
                which = f"id {missing[0]} is missing" if missing.size else f"id {extra[0]} is not a pose of the graph"
                raise ParseError(self.path, None, f"has {self.rows} rows for the graph's {ids.size} poses: its first "
                                 f"column is not the graph's ids ({which}), so its lines are TUM rows in order, one "
                                 "per pose; --estimate-format ceres reads the first column as pose ids")
            return replace(self, format="tum", keys=self.keys.astype(float), ambiguous=False).poses_for(graph)
        if self.format in ("tum", "kitti") and rows == "order":
            if self.rows != ids.size:
                raise ParseError(self.path, None, f"has {self.rows} {self.format.upper()} row(s) for the graph's "
                                 f"{ids.size} poses ({self.format.upper()} rows carry no pose ids: row k is the "
                                 "pose with the k-th smallest id, so the counts must match)")
            order = np.arange(self.rows)
        else:
            keys = self.keys
            if self.format == "tum":
                keys = _integral_keys(self, "timestamps as pose ids")
            order = _matchinteger_ids(self, keys, ids)
        rot, trans = self.rot[order], self.trans[order]
        rq, tq = self.rotation_quantum[order], self.translation_quantum[order]
        if graph.dim != self.dim:
            rot, trans = _planar(self, order, rot, trans, rq, tq)
        return EstimatePoses(rot=rot, trans=trans, rotation_quantum=rq, translation_quantum=tq,
                             format=self.format, path=self.path)


@dataclass(frozen=True, eq=False)
class EstimatePoses:
    """An estimate file's poses on a graph: row k is the pose with the k-th smallest id, and the
    quanta say how precisely each was written."""

    rot: np.ndarray
    trans: np.ndarray
    rotation_quantum: np.ndarray
    translation_quantum: np.ndarray
    format: str
    path: str


def read_estimate_file(path: str | os.PathLike[str], *, format: EstimateFormat = "auto") -> EstimateFile:
    """The poses of an estimate file (module docstring), read through the input layer.

    Parameters
    ----------
    path : str or os.PathLike
        The file (gzip-compressed files are read transparently).
    format : {"auto", "g2o", "toro", "ceres", "tum", "kitti"}
        ``"auto"`` reads the format from the content; a name insists on it.

    Raises
    ------
    ParseError
        ``path:line: reason`` for an empty file, a line of another shape, a non-number, a
        non-finite value, an id that is not a non-negative integer, a duplicate id, a zero
        quaternion or a row that is not a rotation within its digits' rounding.
    """
    if format not in ESTIMATE_FORMATS:
        raise ParseError(os.fspath(path), None, f"format={format!r} is not one of {', '.join(ESTIMATE_FORMATS)}")
    inp = read_input(path)
    table = scan_numeric(inp.data, inp.path)
    if table.tagged:
        found = _read_vertices(table)
    else:
        found = _read_numeric(table)
    if format != "auto" and not _compatible(found, format):
        raise ParseError(found.path, int(found.lines[0]), f"holds {_shape_name(found)} lines, not {format}")
    if format == "tum" and found.format == "ceres":
        return replace(found, format="tum", keys=found.keys.astype(float), ambiguous=False)
    if format == "ceres" and found.format == "tum":
        if found.keys.dtype.kind != "i":
            raise ParseError(found.path, int(found.lines[0]), "the first column is not integer pose ids: not Ceres")
    return replace(found, ambiguous=found.ambiguous and format == "auto")


# ---------------------------------------------------------------------------------------------
# g2o / TORO vertex lines

def _read_vertices(table: NumericTable) -> EstimateFile:
    lead = np.array([t.decode(errors="replace") for t in table.tokens[table.first]])
    tags, inverse = np.unique(lead, return_inverse=True)
    unknown = [str(t) for t in tags if t not in VERTEX_RECORDS and t not in EDGE_TAGS and t not in SKIPPED_TAGS]
    if unknown:
        k = int(np.flatnonzero(lead == unknown[0])[0])
        what = "a numeric line among g2o/TORO records" if unknown[0][:1].isdigit() or unknown[0][:1] in "+-." \
            else f"unknown record {unknown[0]!r}"
        raise ParseError(table.path, int(table.line[k]), what)
    vertex_tags = [str(t) for t in tags if t in VERTEX_RECORDS]
    if not vertex_tags:
        raise ParseError(table.path, None, "has no VERTEX lines: no poses to read")
    kinds = {VERTEX_RECORDS[t][:2] for t in vertex_tags}
    if len(kinds) > 1:
        k = int(np.flatnonzero(lead == vertex_tags[-1])[0])
        raise ParseError(table.path, int(table.line[k]), f"mixes vertex records {', '.join(vertex_tags)}")
    tag = vertex_tags[0]
    fmt, dim, fields = VERTEX_RECORDS[tag]
    rows = np.flatnonzero(lead == tag)
    _check_counts(table, rows, fields + 2, tag)
    ids = integer_ids(table, rows, f"{tag}: vertex id", column=1)
    vals, quanta = numbers(table, rows, slice(2, 2 + fields), tag)
    lines = table.line[rows]
    trans = vals[:, :dim]
    tq = quanta[:, :dim].max(axis=1)
    rq = quanta[:, dim:].max(axis=1)
    if tag == "VERTEX_SE2" or tag == "VERTEX2":
        rot = _angle_rotations(vals[:, 2])
    elif tag == "VERTEX3":
        rot = euler_to_rot(vals[:, 3], vals[:, 4], vals[:, 5])
    else:
        # vertex quaternions are normalised, as the graph reader does (any non-zero quaternion)
        rot = _quaternion_rotations(table.path, lines, vals[:, 3:7], rq, normalise_any=True)
    _check_unique(table.path, ids, lines)
    return EstimateFile(table.path, fmt, dim, ids, rot, trans, lines, rq, tq)


# ---------------------------------------------------------------------------------------------
# headerless numeric lines: Ceres, TUM, KITTI

def _read_numeric(table: NumericTable) -> EstimateFile:
    counts = table.count
    width = int(counts[0])
    odd = np.flatnonzero(counts != width)
    if odd.size:
        k = int(odd[0])
        raise ParseError(table.path, int(table.line[k]), f"has {counts[k]} fields where the first line has {width}")
    if width not in NUMERIC_SHAPES:
        raise ParseError(table.path, int(table.line[0]), f"{width} fields per line: not an estimate format "
                         "(Ceres 'id x y yaw' has 4, Ceres 3D 'id x y z qx qy qz qw' and TUM "
                         "'timestamp x y z qx qy qz qw' have 8, KITTI's 3x4 matrix has 12)")
    rows = np.arange(counts.size)
    lines = table.line
    if width == 12:
        vals, quanta = numbers(table, rows, slice(0, 12), "KITTI row")
        m = vals.reshape(-1, 3, 4)
        q = quanta.reshape(-1, 3, 4)
        rot = _matrix_rotations(table.path, lines, m[:, :, :3], q[:, :, :3].max(axis=(1, 2)))
        return EstimateFile(table.path, "kitti", 3, np.empty(0, np.int64), rot, m[:, :, 3].copy(), lines,
                            q[:, :, :3].max(axis=(1, 2)), q[:, :, 3].max(axis=1))
    vals, quanta = numbers(table, rows, slice(1, width), "pose")
    if width == 4:
        ids = integer_ids(table, rows, "Ceres 2D line: pose id")
        _check_unique(table.path, ids, lines)
        return EstimateFile(table.path, "ceres", 2, ids, _angle_rotations(vals[:, 2]), vals[:, :2].copy(), lines,
                            quanta[:, 2].copy(), quanta[:, :2].max(axis=1))
    rq = quanta[:, 3:7].max(axis=1)
    rot = _quaternion_rotations(table.path, lines, vals[:, 3:7], rq, normalise_any=False)
    first = table.tokens[table.first]
    integral = bool(np.char.isdigit(first).all()) and int(np.strings.str_len(first).max()) <= ID_MAX_DIGITS
    if integral and np.unique(first.astype(np.int64)).size == first.size:
        # distinct integers: Ceres ids if they are the graph's, TUM timestamps otherwise (poses_for)
        return EstimateFile(table.path, "ceres", 3, first.astype(np.int64), rot, vals[:, :3].copy(), lines, rq,
                            quanta[:, :3].max(axis=1), ambiguous=True)
    stamps, _ = numbers(table, rows, slice(0, 1), "TUM line: timestamp")
    return EstimateFile(table.path, "tum", 3, stamps[:, 0], rot, vals[:, :3].copy(), lines, rq,
                        quanta[:, :3].max(axis=1))


# ---------------------------------------------------------------------------------------------
# rotations

def _angle_rotations(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _quaternion_rotations(path: str, lines: np.ndarray, q: np.ndarray, quantum: np.ndarray, *,
                          normalise_any: bool) -> np.ndarray:
    """Rotations of quaternions (x, y, z, w). ``normalise_any``: every non-zero quaternion is
    normalised (g2o's VERTEX_SE3:QUAT, as the graph reader does); else the norm must be 1 within
    the rounding of the written digits (``ROUNDING_QUANTA`` quanta)."""
    norm = np.linalg.norm(q, axis=1)
    zero = norm == 0
    if zero.any():
        k = int(np.flatnonzero(zero)[0])
        raise ParseError(path, int(lines[k]), "zero quaternion: not a rotation")
    if not normalise_any:
        tol = ROUNDING_QUANTA * quantum + FLOAT_ROTATION_TOL
        off = np.abs(norm - 1.0)
        bad = off > tol
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ParseError(path, int(lines[k]), f"quaternion of norm {norm[k]:.9g}: not a rotation (its digits "
                             f"allow a norm within {tol[k]:.2g} of 1)")
        _warn_projected(path, off, "quaternion norm")
    return quat_to_rot(q / norm[:, None])


def _matrix_rotations(path: str, lines: np.ndarray, m: np.ndarray, quantum: np.ndarray) -> np.ndarray:
    """The rotations of (k, 3, 3) matrices by the one rotation check (``posecrb.lie.so.check_rotations``):
    within double precision's rounding taken as they are, within the rounding of their digits
    (``ROUNDING_QUANTA`` quanta of the file's coarsest row) projected onto the rotations with a warning,
    beyond that, or a reflection, an error naming the line."""
    limit = ROUNDING_QUANTA * float(quantum.max(initial=0.0)) + FLOAT_ROTATION_TOL
    try:
        rot, _ = check_rotations(m, tol=FLOAT_ROTATION_TOL, limit=limit, name=f"{path}: the 3x3 blocks")
    except NotRotations as exc:
        line = int(lines[exc.rows[0]]) if exc.rows.size else None
        # the check names rows by their index; the error names the first one's line instead
        reason = re.sub(r"^rows? [0-9, .]+\(of [0-9]+\) ", "", str(exc).split(": ", 2)[-1])
        raise ParseError(path, line, f"the 3x3 block {reason}") from None
    return rot


def _warn_projected(path: str, deviation: np.ndarray, what: str) -> None:
    off = deviation > FLOAT_ROTATION_TOL
    if off.any():
        log.warning("%s: %d %s(s) off a rotation by up to %.2g (the rounding of their digits): projected onto the "
                    "rotations", path, int(off.sum()), what, float(deviation.max()))


def _planar(f: EstimateFile, order: np.ndarray, rot: np.ndarray, trans: np.ndarray, rq: np.ndarray,
            tq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """3D rows as the planar poses of a 2D graph: z = 0 and a rotation about z, within the rows'
    rounding; the (x, y) part and the angle about z."""
    tilt = np.maximum(np.abs(rot[:, 2, :2]).max(axis=1), np.abs(rot[:, :2, 2]).max(axis=1))
    z = np.abs(trans[:, 2])
    bad = (tilt > ROUNDING_QUANTA * rq + FLOAT_ROTATION_TOL) | (z > ROUNDING_QUANTA * tq + FLOAT_ROTATION_TOL)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ParseError(f.path, int(f.lines[order[k]]), f"a 3D pose (z = {trans[k, 2]:.6g}, tilt {tilt[k]:.3g}) "
                         "for a 2D graph: TUM, KITTI and Ceres 3D rows of a 2D graph must be planar (z = 0, a "
                         "rotation about z)")
    theta = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    return _angle_rotations(theta), np.ascontiguousarray(trans[:, :2])


# ---------------------------------------------------------------------------------------------
# checks and matching

def _check_counts(table: NumericTable, rows: np.ndarray, expected: int, tag: str) -> None:
    bad = np.flatnonzero(table.count[rows] != expected)
    if bad.size:
        k = rows[bad[0]]
        raise ParseError(table.path, int(table.line[k]), f"{tag} needs {expected - 1} numeric fields, found "
                         f"{table.count[k] - 1}")


def _check_unique(path: str, ids: np.ndarray, lines: np.ndarray) -> None:
    order = np.argsort(ids, kind="stable")
    dup = np.flatnonzero(ids[order][1:] == ids[order][:-1])
    if dup.size:
        k = order[dup[0] + 1]
        raise ParseError(path, int(lines[k]), f"pose id {ids[k]} appears twice")


def _integral_keys(f: EstimateFile, what: str) -> np.ndarray:
    keys = f.keys
    bad = (keys != np.round(keys)) | (keys < 0) | (keys >= 2.0 ** 53)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ParseError(f.path, int(f.lines[k]), f"timestamp {keys[k]:.17g} is not an integer pose id ({what})")
    ids = keys.astype(np.int64)
    _check_unique(f.path, ids, f.lines)
    return ids


def _matchinteger_ids(f: EstimateFile, keys: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Row of each graph id (``ids`` sorted): every id exactly once, no other."""
    order = np.argsort(keys, kind="stable")
    pos = np.searchsorted(keys[order], ids)
    found = (pos < keys.size) & (keys[order][np.minimum(pos, keys.size - 1)] == ids)
    if not found.all():
        missing = ids[~found]
        raise ParseError(f.path, None, f"lacks {missing.size} pose(s) of the graph, e.g. id {missing[0]}")
    if keys.size > ids.size:
        extra = np.setdiff1d(keys, ids)
        k = int(np.flatnonzero(keys == extra[0])[0])
        raise ParseError(f.path, int(f.lines[k]), f"has {extra.size} pose(s) the graph does not have, e.g. id "
                         f"{extra[0]}")
    return order[pos]


def _compatible(found: EstimateFile, asked: str) -> bool:
    """Whether a file read as ``found`` may be read as ``asked`` (8-column lines are Ceres 3D or TUM)."""
    return found.format == asked or (found.ambiguous and asked in ("ceres", "tum"))


def _shape_name(f: EstimateFile) -> str:
    return {"g2o": "g2o VERTEX", "toro": "TORO VERTEX", "ceres": f"Ceres {f.dim}D", "tum": "TUM",
            "kitti": "KITTI"}[f.format]



__all__ = ["EstimateFile", "EstimatePoses", "read_estimate_file"]
