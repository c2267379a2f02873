"""Content-sniffing, vectorised reader for g2o and TORO files (README, "Conventions").

Robustness rules (each violation is a ``ParseError`` naming file, line and reason):

* Lines end at ``\n``, ``\r\n`` or ``\r`` only. ``str.splitlines`` would also break at form
  feed, vertical tab, ``\x1c``-``\x1e``, NEL and U+2028/U+2029, turning the tail of a comment
  into data and shifting every later line number.
* Fields are separated by ASCII blanks (space, tab, form feed, vertical tab). Numbers follow
  the plain decimal grammar ``[+-]digits[.digits][e[+-]digits]`` (plus nan/inf, rejected as
  non-finite): Python's ``float``/``int`` would also take ``1_0``, non-ASCII digits and
  surrounding Unicode spaces.
* Vertex ids are parsed as integers, never through float64 (which changes ids above 2^53),
  and must fit int64.
* Magnitudes stay inside the range where everything downstream is finite (``MAX_*`` below).
"""
from __future__ import annotations

import hashlib
import logging
import os
import re
from itertools import chain

import numpy as np

from ..core.errors import InternalError, ParseError, UsageError
from ..core.files import read_regular_file
from ..core.graph import PoseGraph
from ..core.noise import isotropic_precisions, rotation_weight
from ..lie.so import so2_exp
from .records import RECORDS, SKIPPED_TAGS, TORO2_INFO_ORDER, RecordKind
from .rotations import euler_to_rot, quat_to_rot

log = logging.getLogger("posecrb")

QUATERNION_MODES = ("normalize", "raw")

# Magnitude limits, checked at parse time so that no quantity built from a file overflows
# or underflows later (the FIM, the Laplacians, the solver's data matrix and the CRLB are
# sums over edges of products of two or three of these). With |t| <= 1e50 and
# tau, kappa, w in [1e-100, 1e100], tau |t|^2 <= 1e200 and a covariance 1/tau <= 1e100:
# products and sums over any realistic number of edges stay far inside 1e+-308. Real
# datasets use |t| < 1e5 and information < 1e9.
MAX_TRANSLATION = 1e50          # every translation component (edges and vertices)
MAX_INFORMATION = 1e100         # every information-matrix entry
PRECISION_RANGE = (1e-100, 1e100)   # tau, kappa and the 3D rotation weight w = omega(kappa)/3 (eq. 59)

_LINE_END = re.compile(r"\r\n|\r|\n")
# Characters str.split() treats as whitespace but a g2o/TORO reader must not.
_ODD_SPACE = re.compile(r"[\x1c-\x1f\x85\xa0\u1680\u2000-\u200a\u2028\u2029\u202f\u205f\u3000]")
_FIELD_SEP = re.compile(r"[ \t\f\v]+")
_NUMBER = r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|(?i:nan|inf|infinity))"
# Fast screens over all tokens of a block joined by spaces. Past them, float() and int() can
# only meet the plain grammar (no underscores, non-ASCII digits or Unicode spaces, which
# both would accept); the exact grammar _NUMBER is applied only to locate an error.
_NOT_NUMBER_CHAR = re.compile(r"[^0-9eE.+\- nNaAiIfFtTyY]")
_NOT_ID_CHAR = re.compile(r"[^0-9 ]")
_INT64_MAX = np.iinfo(np.int64).max


def _fmt(x: float) -> str:
    """A number as users write it (never ``np.float64(...)``)."""
    x = float(x)
    return f"{x:.6g}" if x == x and abs(x) != float("inf") else str(x)


def load(path: str | os.PathLike, quaternions: str = "normalize") -> PoseGraph:
    """Read a g2o or TORO pose-graph file; the format is detected from its content.

    ``quaternions`` says how the g2o 3D edge quaternions (qx, qy, qz, qw) become R~:

    - ``"normalize"`` (default): ``q / |q|`` (computed after scaling q by its
      largest component, so no norm overflows or underflows) then the rotation matrix;
      every R~ is in SO(3).
    - ``"raw"``: SE-Sync's g2o reader, i.e. Eigen's ``Quaternion(qw, qx, qy, qz).toRotationMatrix()``
      applied to the quaternion AS WRITTEN (no normalisation). Files print quaternions with
      6-9 digits, so R~ is then slightly non-orthogonal (``|I - R~ R~^T|`` up to ~1e-5 on
      cubicle.g2o), and SE-Sync's objective (``posecrb.solver``, whose data matrix carries
      ``kappa I`` / ``-kappa R~`` blocks exactly as SE-Sync's) differs from the normalised
      reading by up to ~3e-5 relative. This mode exists ONLY to reproduce SE-Sync's numbers;
      the rest of posecrb (FIM, bounds, CRLB) assumes rotations and should get the default.
      A quaternion whose squared norm exceeds ``MAX_INFORMATION`` is an error in this mode.

    Either way a zero quaternion is an error, vertex quaternions (an estimate, which
    SE-Sync's reader ignores) are always normalised, and 2D/TORO files are unaffected.
    Only regular files are read (a directory, FIFO or device is an error saying so).
    """
    path = os.fspath(path)
    data = read_regular_file(path)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = len(_LINE_END.findall(data[: exc.start].decode("utf-8", "replace"))) + 1
        raise ParseError(path, line, "not a text file (invalid UTF-8)") from None
    return parse_text(text, path=path, sha256=hashlib.sha256(data).hexdigest(), quaternions=quaternions)


def _split_lines(text: str) -> list[list[str]]:
    """Fields of every line; lines end at \n, \r\n, \r only (see the module docstring)."""
    lines = _LINE_END.split(text) if "\r" in text else text.split("\n")
    if _ODD_SPACE.search(text) is None and "\f" not in text and "\v" not in text:
        return [ln.split() for ln in lines]          # fast path: only ASCII blanks occur
    return [[f for f in _FIELD_SEP.split(ln) if f] for ln in lines]


def _numeric_block(path: str, rows: list[list[str]], lines: np.ndarray,
                   rec: RecordKind) -> tuple[np.ndarray, np.ndarray]:
    """(k, n_ids) int64 ids and (k, fields - n_ids) float64 values of the records, with exact
    error locations. Ids never pass through float64."""
    counts = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
    bad = np.flatnonzero(counts != rec.fields + 1)
    if bad.size:
        k = bad[0]
        raise ParseError(path, int(lines[k]),
                         f"{rec.tag} needs {rec.fields} numeric fields, found {counts[k] - 1}")
    nid = rec.n_ids
    what = "vertex id" if rec.kind == "vertex" else "edge endpoint"
    id_tokens = list(chain.from_iterable(r[1: 1 + nid] for r in rows))
    joined = " ".join(id_tokens)
    if _NOT_ID_CHAR.search(joined) is not None or max(map(len, id_tokens)) > 18:
        for k, r in enumerate(rows):   # rare path: find the offending line, if any
            for tok in r[1: 1 + nid]:
                if _NOT_ID_CHAR.search(tok) is not None or int(tok) > _INT64_MAX:
                    raise ParseError(path, int(lines[k]), f"{rec.tag}: {what} {tok!r} is not a non-negative "
                                                          "integer id that fits 64 bits (0 .. 2^63-1)")
    # Digits only (checked above): int() is exact and cannot meet its extensions (1_0, spaces).
    ids = np.fromiter(map(int, id_tokens), dtype=np.int64, count=len(id_tokens)).reshape(len(rows), nid)
    tokens = list(chain.from_iterable(r[1 + nid:] for r in rows))
    vals = None
    if _NOT_NUMBER_CHAR.search(" ".join(tokens)) is None:
        try:
            vals = np.array(tokens, dtype=np.float64)
        except ValueError:
            pass
    if vals is None:
        single = re.compile(_NUMBER)
        for k, r in enumerate(rows):   # error path only: find the offending token
            for tok in r[1 + nid:]:
                if single.fullmatch(tok) is None:
                    raise ParseError(path, int(lines[k]), f"{rec.tag}: {tok!r} is not a number")
        raise InternalError("unreachable: every token matches the number grammar")
    vals = vals.reshape(len(rows), rec.fields - nid)
    finite = np.isfinite(vals).all(axis=1)
    if not finite.all():
        k = int(np.flatnonzero(~finite)[0])
        raise ParseError(path, int(lines[k]), f"{rec.tag}: non-finite value (NaN or inf)")
    return ids, vals


def _upper_to_full(vals: np.ndarray, q: int) -> np.ndarray:
    """(k, q, q) symmetric matrices from row-major upper triangles."""
    iu = np.triu_indices(q)
    out = np.zeros((vals.shape[0], q, q))
    out[:, iu[0], iu[1]] = vals
    out[:, iu[1], iu[0]] = vals
    return out


def _quaternions(path: str, q: np.ndarray, lines: np.ndarray, tag: str, normalize: bool = True) -> np.ndarray:
    # Scale by the largest |component| first: q / s has components in [-1, 1] and norm in
    # [1, 2], so the normalisation neither overflows (1e308 1e308 0 0) nor underflows.
    s = np.max(np.abs(q), axis=1)
    bad = np.flatnonzero(~(s > 0))
    if bad.size:
        raise ParseError(path, int(lines[bad[0]]), f"{tag}: zero quaternion")
    qs = q / s[:, None]
    ns = np.linalg.norm(qs, axis=1)
    if normalize:
        return quat_to_rot(qs / ns[:, None])
    # quat_to_rot is Eigen's toRotationMatrix formula (1 - 2(y^2 + z^2), 2(xy - zw), ...),
    # so the unnormalised input gives SE-Sync's R~ (load(..., quaternions="raw")).
    with np.errstate(over="ignore"):
        norm2 = (s * ns) ** 2
    big = np.flatnonzero(~(norm2 <= MAX_INFORMATION))
    if big.size:
        k = big[0]
        raise ParseError(path, int(lines[k]), f"{tag}: quaternion norm {_fmt(s[k] * ns[k])} is too large to be "
                                              "used unnormalised (SE-Sync-compatible reading)")
    return quat_to_rot(q)


def _check_magnitude(path: str, lines: np.ndarray, tag: str, vals: np.ndarray, limit: float, what: str) -> None:
    big = np.abs(vals).reshape(vals.shape[0], -1).max(axis=1) > limit
    if big.any():
        k = int(np.flatnonzero(big)[0])
        v = vals[k].ravel()[np.argmax(np.abs(vals[k]).ravel())]
        raise ParseError(path, int(lines[k]), f"{tag}: {what} {_fmt(v)} exceeds {_fmt(limit)} in magnitude "
                                              "(quantities built from it would overflow)")


def _check_positive_definite(path: str, lines: np.ndarray, tag: str, ends: tuple, name: str,
                             block: np.ndarray) -> None:
    """Scale-aware positive-definiteness of each (b, b) block.

    The block is scaled to unit diagonal, D^-1/2 A D^-1/2 (diag(1e12, 1e-3) becomes I), and
    the smallest eigenvalue of that correlation matrix must exceed its rounding error
    (b eps per entry, margin 100). An absolute or max-eigenvalue-relative threshold would
    reject well-defined matrices whose diagonal spans many decades.
    """
    b = block.shape[-1]
    diag = np.diagonal(block, axis1=1, axis2=2)
    pos = np.all(diag > 0, axis=1)
    d = np.where(diag > 0, diag, 1.0) ** -0.5
    corr = block * d[:, :, None] * d[:, None, :]
    eig = np.linalg.eigvalsh(corr)[:, 0]
    tol = 100 * b * np.finfo(float).eps
    bad = np.flatnonzero(~pos | ~(eig > tol))
    if not bad.size:
        return
    k = bad[0]
    where = f"{tag} {ends[0][k]} {ends[1][k]}: {name} block of the information matrix is not positive definite"
    if not pos[k]:
        j = int(np.argmin(diag[k]))
        reason = f"(diagonal entry {j + 1} is {_fmt(diag[k, j])})"
    elif eig[k] > -tol:
        reason = "(singular to working precision)"
    else:
        reason = f"(smallest eigenvalue {_fmt(eig[k])} after scaling to unit diagonal)"
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
                w[small] = rotation_weight(np.where(kappa[small] > 0, kappa[small], 1.0), dim)
        checks.append(("rotation weight omega(kappa)/3 (eq. 59)", w))
    for what, v in checks:
        bad = np.flatnonzero(~((v >= lo) & (v <= hi)))
        if bad.size:
            k = bad[0]
            raise ParseError(path, int(lines[k]), f"{tag} {ends[0][k]} {ends[1][k]}: {what} = {_fmt(v[k])} is "
                                                  f"outside [{_fmt(lo)}, {_fmt(hi)}] (information too "
                                                  f"{'small' if v[k] < lo else 'large'} to compute with)")
    return tau, kappa


def _decode_edges(path: str, rec: RecordKind, ids: np.ndarray, vals: np.ndarray, lines: np.ndarray,
                  normalize: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    i, j = ids[:, 0], ids[:, 1]
    loop = np.flatnonzero(i == j)
    if loop.size:
        raise ParseError(path, int(lines[loop[0]]), f"{rec.tag}: self-loop on pose {i[loop[0]]}")
    d = rec.dim
    t = vals[:, :d]
    _check_magnitude(path, lines, rec.tag, t, MAX_TRANSLATION, "translation component")
    if d == 2:
        r = so2_exp(vals[:, 2])
        raw = vals[:, 3:9]
        if rec.family == "toro":
            raw = raw[:, np.array([TORO2_INFO_ORDER[(int(a), int(b))] for a, b in zip(*np.triu_indices(3))])]
    else:
        if rec.family == "g2o":
            r = _quaternions(path, vals[:, 3:7], lines, rec.tag, normalize)
            raw = vals[:, 7:28]
        else:
            r = euler_to_rot(vals[:, 3], vals[:, 4], vals[:, 5])
            raw = vals[:, 6:27]
    _check_magnitude(path, lines, rec.tag, raw, MAX_INFORMATION, "information entry")
    info = _upper_to_full(raw, 3 if d == 2 else 6)
    # The isotropic model needs the translation and rotation blocks to be positive
    # definite. Real files (cubicle.g2o) carry full matrices whose cross terms make
    # them indefinite although both blocks are fine; that is counted, not fatal.
    for name, block in (("translation", info[:, :d, :d]), ("rotation", info[:, d:, d:])):
        _check_positive_definite(path, lines, rec.tag, (i, j), name, block)
    precisions = _check_precisions(path, lines, rec.tag, (i, j), info, d)
    return i, j, r, t, info, precisions


def _decode_vertices(path: str, rec: RecordKind, ids: np.ndarray, vals: np.ndarray,
                     lines: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    vid = ids[:, 0]
    d = rec.dim
    trans = vals[:, :d]
    _check_magnitude(path, lines, rec.tag, trans, MAX_TRANSLATION, "translation component")
    if d == 2:
        return vid, so2_exp(vals[:, 2]), trans
    if rec.family == "g2o":
        return vid, _quaternions(path, vals[:, 3:7], lines, rec.tag), trans
    return vid, euler_to_rot(vals[:, 3], vals[:, 4], vals[:, 5]), trans


def parse_text(text: str, path: str = "<string>", sha256: str | None = None,
               quaternions: str = "normalize") -> PoseGraph:
    """Parse the content of a g2o/TORO file (see ``load``, also for ``quaternions``)."""
    if quaternions not in QUATERNION_MODES:
        raise UsageError(f"quaternions must be one of {', '.join(QUATERNION_MODES)}, not {quaternions!r}")
    rows = _split_lines(text)
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
    eids, evals = _numeric_block(path, [rows[k] for k in e_idx], e_lines, erec)
    normalize = quaternions == "normalize"
    ei, ej, erot, etrans, einfo, precisions = _decode_edges(path, erec, eids, evals, e_lines, normalize)

    vertex_rot = vertex_trans = None
    if vrec is not None:
        v_idx = np.asarray(groups[vrec.tag])
        v_lines = v_idx + 1
        vids, vvals = _numeric_block(path, [rows[k] for k in v_idx], v_lines, vrec)
        vid, vrot, vtrans = _decode_vertices(path, vrec, vids, vvals, v_lines)
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
    graph = PoseGraph(
        dim=erec.dim, ids=ids, src=np.searchsorted(ids, ei), dst=np.searchsorted(ids, ej),
        rot=erot, trans=etrans, info=einfo, vertex_rot=vertex_rot, vertex_trans=vertex_trans,
        path=path, format=erec.family, skipped=skipped, edge_lines=e_lines, sha256=sha256,
    )
    graph.__dict__["_precisions"] = precisions   # seed the cached (tau, kappa): computed and checked above
    return graph
