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
file's bytes with whole-buffer numpy operations (token boundaries, the lines from the newlines
between tokens, tags) and converts each group's numbers from the token boundaries with
``posecrb.io.decimals`` (correctly rounded, ids never through float64); it takes ASCII files whose
fields are separated by blanks (``\\r`` only in ``\\r\\n``) and gives up (``Fallback``) on anything
else: another control character, a line with another field count, a token outside the plain
decimal grammar, an id above 2^63 - 1. ``split_text`` is the reference tokeniser over ``str``; it
takes every input and locates every error, so the fast path never has to.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from itertools import chain

import numpy as np

from ..core.errors import InternalError, ParseError
from ..core.integers import IntegerError, parse_int, shown
from .decimals import decimals, integers
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

# The fast tokeniser's alphabet: printable ASCII, the blanks (tab, vertical tab, form feed) and
# newline, \r only in \r\n (other control characters and a lone \r: split_text's rules decide).
_FAST_BYTES = bytes([9, 10, 11, 12, 13] + list(range(32, 127)))
_FEW_TAGS = 8                   # tags told apart by comparison before np.unique groups the rest
_BLOCK = 1 << 18                # bytes per step of the boundary scan (its temporaries stay in the cache)


class Fallback(Exception):
    """The fast tokeniser cannot take this input; ``split_text`` decides (never leaves the module's callers)."""


def fmt_number(x: float) -> str:
    """A number as users write it (never ``np.float64(...)``)."""
    x = float(x)
    return f"{x:.6g}" if x == x and abs(x) != float("inf") else str(x)


def check_magnitude(path: str, lines: np.ndarray, tag: str, vals: np.ndarray, limit: float, what: str) -> None:
    """Every entry of each record's ``vals`` within ``limit`` in magnitude (``MAX_*`` above)."""
    if vals.size == 0 or (vals.max() <= limit and vals.min() >= -limit):
        return                    # two reductions without a temporary; rows only to locate an error
    big = np.abs(vals).reshape(vals.shape[0], -1).max(axis=1) > limit
    if big.any():
        k = int(np.flatnonzero(big)[0])
        v = vals[k].ravel()[np.argmax(np.abs(vals[k]).ravel())]
        raise ParseError(path, int(lines[k]), f"{tag}: {what} {fmt_number(v)} exceeds {fmt_number(limit)} in "
                                              "magnitude (quantities built from it would overflow)")


def _check_finite(path: str, rec: RecordKind, lines: np.ndarray, vals: np.ndarray) -> None:
    with np.errstate(over="ignore", invalid="ignore"):
        total = vals.sum()
    if np.isfinite(total):
        return                    # a finite sum has finite terms (a NaN or an inf makes it NaN or inf)
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
# Fast tokeniser: whole-buffer numpy operations, no Python loop per line or token.

def _boundaries(buf: np.ndarray) -> tuple[np.ndarray, int]:
    """Token starts and ends (alternating, sorted) of the bytes, where a byte above the blank
    (32) meets one that is not, and the number of control characters (below 32); in blocks whose
    temporaries stay in the cache, written into one array (untouched pages of its bound, one entry
    per byte, cost nothing)."""
    out = np.empty(buf.size + 1, np.intp)
    count = controls = 0
    for a in range(0, buf.size, _BLOCK):
        piece = buf[a: a + _BLOCK]
        word = piece > 32
        if word[0] != (a > 0 and buf[a - 1] > 32):
            out[count] = a
            count += 1
        change = np.flatnonzero(word[1:] != word[:-1])
        change += a + 1
        out[count: count + change.size] = change
        count += change.size
        controls += int(np.count_nonzero(piece < 32))
    if buf[-1] > 32:
        out[count] = buf.size
        count += 1
    return out[:count], controls


def _lines(buf: np.ndarray, data: bytes, tok_start: np.ndarray,
           tok_end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index of the first token of each line that has tokens, its 0-based line), from the
    newlines in the gaps between tokens: a gap of one byte is a newline or a blank; wider gaps
    (indentation, trailing blanks, empty lines) are counted."""
    gap = tok_end[:-1]                              # gap k precedes token k + 1
    starts_line = np.empty(tok_start.size, bool)
    starts_line[0] = True
    np.equal(buf[gap], 10, out=starts_line[1:])
    wide = np.flatnonzero(buf[1:][gap] <= 32)       # its second byte is a blank too
    breaks = np.empty(0, np.intp)
    if wide.size:
        newlines = np.flatnonzero(buf == 10)
        breaks = np.searchsorted(newlines, tok_start[wide + 1]) - np.searchsorted(newlines, gap[wide])
        starts_line[wide + 1] = breaks > 0
    first = np.flatnonzero(starts_line)
    step = np.ones(first.size, np.intp)             # newlines before each line's first token
    step[0] = data.count(b"\n", 0, int(tok_start[0]))
    if wide.size:
        at = np.searchsorted(first, wide + 1)
        hit = (at < first.size) & (first[np.minimum(at, first.size - 1)] == wide + 1)
        step[at[hit]] = breaks[hit]
    return first, np.cumsum(step)


def _group_tags(buf: np.ndarray, tag_start: np.ndarray, tag_len: np.ndarray) -> dict[str, np.ndarray]:
    """Positions (into the lines that have tokens) of each tag, tags in order of first occurrence.

    Per length, each tag is one fixed-width byte string (a window view of the buffer); the lines
    of the first remaining tag are split off by one comparison, which is all a file of a few
    record kinds needs. Past ``_FEW_TAGS`` kinds (comments that differ, say) np.unique groups the
    rest."""
    of_tag: dict[str, np.ndarray] = {}
    # (bincount, not np.unique on the lengths: numpy's unique consults numpy.ma, which the CLI defers)
    for length in np.flatnonzero(np.bincount(tag_len)):
        sel = np.flatnonzero(tag_len == length)
        names = np.ndarray((buf.size - length + 1,), f"S{length}", buf, strides=(1,))[tag_start[sel]]
        for _ in range(_FEW_TAGS):
            same = names == names[0]
            of_tag[names[0].decode("ascii")] = sel[same]
            sel, names = sel[~same], names[~same]
            if not sel.size:
                break
        if sel.size:
            unique, inverse = np.unique(names, return_inverse=True)
            order = np.argsort(inverse, kind="stable")
            bounds = np.searchsorted(inverse[order], np.arange(unique.size + 1))
            for u, name in enumerate(unique):
                of_tag[name.decode("ascii")] = sel[order[bounds[u]: bounds[u + 1]]]
    return {tag: of_tag[tag] for tag in sorted(of_tag, key=lambda tag: int(of_tag[tag][0]))}


def scan_bytes(data: bytes) -> Tokens:
    """The fast tokeniser (module docstring); raises ``Fallback`` where it cannot decide.

    Token starts and ends are found once over the whole buffer; each line's first token (its tag)
    is compared as a fixed-width byte string, so grouping costs a comparison per kind of tag, not a
    loop over lines. A group's numbers are converted from the token boundaries by ``posecrb.io.decimals``:
    the tokens of a run of lines of one record kind are one slice of the boundary arrays.
    """
    if not data or not data.isascii() or b"\x7f" in data:
        raise Fallback
    buf = np.frombuffer(data, dtype=np.uint8)
    bounds, controls = _boundaries(buf)
    tok_start, tok_end = bounds[0::2], bounds[1::2]       # tok_end exclusive
    if tok_start.size == 0:
        raise Fallback
    first, line = _lines(buf, data, tok_start, tok_end)
    if controls != line[-1] + data.count(b"\n", int(tok_start[first[-1]])):   # control bytes besides \n
        returns = data.count(b"\r")
        if data.translate(None, _FAST_BYTES) or (returns and returns != data.count(b"\r\n")):
            raise Fallback        # other control characters, or a lone \r (a line end): split_text's rules
    counts = np.diff(first, append=tok_start.size)          # tokens per line
    position = np.full(int(line[-1]) + 1, -1, np.intp)      # of each line among those with tokens
    position[line] = np.arange(line.size)
    tags = _group_tags(buf, tok_start[first], tok_end[first] - tok_start[first])
    groups = {tag: line[at] for tag, at in tags.items()}

    def numeric(path: str, rec: RecordKind, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        width, nid = rec.fields + 1, rec.n_ids
        at = position[idx] if idx.size else idx
        if idx.size == 0 or (counts[at] != width).any():
            raise Fallback
        tokens = first[at]
        if tokens[-1] - tokens[0] == width * (idx.size - 1):    # one run of lines: a slice, no gather
            run = slice(int(tokens[0]), int(tokens[0]) + width * idx.size)
            starts, ends = tok_start[run].reshape(-1, width), tok_end[run].reshape(-1, width)
        else:
            at_tokens = tokens[:, None] + np.arange(width)
            starts, ends = tok_start[at_tokens], tok_end[at_tokens]
        ids = integers(buf, starts[:, 1: 1 + nid], ends[:, 1: 1 + nid])
        vals = decimals(buf, starts[:, 1 + nid:], ends[:, 1 + nid:])
        if ids is None or vals is None:
            raise Fallback
        _check_finite(path, rec, idx + 1, vals)
        return ids, vals

    return Tokens(groups=groups, numeric=numeric)
