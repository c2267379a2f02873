"""Decimal tokens of a file's bytes to float64 and int64, vectorised and correctly rounded.

The readers locate every token once (``posecrb.io.text.scan_bytes``); this module converts the
tokens ``buf[starts[k]:ends[k]]`` without a call per token. Each token is copied, right-aligned,
into a row of 8, 16 or 24 bytes (the widest token of a step of ``_CHUNK`` tokens decides); whole-row
numpy operations, over steps that stay in the cache, split it into a sign, a digit string with the
decimal point removed and an exponent, and the digits become an integer ``w < 10^19`` eight at a
time (SWAR: a 64-bit word holds eight digits, three multiply-shift steps sum them). The value is
then ``w * 10^q``; a positive power is multiplied into ``w`` while that stays below 2^64, and the
rest is one division, rounded once:

* Clinger's fast path: for ``w <= 2^53`` and ``-22 <= q <= 0`` both operands are exact doubles and
  one IEEE division rounds the exact value;
* beyond it, with x87 extended precision (``np.longdouble`` on x86-64 Linux, a 64-bit significand),
  ``w`` and ``10^-q`` (``q >= -27``, so ``5^-q < 2^64``) are exact, so one division rounds the
  exact value to 64 bits; rounding that to a double is the correctly rounded result unless the
  64-bit one lies exactly halfway between two doubles (its 11 extra bits are ``10000000000``),
  where the two roundings could differ: those few tokens go to ``strtod``.

What neither covers (more than 19 significant digits, a larger ``|q|``, a halfway case, a token
wider than ``WIDTH``) goes to ``np.fromstring`` (``strtod``, correctly rounded) once its grammar is
known. Either way each number is what Python's ``float`` reads. Only the plain decimal grammar
``[+-]digits[.digits][(e|E)[+-]digits]`` (or ``.digits``) is accepted; for anything else the
converters return None and the caller's reference tokeniser locates the error.
"""
from __future__ import annotations

import re
from functools import cache

import numpy as np

WIDTH = 24                    # widest token converted row-wise; %.17g numbers take at most 24 bytes
_WIDTHS = (8, 16, WIDTH)      # row widths: one, two or three 64-bit words
_CHUNK = 32768                # tokens per step: rows and temporaries of one step stay in the cache
_MAX_EXACT_POWER = 27         # 5^27 < 2^64: 10^q exact in the 64-bit significand for |q| <= 27
_MAX_EXPONENT_DIGITS = 4      # exponents up to 9999 are read row-wise; longer ones by strtod
_MAX_FOLD = 19                # w 10^q (q > 0) is computed in integers up to q = 19, while below 2^64
_U = np.uint64
_LE = np.dtype("<u8")         # rows of bytes as words: the row's first byte is a word's lowest
_LOW5 = _U(0xFFFFFFFFFF)      # the first five columns of a 24-byte row: above 19 digits when not zero
_PAIRS, _QUADS = _U(0x00FF00FF00FF00FF), _U(0x0000FFFF0000FFFF)
_LANES = _U(0x0101010101010101)
_INT64_MAX = _U(2 ** 63 - 1)
_DOT = ord(".") - 48 + 256    # the point after subtracting "0" from every byte
_PLAIN = re.compile(rb"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def _mask_table(width: int, columns: list[slice]) -> np.ndarray:
    """Row r: 0xFF in ``columns[r]`` of a ``width``-byte row, as one item (one take per row)."""
    table = np.zeros((len(columns), width), np.uint8)
    for r, cols in enumerate(columns):
        table[r, cols] = 0xFF
    return table.view(f"V{width}").ravel()


_LAST = {w: _mask_table(w, [slice(w - n, w) for n in range(w + 1)]) for w in _WIDTHS}     # the last n columns
_BEFORE = {w: _mask_table(w, [slice(1, c) for c in range(w + 1)]) for w in _WIDTHS}       # columns 1 .. c - 1
# 10^k and -10^k (index k + 23) as exact doubles: the sign rides on the division
_SIGNED_POW10 = np.concatenate([10.0 ** np.arange(23), -(10.0 ** np.arange(23))])
_POW10_INT = np.array([10 ** k for k in range(_MAX_FOLD + 1)], dtype=_U)
_FOLD_LIMIT = np.array([(2 ** 64 - 1) // 10 ** k for k in range(_MAX_FOLD + 1)], dtype=_U)   # w 10^k < 2^64


@cache
def _extended_powers() -> np.ndarray | None:
    """±10^0 .. ±10^27 as ``np.longdouble`` (exact: 5^k 2^k; -10^k at index k + 28) when it is the
    x87 80-bit format computing at full precision (the halfway test reads its bit layout), else None."""
    if np.finfo(np.longdouble).nmant != 63 or np.dtype(np.longdouble).itemsize != 16:
        return None
    x = np.array([2 ** 63 + 1], dtype=_U).astype(np.longdouble)
    if float((x + np.longdouble(0))[0] - np.longdouble(2 ** 63)) != 1.0:   # precision control below 64 bits
        return None
    k = np.arange(_MAX_EXACT_POWER + 1)
    powers = np.array([5 ** int(i) for i in k], dtype=_U).astype(np.longdouble) * np.exp2(k).astype(np.longdouble)
    return np.concatenate([powers, -powers])


class _Rows:
    """The ``width`` bytes before given ends of ``buf`` as rows (tokens right-aligned), by one
    fancy index of a window view; ends nearer the start than ``width`` read a padded copy."""

    def __init__(self, buf: np.ndarray):
        self.buf = buf
        self.views: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def __call__(self, ends: np.ndarray, width: int) -> np.ndarray:
        if width not in self.views:
            buf, item = self.buf, f"V{width}"
            head = np.concatenate([np.full(width, 32, np.uint8), buf[:width]])
            body = np.ndarray((max(buf.size - width + 1, 0),), item, buf, strides=(1,))
            self.views[width] = body, np.ndarray((head.size - width + 1,), item, head, strides=(1,))
        body, head = self.views[width]
        first = ends - width
        near = first < 0
        rows = body[np.maximum(first, 0)] if body.size else head[ends]
        if body.size and near.any():
            rows[near] = head[ends[near]]
        return rows.view(np.uint8).reshape(ends.size, width)


def _row_width(length: np.ndarray) -> int:
    """The row width of a step: the narrowest wider than its longest token, so that dropping a
    point never needs the first column (``WIDTH`` itself checks that column: ``fits``)."""
    longest = int(length.max())
    return next((w for w in _WIDTHS if longest < w), WIDTH)


def _single_flag(flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(count, column of the highest) of the 0/1 bytes of (T, words) words; the column is exact
    when the count is 1: the row read as one number is then 2^(8 col), exact as a double."""
    lanes = flags[:, 0].copy()
    row = flags[:, 0].astype(np.float64)
    for k in range(1, flags.shape[1]):
        lanes += flags[:, k]                                    # one 0/1 byte per lane: no carries
        row += flags[:, k].astype(np.float64) * 2.0 ** (64 * k)
    count = (lanes * _LANES) >> _U(56)
    return count.astype(np.intp), (np.frexp(row)[1] - 1) >> 3


def _digits(rows: np.ndarray, first: np.ndarray, length: np.ndarray) -> tuple[np.ndarray, ...]:
    """Split ``[+-]digits[.digits]`` tokens, right-aligned in ``rows`` (consumed; (T, 8, 16 or
    24)) with ``length`` (1..width) bytes starting with the byte ``first``.

    Returns ``w`` (uint64: the digits without the point, valid where ``fits``: at most 19
    columns), ``frac`` (digits after the point), ``neg``, ``signed``, ``dotted``, ``valid`` (the
    grammar, at least one digit) and ``fits``."""
    n, width = rows.shape
    words = width // 8
    chars = np.subtract(rows, np.uint8(48), out=rows)             # digits 0..9, every other byte above 9
    other = chars > 9
    neg = first == ord("-")
    signed = neg | (first == ord("+"))
    body = length - signed                                        # the digits and the point
    mask = np.take(_LAST[width], body).view(_LE).reshape(n, words)
    count, col = _single_flag(other.view(_LE).reshape(n, words) & mask)
    dotted = count == 1
    col[~dotted] = -1
    at = chars.reshape(-1)[np.arange(0, n * width, width) + np.maximum(col, 0)]
    valid = (count <= 1) & (body > count) & (~dotted | (at == _DOT))
    frac = np.where(dotted, width - 1 - col, 0)
    keep = other.view(np.uint8)
    keep -= 1                                                     # 0xFF at digits
    packed = np.bitwise_and(chars, keep, out=chars).view(_LE).reshape(n, words)
    packed &= mask
    # drop the point: the columns before it move one to the right. Column 0 is left alone: it is
    # outside the token (rows of 8 and 16 bytes are wider than their tokens) or, in a full row of
    # 24, fails ``fits``; so what the flat shift carries into it from the row before does not matter
    flat = packed.reshape(-1)
    shifted = flat << _U(8)
    shifted[1:] |= flat[:-1] >> _U(56)
    shifted ^= flat
    shifted &= np.take(_BEFORE[width], col + 1).view(_LE)
    flat ^= shifted
    fits = (packed[:, 0] & _LOW5) == 0 if width > 19 else np.ones(n, bool)
    flat *= _U(2561)                      # 10 * 2^8 + 1: pairs of digits
    flat >>= _U(8)
    flat &= _PAIRS
    flat *= _U(6553601)                   # 100 * 2^16 + 1: groups of four
    flat >>= _U(16)
    flat &= _QUADS
    flat *= _U(42949672960001)            # 10^4 * 2^32 + 1: eight digits per word
    flat >>= _U(32)
    w = packed[:, 0].copy()
    for k in range(1, words):
        w *= _U(10 ** 8)
        w += packed[:, k]
    return w, frac, neg, signed, dotted, valid, fits


def _scale(w: np.ndarray, q: np.ndarray, neg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(±w 10^q as float64, where that is correctly rounded) for uint64 ``w`` (consumed) and int
    ``q`` (module docstring)."""
    up = np.flatnonzero(q > 0)
    if up.size:                   # w 10^q, q > 0, is an integer: exact in w while it stays below 2^64
        k = np.minimum(q[up], _MAX_FOLD)
        fold = up[(q[up] <= _MAX_FOLD) & (w[up] <= _FOLD_LIMIT[k])]
        w[fold] *= _POW10_INT[q[fold]]
        q[fold] = 0
    down = np.clip(-q, 0, _MAX_EXACT_POWER)
    sign = neg.astype(np.intp)
    exact = (w <= _U(2 ** 53)) & (q <= 0) & (q >= -22)      # Clinger: two exact doubles, one division
    powers = _extended_powers()
    if powers is None:
        value = w.astype(np.float64)
        value /= _SIGNED_POW10[np.minimum(down, 22) + 23 * sign]
        return value, exact
    rest = np.flatnonzero(~exact)
    if rest.size * 2 > w.size:    # mostly long digit strings: all at once in extended precision
        return _extended(w, q, down, sign, powers)
    value = w.astype(np.float64)
    value /= _SIGNED_POW10[np.minimum(down, 22) + 23 * sign]
    if rest.size:
        value[rest], exact[rest] = _extended(w[rest], q[rest], down[rest], sign[rest], powers)
    return value, exact


def _extended(w: np.ndarray, q: np.ndarray, down: np.ndarray, sign: np.ndarray,
              powers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_scale`` in x87 extended precision: one rounding to 64 bits, then to 53 unless that one is
    exactly halfway between two doubles (module docstring)."""
    wide = w.astype(np.longdouble)
    wide /= powers[down + (_MAX_EXACT_POWER + 1) * sign]
    halfway = (wide.view(_U)[::2] & _U(0x7FF)) == _U(0x400)
    return wide.astype(np.float64), (q <= 0) & (q >= -_MAX_EXACT_POWER) & ~halfway


def _plain(buf: np.ndarray, rows_of: _Rows, starts: np.ndarray,
           ends: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(values, exact, valid) of tokens of at most ``WIDTH`` bytes without an exponent."""
    length = ends - starts
    w, frac, neg, _, _, valid, fits = _digits(rows_of(ends, _row_width(length)), buf[starts], length)
    value, exact = _scale(w, -frac, neg)
    return value, exact & fits, valid


def _with_exponent(buf: np.ndarray, rows_of: _Rows, starts: np.ndarray,
                   ends: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(values, exact, valid) of tokens of at most ``WIDTH`` bytes read as mantissa (e|E)[+-]digits:
    the token's only e splits it, and each side is read as a token of its own."""
    inside = np.take(_LAST[WIDTH], ends - starts).view(_LE).reshape(-1, 3)
    count, col = _single_flag(((rows_of(ends, WIDTH) | np.uint8(0x20)) == ord("e")).view(_LE).reshape(-1, 3)
                              & inside)
    at = ends - (WIDTH - col)                                      # the e's offset in buf
    valid = (count == 1) & (at > starts) & (at < ends - 1)
    k = np.flatnonzero(valid)
    value, exact = np.zeros(starts.size), np.zeros(starts.size, bool)
    if not k.size:
        return value, exact, valid
    s, e, at = starts[k], ends[k], at[k]
    w, frac, neg, _, _, mantissa, fits = _digits(rows_of(at, _row_width(at - s)), buf[s], at - s)
    ew, _, eneg, _, edotted, exponent, efits = _digits(rows_of(e, _row_width(e - at - 1)), buf[at + 1], e - at - 1)
    valid[k] = mantissa & exponent & ~edotted
    small = efits & (ew < _U(10 ** _MAX_EXPONENT_DIGITS))
    power = np.where(small, ew, _U(0)).astype(np.intp)
    value_k, exact_k = _scale(w, np.where(eneg, -power, power) - frac, neg)
    value[k], exact[k] = value_k, exact_k & fits & small
    return value, exact, valid


def _row_chunks(starts: np.ndarray) -> range:
    """Row offsets of the steps over (k, c) token arrays, about ``_CHUNK`` tokens each."""
    return range(0, starts.shape[0], max(1, _CHUNK // max(1, starts.shape[1])))


def _same_bytes(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> bool:
    """Whether every ``buf[starts[i]:ends[i]]`` is the first one's bytes."""
    size = int(ends[0] - starts[0])
    view = np.ndarray((buf.size - size + 1,), f"S{size}", buf, strides=(1,))
    return bool(((ends - starts) == size).all() and (view[starts] == view[starts[0]]).all())


def _constant_columns(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Which columns hold one token throughout (the same bytes on every row): an information
    matrix shared by every edge, as most datasets have, is then read once. Rows spread over the
    column rule most columns out; a run of the remaining columns is compared as one span of bytes
    (tokens and blanks), and column by column only when the span differs."""
    sample = slice(None, None, max(1, starts.shape[0] // 64))
    constant = np.array([_same_bytes(buf, starts[sample, j], ends[sample, j]) for j in range(starts.shape[1])])
    constant &= ends[0] - starts[0] <= WIDTH
    edges = np.diff(np.concatenate(([0], constant.view(np.int8), [0])))
    for first, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if not _same_bytes(buf, starts[:, first], ends[:, stop - 1]):
            constant[first: stop] = [_same_bytes(buf, starts[:, j], ends[:, j]) for j in range(first, stop)]
    return constant


def decimals(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
    """float64 of the tokens ``buf[starts[i, j]:ends[i, j]]`` ((k, c) arrays, views welcome; uint8
    ``buf``), each as Python's ``float`` reads it, or None when one is not a plain decimal number
    (module docstring). A column of one repeated token is read once."""
    if starts.shape[0] < 2:
        return _decimals(buf, starts, ends)
    constant = _constant_columns(buf, starts, ends)
    if not constant.any():
        return _decimals(buf, starts, ends)
    out = np.empty(starts.shape)
    once = _decimals(buf, starts[:1, constant], ends[:1, constant])
    rest = _decimals(buf, starts[:, ~constant], ends[:, ~constant]) if not constant.all() else out[:, :0]
    if once is None or rest is None:
        return None
    out[:, constant] = once
    out[:, ~constant] = rest
    return out


def _decimals(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
    """``decimals`` token by token."""
    out = np.empty(starts.shape)
    flat = out.reshape(-1)
    columns = starts.shape[1]
    rows_of = _Rows(buf)
    hard: list[np.ndarray] = []        # flat indices left to strtod
    exponent: list[np.ndarray] = []    # flat indices of tokens that are not plain mantissas
    steps = _row_chunks(starts)
    for a in steps:
        s, e = starts[a: a + steps.step].ravel(), ends[a: a + steps.step].ravel()
        short = e - s <= WIDTH
        if not short.all():
            s = np.where(short, s, e - 1)                           # a stand-in: strtod reads these
        value, exact, valid = _plain(buf, rows_of, s, e)
        flat[a * columns: a * columns + value.size] = value
        hard.append(a * columns + np.flatnonzero(valid & ~exact | ~short))
        exponent.append(a * columns + np.flatnonzero(~valid & short))
    others = np.concatenate(exponent) if exponent else np.empty(0, np.intp)
    for a in range(0, others.size, _CHUNK):
        k = others[a: a + _CHUNK]
        row, col = np.divmod(k, columns)
        value, exact, valid = _with_exponent(buf, rows_of, starts[row, col], ends[row, col])
        if not valid.all():
            return None
        flat[k] = value
        hard.append(k[~exact])
    slow = np.concatenate(hard) if hard else np.empty(0, np.intp)
    if slow.size:
        row, col = np.divmod(slow, columns)
        data = buf.data.cast("B")
        tokens = [bytes(data[i:j]) for i, j in zip(starts[row, col].tolist(), ends[row, col].tolist())]
        if any(_PLAIN.fullmatch(t) is None for t in tokens if len(t) > WIDTH):
            return None
        values = np.fromstring(b" ".join(tokens), dtype=np.float64, sep=" ")
        if values.size != slow.size:     # pragma: no cover - every token matched the grammar
            return None
        flat[slow] = values
    return out


def _short_integers(rows: np.ndarray, length: np.ndarray) -> np.ndarray | None:
    """uint64 of digit-only tokens of 1 to 8 bytes, right-aligned in (T, 8) ``rows`` (consumed)."""
    n = rows.shape[0]
    chars = np.subtract(rows, np.uint8(48), out=rows)
    mask = np.take(_LAST[8], length).view(_LE)
    if ((chars > 9).view(_LE).reshape(n) & mask).any():
        return None
    words = chars.view(_LE).reshape(n)
    words &= mask
    words *= _U(2561)
    words >>= _U(8)
    words &= _PAIRS
    words *= _U(6553601)
    words >>= _U(16)
    words &= _QUADS
    words *= _U(42949672960001)
    words >>= _U(32)
    return words


def integers(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
    """int64 of the digit-only tokens ``buf[starts[i, j]:ends[i, j]]`` ((k, c) arrays), or None
    when one has another character, more than ``WIDTH`` digits or a value above 2^63 - 1. Never
    through float64."""
    out = np.empty(starts.shape, np.int64)
    steps = _row_chunks(starts)
    rows_of = _Rows(buf)
    for a in steps:
        s, e = starts[a: a + steps.step].ravel(), ends[a: a + steps.step].ravel()
        length = e - s
        if length.max() > WIDTH:
            return None
        width = _row_width(length)
        if width == 8:              # ids below 10^7: one word each, no sign or point to look for
            w = _short_integers(rows_of(e, 8), length)
            if w is None:
                return None
        else:
            w, _, _, signed, dotted, valid, fits = _digits(rows_of(e, width), buf[s], length)
            if not (valid & fits & ~signed & ~dotted & (w <= _INT64_MAX)).all():
                return None
        out[a: a + steps.step] = w.view(np.int64).reshape(-1, starts.shape[1])
    return out
