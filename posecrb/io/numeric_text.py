"""Headerless numeric text, vectorised over the whole file: data lines, their fields, the numbers
and how precisely each was written (the estimate files of posecrb.io.estimates).

Lines end at ``\\n``, ``\\r\\n`` or ``\\r``; fields are separated by blanks (space, tab, vertical tab,
form feed); a line whose first field starts with ``#`` is a comment. Numbers follow the plain
decimal grammar (no nan/inf, no ``1_0``); ids are digits only and never pass through float64.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..core.errors import ParseError

ID_MAX_DIGITS = 18            # ids below 10^18 < 2^63 fit int64 exactly
# Plain decimal numbers: no nan/inf (non-finite), no 1_0 or non-ASCII digits (float() would take them).
_BAD_NUMBER_BYTES = re.compile(rb"[^0-9eE.+\- ]")
_NUMBER = re.compile(rb"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


@dataclass(frozen=True, eq=False)
class NumericTable:
    path: str
    tokens: np.ndarray        # (T,) bytes, the non-comment tokens in file order
    line_of: np.ndarray       # (T,) 1-based line of each token
    first: np.ndarray         # (L,) index into tokens of each data line's first token
    count: np.ndarray         # (L,) tokens per data line
    line: np.ndarray          # (L,) 1-based line number of each data line
    tagged: bool              # some data line starts with a letter (a g2o/TORO record)


def scan_numeric(data: bytes, path: str) -> NumericTable:
    """Data lines and their tokens. Lines end at ``\\n``, ``\\r\\n`` or ``\\r``; fields are
    separated by blanks (space, tab, vertical tab, form feed); a line whose first field starts
    with ``#`` is a comment."""
    b = np.frombuffer(data, dtype=np.uint8)
    if b.size == 0 or not data.strip():
        raise ParseError(path, None, "is empty: no poses")
    cr = b == 13
    crlf = cr & np.concatenate([b[1:] == 10, [False]])
    newline = (b == 10) | (cr & ~crlf)
    blank = (b == 32) | (b == 9) | (b == 11) | (b == 12) | crlf
    space = newline | blank
    start = ~space & np.concatenate([[True], space[:-1]])
    line_index = np.cumsum(newline) - newline          # 0-based line of every byte
    starts = np.flatnonzero(start)
    tok_line = line_index[starts]
    tokens = np.array(data.split(), dtype=np.bytes_)
    if tokens.size != starts.size:    # pragma: no cover - the blank set above is bytes.split()'s
        raise ParseError(path, None, "could not be split into fields")
    first_of_line = np.concatenate([[True], tok_line[1:] != tok_line[:-1]])
    comment_line = first_of_line & (b[starts] == ord("#"))
    # a token is in a comment when its line's first token starts with '#'
    line_first = np.maximum.accumulate(np.where(first_of_line, np.arange(starts.size), 0))
    comment = comment_line[line_first]
    keep = ~comment
    tokens, tok_line = tokens[keep], tok_line[keep]
    if tokens.size == 0:
        raise ParseError(path, None, "is empty: no poses (only comments)")
    first_mask = np.concatenate([[True], tok_line[1:] != tok_line[:-1]])
    first = np.flatnonzero(first_mask)
    count = np.diff(np.append(first, tokens.size))
    lead = tokens[first]
    alpha = np.char.isalpha(np.strings.slice(lead, 0, 1))
    return NumericTable(path, tokens, tok_line + 1, first, count, tok_line[first] + 1, bool(alpha.any()))


def numbers(table: NumericTable, rows: np.ndarray, cols: slice, what: str) -> tuple[np.ndarray, np.ndarray]:
    """(values, quanta) of the tokens in columns ``cols`` (after the line's first token index) of
    data lines ``rows``: (k, c) float64 and their quanta. Plain decimal numbers only."""
    base = table.first[rows]
    width = cols.stop - cols.start
    idx = base[:, None] + np.arange(cols.start, cols.stop)[None, :]
    tok = table.tokens[idx]
    flat = tok.ravel()
    joined = b" ".join(flat.tolist())
    vals = None
    if not _BAD_NUMBER_BYTES.search(joined):
        try:
            vals = flat.astype(np.float64)
        except ValueError:
            vals = None
    if vals is None:
        _raise_bad_number(table, idx, what)
    assert vals is not None
    vals = vals.reshape(-1, width)
    bad = ~np.isfinite(vals).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ParseError(table.path, int(table.line[rows[k]]), f"{what}: non-finite value")
    return vals, quanta(flat).reshape(-1, width)


def quanta(tok: np.ndarray) -> np.ndarray:
    """The quantum ``10^(exponent - decimals)`` of each number token (bytes): the unit of its last
    written digit, so rounding to the written digits moved it by at most half of it.

    A token without a decimal point or an exponent is an integer written exactly (quantum 0):
    writers of floating-point values print one of them unless the value is an integer within their
    precision, and a pose made of such integers (a signed permutation) is checked as exact. Writers
    of significant digits (C's ``%g``, GTSAM's ``writeG2o``) drop trailing zeros, so ``11.9`` may
    stand for ``11.9000``: where no token of the file ends in a zero after its decimal point, every
    token is taken to carry the digits most of them have (the 90th percentile of their significant
    digits), and its quantum is the smaller of the two."""
    n = np.strings.str_len(tok)
    dot = np.strings.find(tok, b".")
    e = np.maximum(np.strings.find(tok, b"e"), np.strings.find(tok, b"E"))
    mantissa_end = np.where(e >= 0, e, n)
    decimals = np.where(dot >= 0, mantissa_end - dot - 1, 0)
    exponent = np.zeros(tok.shape, dtype=np.int64)
    has = e >= 0
    if has.any():
        exponent[has] = np.strings.slice(tok[has], e[has] + 1, n[has]).astype(np.int64)
    written = np.where((dot >= 0) | has, np.power(10.0, (exponent - decimals).astype(float)), 0.0)
    mantissa = np.strings.slice(tok, 0, mantissa_end)
    padded = (dot >= 0) & ~has & np.strings.endswith(mantissa, b"0")
    if tok.size == 0 or padded.any():
        return written
    digits = np.strings.str_len(np.strings.lstrip(
        np.strings.replace(np.strings.replace(np.strings.replace(mantissa, b".", b""), b"-", b""), b"+", b""), b"0"))
    fractional = ((dot >= 0) | has) & (digits > 0)
    if not fractional.any():
        return written
    significant = int(np.percentile(digits[fractional], 90))
    value = np.abs(tok.astype(np.float64))
    with np.errstate(divide="ignore"):
        magnitude = np.floor(np.log10(np.where(value > 0, value, 1.0)))
    implied = np.power(10.0, magnitude - significant + 1)
    return np.where(fractional, np.minimum(written, implied), written)


def integer_ids(table: NumericTable, rows: np.ndarray, what: str, column: int = 0) -> np.ndarray:
    """Token ``column`` of data lines ``rows`` as non-negative int64 ids (digits only, never via float64)."""
    tok = table.tokens[table.first[rows] + column]
    ok = np.char.isdigit(tok) & (np.strings.str_len(tok) <= ID_MAX_DIGITS)
    if not ok.all():
        k = int(np.flatnonzero(~ok)[0])
        raise ParseError(table.path, int(table.line[rows[k]]), f"{what} {tok[k].decode(errors='replace')!r} is not "
                         "a non-negative integer id that fits 64 bits")
    return tok.astype(np.int64)


def _raise_bad_number(table: NumericTable, idx: np.ndarray, what: str) -> None:
    for k in range(idx.shape[0]):          # error path only: locate the first offending token
        for t in table.tokens[idx[k]]:
            if _NUMBER.fullmatch(t) is None:
                raise ParseError(table.path, int(table.line_of[idx[k, 0]]),
                                 f"{what}: {t.decode(errors='replace')!r} is not a number")
    raise ParseError(table.path, None, f"{what}: a value is not a number")   # pragma: no cover


__all__ = ["ID_MAX_DIGITS", "NumericTable", "integer_ids", "numbers", "quanta", "scan_numeric"]
