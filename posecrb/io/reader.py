"""The format-independent part of reading a pose-graph file: records -> checked ``PoseGraph``.

``parse`` takes a file's tokens (``posecrb.io.text``) and the registered formats
(``posecrb.io.formats``): it groups records, rejects unknown tags and mixed families or
dimensions, decodes the edges and vertices through their format, and checks what every later
computation relies on (docs/design.md#formats): no self-loops, magnitudes inside the ``MAX_*``
limits, positive-definite translation and rotation blocks of every information matrix, tau,
kappa and the eq. (59) rotation weight inside ``PRECISION_RANGE``, unique vertex ids, edges only
to declared vertices. Each violation is a ``ParseError`` naming file, line and reason.
"""
from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import overload

import numpy as np

from ..core.choices import QUATERNION_MODES
from ..core.errors import ParseError, UsageError
from ..core.graph import PoseGraph
from ..core.noise import isotropic_precisions, rotation_weights
from .records import SKIPPED_TAGS, Format, RecordKind
from .text import MAX_INFORMATION, MAX_TRANSLATION, PRECISION_RANGE, Tokens, check_magnitude, fmt_number

log = logging.getLogger("posecrb")


def _upper_to_full(vals: np.ndarray, q: int) -> np.ndarray:
    """(k, q, q) symmetric matrices from row-major upper triangles (one take of the columns)."""
    upper = np.zeros((q, q), np.intp)
    upper[np.triu_indices(q)] = np.arange(q * (q + 1) // 2)
    return np.take(vals, np.maximum(upper, upper.T).ravel(), axis=1).reshape(-1, q, q)


# Blocks whose Gershgorin bound on the smallest eigenvalue of the unit-diagonal scaling exceeds this
# are positive definite far beyond any rounding of the test below (its tolerance is ~1e-13), so the
# eigenvalues are computed only for the others, which decide exactly as before.
_SURELY_DEFINITE = 1e-6


def _check_positive_definite(path: str, lines: np.ndarray, tag: str, ends: tuple, name: str,
                             block: np.ndarray) -> None:
    """Scale-aware positive-definiteness of each (b, b) block.

    The block is scaled to unit diagonal, D^-1/2 A D^-1/2 (diag(1e12, 1e-3) becomes I), and
    the smallest eigenvalue of that correlation matrix must exceed its rounding error
    (b eps per entry, margin 100). An absolute or max-eigenvalue-relative threshold would
    reject well-defined matrices whose diagonal spans many decades. The eigenvalues are computed
    only for the blocks that Gershgorin's bound, 1 - sum_j!=i |c_ij|, does not show definite by
    ``_SURELY_DEFINITE``.
    """
    b = block.shape[-1]
    pos = block[:, 0, 0] > 0
    for i in range(1, b):
        pos &= block[:, i, i] > 0
    surely = pos
    with np.errstate(all="ignore"):        # NaN or inf where not positive or extreme: not sure
        scale = [1 / np.sqrt(block[:, i, i]) for i in range(b)]
        for i in range(b):
            off = np.zeros(block.shape[0])
            for j in range(b):
                if j != i:
                    off += np.abs(block[:, i, j]) * (scale[i] * scale[j])
            surely = surely & (off < 1 - _SURELY_DEFINITE)
    doubt = np.flatnonzero(~surely)
    if not doubt.size:
        return
    block = block[doubt]
    diag = np.diagonal(block, axis1=1, axis2=2)
    d = np.where(diag > 0, diag, 1.0) ** -0.5
    eig = np.linalg.eigvalsh(block * d[:, :, None] * d[:, None, :])[:, 0]
    tol = 100 * b * np.finfo(float).eps
    failed = ~pos[doubt] | ~(eig > tol)
    if not failed.any():
        return
    first = int(np.argmax(failed))
    bad, eig, diag = doubt[failed], eig[first:], diag[first:]
    k = bad[0]
    where = f"{tag} {ends[0][k]} {ends[1][k]}: {name} block of the information matrix is not positive definite"
    if not pos[k]:
        j = int(np.argmin(diag[0]))
        reason = f"(diagonal entry {j + 1} is {fmt_number(diag[0, j])})"
    elif eig[0] > -tol:
        reason = "(singular to working precision)"
    else:
        reason = f"(smallest eigenvalue {fmt_number(eig[0])} after scaling to unit diagonal)"
    raise ParseError(path, int(lines[k]), f"{where} {reason}")


def _check_precisions(path: str, lines: np.ndarray, tag: str, ends: tuple, info: np.ndarray,
                      dim: int) -> tuple[np.ndarray, np.ndarray]:
    """tau, kappa (SE-Sync's rule) and the 3D eq. (59) rotation weight inside PRECISION_RANGE;
    returns (tau, kappa)."""
    lo, hi = PRECISION_RANGE
    with np.errstate(all="ignore"):
        tau, kappa = isotropic_precisions(info, dim)
    checks = [("translation precision tau", tau), ("rotation concentration kappa", kappa)]
    if dim == 3:
        # w = omega(kappa)/3 <= kappa, and w ~ kappa^2/3 below kappa ~ 1e-3: only small
        # concentrations can push w under the range; evaluate eq. (59) for those only.
        w = np.full_like(kappa, hi)
        small = kappa < 1e-3
        if small.any():
            with np.errstate(all="ignore"):
                w[small] = rotation_weights(np.where(kappa[small] > 0, kappa[small], 1.0), dim)
        checks.append(("rotation weight omega(kappa)/3 (eq. 59)", w))
    for what, v in checks:
        bad = np.flatnonzero(~((v >= lo) & (v <= hi)))
        if bad.size:
            k = bad[0]
            raise ParseError(path, int(lines[k]), f"{tag} {ends[0][k]} {ends[1][k]}: {what} = {fmt_number(v[k])} "
                                                  f"is outside [{fmt_number(lo)}, {fmt_number(hi)}] (information "
                                                  f"too {'small' if v[k] < lo else 'large'} to compute with)")
    return tau, kappa


def _decode_edges(path: str, fmt: Format, rec: RecordKind, ids: np.ndarray, vals: np.ndarray, lines: np.ndarray,
                  normalize: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                tuple[np.ndarray, np.ndarray]]:
    i, j = ids[:, 0], ids[:, 1]
    loop = np.flatnonzero(i == j)
    if loop.size:
        raise ParseError(path, int(lines[loop[0]]), f"{rec.tag}: self-loop on pose {i[loop[0]]}")
    d = rec.dim
    t = vals[:, :d]
    check_magnitude(path, lines, rec.tag, t, MAX_TRANSLATION, "translation component")
    r, raw = fmt.decode_edges(path, rec, vals, lines, normalize)
    check_magnitude(path, lines, rec.tag, raw, MAX_INFORMATION, "information entry")
    info = _upper_to_full(raw, 3 if d == 2 else 6)
    # The isotropic model needs the translation and rotation blocks to be positive
    # definite. Real files (cubicle.g2o) carry full matrices whose cross terms make
    # them indefinite although both blocks are fine; that is counted, not fatal.
    for name, block in (("translation", info[:, :d, :d]), ("rotation", info[:, d:, d:])):
        _check_positive_definite(path, lines, rec.tag, (i, j), name, block)
    precisions = _check_precisions(path, lines, rec.tag, (i, j), info, d)
    return i, j, r, t, info, precisions


def _decode_vertices(path: str, fmt: Format, rec: RecordKind, ids: np.ndarray, vals: np.ndarray,
                     lines: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    trans = vals[:, :rec.dim]
    check_magnitude(path, lines, rec.tag, trans, MAX_TRANSLATION, "translation component")
    return ids[:, 0], fmt.decode_vertices(path, rec, vals, lines), trans


@overload
def _handed_over(array: np.ndarray) -> np.ndarray: ...


@overload
def _handed_over(array: None) -> None: ...


def _handed_over(array: np.ndarray | None) -> np.ndarray | None:
    """``array``, made here and referenced nowhere else, read-only down to the memory it views, so
    that ``PoseGraph`` keeps it rather than a copy (``frozen_array``); a narrow view of a wider
    block (translations among a record's values) is copied first, so the block is not kept."""
    if array is None:
        return None
    if array.base is not None and array.base.size > 2 * array.size:
        array = array.copy()
    base: object = array
    while isinstance(base, np.ndarray):
        base.setflags(write=False)
        base = base.base
    return array


def _positions(ids: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of each of ``end`` in the increasing ``ids``, and where it is none of them."""
    if ids[-1] - ids[0] == ids.size - 1:    # consecutive ids (the usual numbering): an offset
        pos = end - ids[0]
        return pos, (pos < 0) | (pos >= ids.size)
    pos = np.searchsorted(ids, end)
    return pos, ids[np.minimum(pos, ids.size - 1)] != end


def parse(tokens: Tokens, formats: Mapping[str, Format], path: str = "<string>", sha256: str | None = None,
          quaternions: str = "normalize") -> PoseGraph:
    """A checked ``PoseGraph`` from a file's tokens (module docstring; ``posecrb.io.load`` for
    ``quaternions``). Raises ``ParseError`` (file, line, reason) or ``text.Fallback`` (from the
    fast tokeniser, before anything is logged)."""
    if quaternions not in QUATERNION_MODES:
        raise UsageError(f"quaternions must be one of {', '.join(QUATERNION_MODES)}, not {quaternions!r}")
    known = {tag: rec for fmt in formats.values() for tag, rec in fmt.records.items()}
    groups = tokens.groups
    skipped: dict[str, int] = {}
    records: list[RecordKind] = []
    for tag, idx in groups.items():
        if tag.startswith("#"):
            skipped["#"] = skipped.get("#", 0) + len(idx)
        elif tag in SKIPPED_TAGS:
            skipped[tag] = len(idx)
        elif tag in known:
            records.append(known[tag])
        else:
            raise ParseError(path, int(idx[0]) + 1, f"unknown record type {tag!r}")

    first_line = {rec.tag: int(groups[rec.tag][0]) + 1 for rec in records}
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
    fmt = formats[erec.family]
    vrec = next((rec for rec in records if rec.kind == "vertex"), None)

    e_idx = groups[erec.tag]
    e_lines = e_idx + 1
    eids, evals = tokens.numeric(path, erec, e_idx)
    normalize = quaternions == "normalize"
    ei, ej, erot, etrans, einfo, precisions = _decode_edges(path, fmt, erec, eids, evals, e_lines, normalize)

    vertex_rot = vertex_trans = None
    if vrec is not None:
        v_idx = groups[vrec.tag]
        v_lines = v_idx + 1
        vids, vvals = tokens.numeric(path, vrec, v_idx)
        vid, vrot, vtrans = _decode_vertices(path, fmt, vrec, vids, vvals, v_lines)
        if (vid[1:] > vid[:-1]).all():   # written in order (the usual case): nothing to sort
            ids, vertex_rot, vertex_trans = vid, vrot, vtrans
        else:
            order = np.argsort(vid, kind="stable")
            ids = vid[order]
            dup = np.flatnonzero(ids[1:] == ids[:-1])
            if dup.size:
                later = v_lines[order[dup[0] + 1]]
                raise ParseError(path, int(later), f"duplicate vertex id {ids[dup[0]]}")
            vertex_rot, vertex_trans = vrot[order], vtrans[order]
        src, unknown_src = _positions(ids, ei)
        dst, unknown_dst = _positions(ids, ej)
        for end, unknown in ((ei, unknown_src), (ej, unknown_dst)):
            if unknown.any():
                k = int(np.argmax(unknown))
                raise ParseError(path, int(e_lines[k]), f"{erec.tag}: edge to undeclared vertex id {end[k]}")
    else:
        # sorted distinct ids (not np.unique, which consults numpy.ma, deferred by the CLI)
        ids = np.sort(np.concatenate([ei, ej]))
        ids = ids[np.flatnonzero(np.diff(ids, prepend=ids[:1] - 1))]
        src, dst = _positions(ids, ei)[0], _positions(ids, ej)[0]

    if skipped:
        summary = ", ".join(f"{n} {'comment' if t == '#' else t}" for t, n in sorted(skipped.items()))
        log.warning("%s: skipped %s line(s)", path, summary)
    graph = PoseGraph(
        dim=erec.dim, ids=_handed_over(ids), src=_handed_over(src), dst=_handed_over(dst), rot=_handed_over(erot),
        trans=_handed_over(etrans), info=_handed_over(einfo), vertex_rot=_handed_over(vertex_rot),
        vertex_trans=_handed_over(vertex_trans), path=path, format=erec.family, skipped=skipped,
        edge_lines=_handed_over(e_lines), sha256=sha256, quaternions=quaternions,
    )
    graph.__dict__["_precisions"] = precisions   # seed the cached (tau, kappa): computed and checked above
    return graph
