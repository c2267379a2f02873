"""Content-sniffing, vectorised reader for g2o and TORO files (DESIGN.md section 2)."""
from __future__ import annotations

import hashlib
import logging
import os
from itertools import chain

import numpy as np

from ..errors import ParseError, UsageError
from ..graph import PoseGraph
from ..lie import euler_to_rot, quat_to_rot, rot2
from .formats import RECORDS, SKIPPED_TAGS, TORO2_INFO_ORDER, RecordKind

log = logging.getLogger("posecrb")

QUATERNION_MODES = ("normalize", "raw")


def load(path: str | os.PathLike, quaternions: str = "normalize") -> PoseGraph:
    """Read a g2o or TORO pose-graph file; the format is detected from its content.

    ``quaternions`` says how the g2o 3D edge quaternions (qx, qy, qz, qw) become R~:

    - ``"normalize"`` (default, DESIGN.md section 2): ``q / |q|`` then the rotation matrix;
      every R~ is in SO(3).
    - ``"raw"``: SE-Sync's g2o reader, i.e. Eigen's ``Quaternion(qw, qx, qy, qz).toRotationMatrix()``
      applied to the quaternion AS WRITTEN (no normalisation). Files print quaternions with
      6-9 digits, so R~ is then slightly non-orthogonal (``|I - R~ R~^T|`` up to ~1e-5 on
      cubicle.g2o), and SE-Sync's objective (``posecrb.sesync``, whose data matrix carries
      ``kappa I`` / ``-kappa R~`` blocks exactly as SE-Sync's) differs from the normalised
      reading by up to ~3e-5 relative. This mode exists ONLY to reproduce SE-Sync's numbers;
      the rest of posecrb (FIM, bounds, CRLB) assumes rotations and should get the default.

    Either way a zero quaternion is an error, vertex quaternions (an estimate, which
    SE-Sync's reader ignores) are always normalised, and 2D/TORO files are unaffected.
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise ParseError(path, None, f"cannot read file: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ParseError(path, line, "not a text file (invalid UTF-8)") from None
    return parse_text(text, path=path, sha256=hashlib.sha256(data).hexdigest(), quaternions=quaternions)


def _numeric_block(path: str, rows: list[list[str]], lines: np.ndarray, rec: RecordKind) -> np.ndarray:
    """(k, fields) float array of the records' numeric fields, with exact error locations."""
    counts = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
    bad = np.flatnonzero(counts != rec.fields + 1)
    if bad.size:
        k = bad[0]
        raise ParseError(path, int(lines[k]),
                         f"{rec.tag} needs {rec.fields} numeric fields, found {counts[k] - 1}")
    try:
        vals = np.array(list(chain.from_iterable(r[1:] for r in rows)), dtype=np.float64)
    except ValueError:
        for k, r in enumerate(rows):  # error path only: find the offending line
            for tok in r[1:]:
                try:
                    float(tok)
                except ValueError:
                    raise ParseError(path, int(lines[k]), f"{rec.tag}: {tok!r} is not a number") from None
        raise
    vals = vals.reshape(len(rows), rec.fields)
    finite = np.isfinite(vals).all(axis=1)
    if not finite.all():
        k = int(np.flatnonzero(~finite)[0])
        raise ParseError(path, int(lines[k]), f"{rec.tag}: non-finite value (NaN or inf)")
    return vals


def _ids(path: str, col: np.ndarray, lines: np.ndarray, what: str) -> np.ndarray:
    ok = (col == np.floor(col)) & (col >= 0) & (col < 2 ** 62)
    if not ok.all():
        k = int(np.flatnonzero(~ok)[0])
        raise ParseError(path, int(lines[k]), f"{what} {col[k]!r} is not a non-negative integer id")
    return col.astype(np.int64)


def _upper_to_full(vals: np.ndarray, q: int) -> np.ndarray:
    """(k, q, q) symmetric matrices from row-major upper triangles."""
    iu = np.triu_indices(q)
    out = np.zeros((vals.shape[0], q, q))
    out[:, iu[0], iu[1]] = vals
    out[:, iu[1], iu[0]] = vals
    return out


def _quaternions(path: str, q: np.ndarray, lines: np.ndarray, tag: str, normalize: bool = True) -> np.ndarray:
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~(norm > 1e-12))
    if bad.size:
        raise ParseError(path, int(lines[bad[0]]), f"{tag}: zero quaternion")
    # quat_to_rot is Eigen's toRotationMatrix formula (1 - 2(y^2 + z^2), 2(xy - zw), ...),
    # so the unnormalised input gives SE-Sync's R~ (load(..., quaternions="raw")).
    return quat_to_rot(q / norm[:, None] if normalize else q)


def _decode_edges(path: str, rec: RecordKind, vals: np.ndarray, lines: np.ndarray, normalize: bool = True):
    i = _ids(path, vals[:, 0], lines, "edge endpoint")
    j = _ids(path, vals[:, 1], lines, "edge endpoint")
    loop = np.flatnonzero(i == j)
    if loop.size:
        raise ParseError(path, int(lines[loop[0]]), f"{rec.tag}: self-loop on pose {i[loop[0]]}")
    if rec.dim == 2:
        t = vals[:, 2:4]
        r = rot2(vals[:, 4])
        if rec.family == "g2o":
            info = _upper_to_full(vals[:, 5:11], 3)
        else:
            order = [TORO2_INFO_ORDER[rc] for rc in zip(*np.triu_indices(3))]
            info = _upper_to_full(vals[:, 5:11][:, order], 3)
    else:
        t = vals[:, 2:5]
        if rec.family == "g2o":
            r = _quaternions(path, vals[:, 5:9], lines, rec.tag, normalize)
            info = _upper_to_full(vals[:, 9:30], 6)
        else:
            r = euler_to_rot(vals[:, 5], vals[:, 6], vals[:, 7])
            info = _upper_to_full(vals[:, 8:29], 6)
    # The isotropic model needs the translation and rotation blocks to be positive
    # definite. Real files (cubicle.g2o) carry full matrices whose cross terms make
    # them indefinite although both blocks are fine; that is counted, not fatal.
    d = rec.dim
    for name, block in (("translation", info[:, :d, :d]), ("rotation", info[:, d:, d:])):
        eig = np.linalg.eigvalsh(block)
        bad = np.flatnonzero(~(eig[:, 0] > 1e-12 * np.maximum(eig[:, -1], 1e-300)))
        if bad.size:
            k = bad[0]
            raise ParseError(path, int(lines[k]),
                             f"{rec.tag} {i[k]} {j[k]}: {name} block of the information matrix is not "
                             f"positive definite (smallest eigenvalue {eig[k, 0]:.3g})")
    return i, j, r, t, info


def _decode_vertices(path: str, rec: RecordKind, vals: np.ndarray, lines: np.ndarray):
    ids = _ids(path, vals[:, 0], lines, "vertex id")
    if rec.dim == 2:
        return ids, rot2(vals[:, 3]), vals[:, 1:3]
    if rec.family == "g2o":
        return ids, _quaternions(path, vals[:, 4:8], lines, rec.tag), vals[:, 1:4]
    return ids, euler_to_rot(vals[:, 4], vals[:, 5], vals[:, 6]), vals[:, 1:4]


def parse_text(text: str, path: str = "<string>", sha256: str | None = None,
               quaternions: str = "normalize") -> PoseGraph:
    """Parse the content of a g2o/TORO file (see ``load``, also for ``quaternions``)."""
    if quaternions not in QUATERNION_MODES:
        raise UsageError(f"quaternions must be one of {', '.join(QUATERNION_MODES)}, not {quaternions!r}")
    rows = [ln.split() for ln in text.splitlines()]
    groups: dict[str, list[int]] = {}
    for k, r in enumerate(rows):
        if r:
            groups.setdefault(r[0], []).append(k)

    skipped: dict[str, int] = {}
    records: list[RecordKind] = []
    for tag, idx in groups.items():
        if tag.startswith("#"):
            skipped["#"] = skipped.get("#", 0) + len(idx)
        elif tag in SKIPPED_TAGS:
            skipped[tag] = len(idx)
        elif tag in RECORDS:
            records.append(RECORDS[tag])
        else:
            raise ParseError(path, idx[0] + 1, f"unknown record type {tag!r}")

    first_line = {rec.tag: groups[rec.tag][0] + 1 for rec in records}
    for attr in ("dim", "family"):
        values = {getattr(rec, attr) for rec in records}
        if len(values) > 1:
            late = max(records, key=lambda rec: first_line[rec.tag])
            other = min(records, key=lambda rec: first_line[rec.tag])
            what = "2D and 3D records" if attr == "dim" else "g2o and TORO records"
            raise ParseError(path, first_line[late.tag],
                             f"mixed {what}: {late.tag} after {other.tag} (line {first_line[other.tag]})")
    edge_recs = [rec for rec in records if rec.kind == "edge"]
    if not edge_recs:
        raise ParseError(path, None, "no pose-graph edges found (expected EDGE_SE2, EDGE_SE3:QUAT, EDGE2 or EDGE3)")
    erec = edge_recs[0]
    vrec = next((rec for rec in records if rec.kind == "vertex"), None)

    e_idx = np.asarray(groups[erec.tag])
    e_lines = e_idx + 1
    evals = _numeric_block(path, [rows[k] for k in e_idx], e_lines, erec)
    ei, ej, erot, etrans, einfo = _decode_edges(path, erec, evals, e_lines, quaternions == "normalize")

    vertex_rot = vertex_trans = None
    if vrec is not None:
        v_idx = np.asarray(groups[vrec.tag])
        v_lines = v_idx + 1
        vvals = _numeric_block(path, [rows[k] for k in v_idx], v_lines, vrec)
        vid, vrot, vtrans = _decode_vertices(path, vrec, vvals, v_lines)
        order = np.argsort(vid, kind="stable")
        ids = vid[order]
        dup = np.flatnonzero(ids[1:] == ids[:-1])
        if dup.size:
            later = v_lines[order[dup[0] + 1]]
            raise ParseError(path, int(later), f"duplicate vertex id {ids[dup[0]]}")
        vertex_rot, vertex_trans = vrot[order], vtrans[order]
        for end in (ei, ej):
            pos = np.minimum(np.searchsorted(ids, end), ids.size - 1)
            unknown = np.flatnonzero(ids[pos] != end)
            if unknown.size:
                k = unknown[0]
                raise ParseError(path, int(e_lines[k]), f"{erec.tag}: edge to undeclared vertex id {end[k]}")
    else:
        ids = np.unique(np.concatenate([ei, ej]))

    if skipped:
        summary = ", ".join(f"{n} {'comment' if t == '#' else t}" for t, n in sorted(skipped.items()))
        log.warning("%s: skipped %s line(s)", path, summary)
    return PoseGraph(
        dim=erec.dim, ids=ids, src=np.searchsorted(ids, ei), dst=np.searchsorted(ids, ej),
        rot=erot, trans=etrans, info=einfo, vertex_rot=vertex_rot, vertex_trans=vertex_trans,
        path=path, format=erec.family, skipped=skipped, edge_lines=e_lines, sha256=sha256,
    )
