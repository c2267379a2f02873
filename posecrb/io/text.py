"""Format-independent text machinery of the readers: lines, fields, numbers, limits, errors.

Every format (``posecrb.io.g2o``, ``posecrb.io.toro``) is a line format: one record per line,
a tag then numeric fields. This module turns a file's content into groups of lines by tag and
each group's numeric block into arrays, with every violation a ``ParseError`` naming file,
line and reason (docs/design.md#formats). Robustness rules:

* Lines end at ``\\n``, ``\\r\\n`` or ``\\r`` only (the line rules of every text input,
  ``posecrb.io.lines``). ``str.splitlines`` would also break at form
  feed, vertical tab, ``\\x1c``-``\\x1e``, NEL and U+2028/U+2029, turning the tail of a comment
  into data and shifting every later line number.
* Fields are separated by ASCII blanks (space, tab, form feed, vertical tab). Numbers follow
  the plain decimal grammar ``[+-]digits[.digits][e[+-]digits]`` (plus nan/inf, rejected as
  non-finite): Python's ``float``/``int`` would also take ``1_0``, non-ASCII digits and
  surrounding Unicode spaces.
* Vertex ids are parsed as integers, never through float64 (which changes ids above 2^53),
  and must fit int64.
* Magnitudes stay inside the range where everything downstream is finite (``MAX_*`` below).

Two tokenisers give the same groups and blocks. ``scan_bytes`` is the fast one: it works on the
file's bytes with whole-buffer numpy operations (newlines, token boundaries, tags) and converts
each tag's numeric block with one ``np.fromstring`` call; it takes only plain ASCII files whose
lines are ``TAG`` + blank-separated tokens of ``[0-9.eE+-]`` with short integer ids, and gives up
(``Fallback``) on anything else. ``split_text`` is the reference tokeniser over ``str``; it takes
every input and locates every error, so the fast path never has to.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from itertools import chain

import numpy as np

from ..core.errors import InternalError, ParseError
from ..core.integers import IntegerError, parse_int, shown
from .lines import FIELD_SEP, ODD_SPACE, split_lines
from .records import RecordKind

# Magnitude limits, checked at parse time so that no quantity built from a file overflows
# or underflows later (the FIM, the Laplacians, the solver's data matrix and the CRLB are
# sums over edges of products of two or three of these). With |t| <= 1e50 and
# tau, kappa, w in [1e-100, 1e100], tau |t|^2 <= 1e200 and a covariance 1/tau <= 1e100:
# products and sums over any realistic number of edges stay far inside 1e+-308. Real
# datasets use |t| < 1e5 and information < 1e9.
MAX_TRANSLATION = 1e50          # every translation component (edges and vertices)
MAX_INFORMATION = 1e100         # every information-matrix entry
PRECISION_RANGE = (1e-100, 1e100)   # tau, kappa and the 3D rotation weight w = omega(kappa)/3 (eq. 59)

_NUMBER = r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|(?i:nan|inf|infinity))"
# Fast screens over all tokens of a block joined by spaces. Past them, float() and int() can
# only meet the plain grammar (no underscores, non-ASCII digits or Unicode spaces, which
# both would accept); the exact grammar _NUMBER is applied only to locate an error.
_NOT_NUMBER_CHAR = re.compile(r"[^0-9eE.+\- nNaAiIfFtTyY]")
_NOT_ID_CHAR = re.compile(r"[^0-9 ]")
_INT64_MAX = np.iinfo(np.int64).max

# The fast tokeniser's alphabet: printable ASCII, tab and newline (no \r, \f, \v or other
# control characters: their line and field rules are split_text's), and inside numeric blocks
# only the characters of plain decimal numbers and blanks.
_PRINTABLE = bytes([9, 10] + list(range(32, 127)))
_NUMERIC_BYTES = b"0123456789.eE+- \t\n"
# Ids of at most this many digits are below 2^53, so exact in float64.
_FAST_ID_DIGITS = 15


class Fallback(Exception):
    """The fast tokeniser cannot take this input; ``split_text`` decides (never leaves the module's callers)."""


def fmt_number(x: float) -> str:
    """A number as users write it (never ``np.float64(...)``)."""
    x = float(x)
    return f"{x:.6g}" if x == x and abs(x) != float("inf") else str(x)


def check_magnitude(path: str, lines: np.ndarray, tag: str, vals: np.ndarray, limit: float, what: str) -> None:
    """Every entry of each record's ``vals`` within ``limit`` in magnitude (``MAX_*`` above)."""
    big = np.abs(vals).reshape(vals.shape[0], -1).max(axis=1) > limit
    if big.any():
        k = int(np.flatnonzero(big)[0])
        v = vals[k].ravel()[np.argmax(np.abs(vals[k]).ravel())]
        raise ParseError(path, int(lines[k]), f"{tag}: {what} {fmt_number(v)} exceeds {fmt_number(limit)} in "
                                              "magnitude (quantities built from it would overflow)")


def _check_finite(path: str, rec: RecordKind, lines: np.ndarray, vals: np.ndarray) -> None:
    finite = np.isfinite(vals).all(axis=1)
    if not finite.all():
        k = int(np.flatnonzero(~finite)[0])
        raise ParseError(path, int(lines[k]), f"{rec.tag}: non-finite value (NaN or inf)")


@dataclass(frozen=True)
class Tokens:
    """A file's lines grouped by tag, and the numeric blocks of the groups.

    ``groups`` maps each first field ("tag") to the 0-based indices of its lines, in order of
    first occurrence (blank lines belong to no group). ``numeric(path, rec, idx)`` gives the
    ``(k, n_ids)`` int64 ids and ``(k, fields - n_ids)`` float64 values of the lines ``idx`` of
    record kind ``rec``, or raises ``ParseError`` (``split_text``) / ``Fallback`` (``scan_bytes``).
    """

    groups: dict[str, np.ndarray]
    numeric: Callable[[str, RecordKind, np.ndarray], tuple[np.ndarray, np.ndarray]]


# --------------------------------------------------------------------------------------------
# Reference tokeniser: any text, exact error locations.

def _split_lines(text: str) -> list[list[str]]:
    """Fields of every line, by the line rules of ``posecrb.io.lines`` (module docstring)."""
    lines = split_lines(text)
    if ODD_SPACE.search(text) is None and "\f" not in text and "\v" not in text:
        return [ln.split() for ln in lines]          # only ASCII blanks occur
    return [[f for f in FIELD_SEP.split(ln) if f] for ln in lines]


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
    long_ids = max(map(len, id_tokens)) > 18
    if _NOT_ID_CHAR.search(joined) is not None or long_ids:
        for k, r in enumerate(rows):   # rare path: find the offending line, if any
            for tok in r[1: 1 + nid]:
                try:                           # (parse_int: never int() of thousands of digits)
                    if _NOT_ID_CHAR.search(tok) is not None:
                        raise IntegerError(tok)
                    parse_int(tok, lo=0, hi=_INT64_MAX)
                except IntegerError:
                    raise ParseError(path, int(lines[k]), f"{rec.tag}: {what} {shown(tok)} is not a non-negative "
                                                          "integer id that fits 64 bits (0 .. 2^63-1)") from None
    # Digits only (checked above): int() is exact and cannot meet its extensions (1_0, spaces); long
    # tokens (leading zeros) through parse_int, as int() refuses more than 4300 digits.
    ids = np.fromiter(map(parse_int if long_ids else int, id_tokens), dtype=np.int64,
                      count=len(id_tokens)).reshape(len(rows), nid)
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
    _check_finite(path, rec, lines, vals)
    return ids, vals


def split_text(text: str) -> Tokens:
    """The reference tokeniser (module docstring): every input, every error located."""
    rows = _split_lines(text)
    groups: dict[str, list[int]] = {}
    for k, r in enumerate(rows):
        if r:
            groups.setdefault(r[0], []).append(k)

    def numeric(path: str, rec: RecordKind, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _numeric_block(path, [rows[k] for k in idx], idx + 1, rec)

    return Tokens(groups={tag: np.asarray(idx, dtype=np.int64) for tag, idx in groups.items()}, numeric=numeric)


# --------------------------------------------------------------------------------------------
# Fast tokeniser: whole-buffer numpy operations, no Python loop per line.

def scan_bytes(data: bytes) -> Tokens:
    """The fast tokeniser (module docstring); raises ``Fallback`` where it cannot decide.

    Newlines, token starts and ends are found once over the whole buffer; each line's first
    token (its tag) is compared as a fixed-width byte string, so grouping costs a sort of the
    tags, not a loop over lines.
    """
    if not data.isascii() or data.translate(None, _PRINTABLE):
        raise Fallback
    buf = np.frombuffer(data, dtype=np.uint8)
    nl = np.flatnonzero(buf == 10)
    word = (buf != 32) & (buf != 9) & (buf != 10)
    edge = np.diff(word.view(np.int8), prepend=np.int8(0), append=np.int8(0))
    tok_start = np.flatnonzero(edge == 1)
    tok_end = np.flatnonzero(edge == -1)      # exclusive
    line_start = np.concatenate(([0], nl + 1))   # as text.split("\n"): a final newline ends an empty line
    line_end = np.append(nl, buf.size)
    first_tok = np.searchsorted(tok_start, line_start)    # index of each line's first token
    counts = np.diff(first_tok, append=tok_start.size)    # tokens per line
    used = np.flatnonzero(counts)
    tag_start, tag_end = tok_start[first_tok[used]], tok_end[first_tok[used]]
    tag_len = tag_end - tag_start

    # Tags: per length, the bytes as one fixed-width string each; np.unique groups them.
    tag_of_line: dict[str, np.ndarray] = {}
    first_seen: dict[str, int] = {}
    # (bincount, not np.unique: numpy's unique consults numpy.ma, which the CLI defers; see posecrb.cli)
    for length in np.flatnonzero(np.bincount(tag_len)):
        sel = np.flatnonzero(tag_len == length)
        raw = buf[tag_start[sel][:, None] + np.arange(length)]
        names, inverse = np.unique(np.ascontiguousarray(raw).view(f"S{length}").ravel(), return_inverse=True)
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(names.size + 1))
        for u, name in enumerate(names):
            lines = used[sel[order[bounds[u]: bounds[u + 1]]]]
            tag = name.decode("ascii")
            tag_of_line[tag] = lines
            first_seen[tag] = int(lines[0])
    groups = {tag: tag_of_line[tag] for tag in sorted(first_seen, key=first_seen.__getitem__)}

    def numeric(path: str, rec: RecordKind, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        fields, nid = rec.fields, rec.n_ids
        if idx.size == 0 or (counts[idx] != fields + 1).any():
            raise Fallback
        ftok = first_tok[idx]
        # ids: digits only and short enough to be exact in float64
        id_tok = (ftok[:, None] + np.arange(1, 1 + nid)).ravel()
        id_len = tok_end[id_tok] - tok_start[id_tok]
        if id_len.max() > _FAST_ID_DIGITS:
            raise Fallback
        pos = tok_start[id_tok][:, None] + np.arange(_FAST_ID_DIGITS)
        inside = np.arange(_FAST_ID_DIGITS) < id_len[:, None]
        chars = buf[np.minimum(pos, buf.size - 1)]
        if (inside & ((chars < 48) | (chars > 57))).any():
            raise Fallback
        # The numeric part of each line: from the end of its tag to the end of the line. Runs
        # of consecutive lines are one slice of the file with the tag removed at every line
        # start (each line of a run starts with the tag, no leading blank).
        starts = tok_start[ftok]
        if (starts != line_start[idx]).any():
            raise Fallback
        tag = rec.tag.encode("ascii")
        cut = np.flatnonzero(np.diff(idx) != 1) + 1
        run_first = np.concatenate(([0], cut))
        run_last = np.append(cut - 1, idx.size - 1)
        if run_first.size > 64:   # interleaved tags: join the lines themselves
            text_end = tok_end[ftok]
            blob = b"\n".join([data[a:b] for a, b in zip(text_end.tolist(), line_end[idx].tolist())])
        else:
            parts = [data[tok_end[ftok[a]]: line_end[idx[b]]].replace(b"\n" + tag, b"\n")
                     for a, b in zip(run_first.tolist(), run_last.tolist())]
            blob = b"\n".join(parts)
        if blob.translate(None, _NUMERIC_BYTES):
            raise Fallback
        try:
            flat = np.fromstring(blob, dtype=np.float64, sep=" ")
        except ValueError:
            raise Fallback from None
        if flat.size != idx.size * fields:
            raise Fallback
        block = flat.reshape(idx.size, fields)
        ids = block[:, :nid].astype(np.int64)
        vals = np.ascontiguousarray(block[:, nid:])
        _check_finite(path, rec, idx + 1, vals)
        return ids, vals

    return Tokens(groups=groups, numeric=numeric)
