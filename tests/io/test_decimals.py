"""posecrb.io.decimals, the vectorised reader of decimal tokens, against Python's ``float`` and ``int``.

Python's ``float`` is correctly rounded, so every number must equal it bit for bit (sign of zero
included): random doubles in the formats files use, random digit strings up to and beyond the
row widths, exponents inside and outside the range read row-wise, decimals next to a halfway point
between two doubles (where a second rounding could go wrong), each with and without x87 extended
precision. Anything outside the plain decimal grammar gives None.
"""
from __future__ import annotations

import re
from decimal import ROUND_CEILING, ROUND_FLOOR, Context, Decimal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from posecrb.io import decimals
from posecrb.io.decimals import WIDTH, integers

PLAIN = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def _layout(tokens: list[str], columns: int = 1, sep: str = " ") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bytes of ``tokens`` joined by ``sep``, and (k, columns) token starts and ends."""
    data = sep.join(tokens).encode()
    lengths = np.array([len(t) for t in tokens])
    starts = np.concatenate(([0], np.cumsum(lengths + len(sep))[:-1]))
    return (np.frombuffer(data, np.uint8), starts.reshape(-1, columns), (starts + lengths).reshape(-1, columns))


def _read(tokens: list[str], columns: int = 1) -> np.ndarray | None:
    got = decimals.decimals(*_layout(tokens, columns))
    return None if got is None else got.ravel()


def _assert_as_float(tokens: list[str], got: np.ndarray | None) -> None:
    want = np.array([float(t) for t in tokens])
    assert got is not None
    bad = np.flatnonzero((got != want) | (np.signbit(got) != np.signbit(want)))
    assert not bad.size, [(tokens[k], got[k], want[k]) for k in bad[:5]]


def _near_halfway(x: float, digits: int, up: bool) -> str:
    """A decimal with ``digits`` significant digits just below or above the midpoint between
    ``x`` and the next double up."""
    mid = (Decimal(x) + Decimal(np.nextafter(x, np.inf))) / 2
    return format(Context(prec=digits, rounding=ROUND_CEILING if up else ROUND_FLOOR).plus(mid), "e")


def _tokens(rng: np.random.Generator) -> list[str]:
    xs = rng.standard_normal(3000) * 10.0 ** rng.integers(-40, 40, 3000)
    fmts = ["{!r}", "{:.17g}", "{:.16g}", "{:.15g}", "{:.19g}", "{:.20g}", "{:.6g}", "{:.12e}", "{:.3f}",
            "{:+.9E}", "{:.0f}", "{:.30f}"]
    tokens = [f.format(float(x)) for x in xs for f in fmts]
    for _ in range(20000):      # random digit strings from 1 to 27 digits, a point anywhere, exponents
        digits = "".join(rng.choice(list("0123456789"), rng.integers(1, 28)))
        cut = int(rng.integers(0, len(digits) + 1))
        token = str(rng.choice(["", "-", "+"])) + digits[:cut] + "." + digits[cut:]
        if rng.random() < 0.3:
            token += str(rng.choice(["e", "E"])) + str(rng.choice(["", "-", "+"])) + str(rng.integers(0, 40))
        tokens.append(token if rng.random() < 0.8 else token.replace(".", ""))
    tokens += [_near_halfway(float(abs(x)), d, up) for x in xs[:1000] for d in (17, 18, 19) for up in (False, True)]
    tokens += ["0", "-0", "+0.0", "0e400", "1e22", "1e23", "1e-22", "9007199254740993", "9007199254740992.5",
               "0.1e+001", "5.e-3", ".5", "5.", "1e308", "1e-308", "4.9e-324", "2.4703282292062328e-324", "1e400",
               "-1e400", "1e-400", "1e0005", "1e" + "0" * 30 + "5", "0" * 40 + "1.5", "1" + "0" * 30,
               "." + "0" * 30 + "1", "18446744073709551615", "18446744073709551616", "9999999999999999999",
               "1234567.", ".1234567", "1234567.8", "123456789012345.", "12345678901234.5"]
    return tokens


@pytest.fixture(scope="module")
def tokens() -> list[str]:
    return _tokens(np.random.default_rng(11))


@pytest.mark.parametrize("extended", [True, False], ids=["x87", "doubles-only"])
def test_numbers_are_read_as_python_float_reads_them(tokens, extended, monkeypatch):
    if not extended:
        monkeypatch.setattr(decimals, "_extended_powers", lambda: None)
    elif decimals._extended_powers() is None:
        pytest.skip("np.longdouble is not x87 extended precision here")
    _assert_as_float(tokens, _read(tokens))
    by_length = sorted(tokens, key=len)       # steps of short tokens take the 8- and 16-byte rows
    _assert_as_float(by_length, _read(by_length))
    _assert_as_float(tokens[:3000], _read(tokens[:3000], columns=3))


def test_halfway_cases_go_to_strtod():
    """64-bit results exactly halfway between two doubles are not taken from the double rounding:
    the tokens built to land there are flagged, and every value taken is Python's."""
    if decimals._extended_powers() is None:
        pytest.skip("np.longdouble is not x87 extended precision here")
    rng = np.random.default_rng(3)
    xs = (1 + rng.random(4000)) * 2.0 ** rng.integers(-20, 20, 4000)
    tokens = [_near_halfway(float(x), 19, up) for x in xs for up in (False, True)]
    mantissa = [t.split("e")[0].replace(".", "") for t in tokens]
    w = np.array([int(m) for m in mantissa], dtype=np.uint64)
    q = np.array([int(t.split("e")[1]) - (len(m) - 1) for t, m in zip(tokens, mantissa)])
    value, exact = decimals._scale(w.copy(), q.copy(), np.zeros(w.size, bool))
    want = np.array([float(t) for t in tokens])
    assert 0 < np.count_nonzero(~exact) < w.size // 2
    np.testing.assert_array_equal(value[exact], want[exact])
    _assert_as_float(tokens, _read(tokens))


@settings(derandomize=True, max_examples=300, deadline=None, database=None)
@given(token=st.text(alphabet="0123456789.eE+-", min_size=1, max_size=30))
def test_odd_tokens_are_numbers_exactly_when_the_grammar_says_so(token):
    got = _read(["1", token, "2"])
    if PLAIN.fullmatch(token) is None:
        assert got is None
    else:
        _assert_as_float(["1", token, "2"], got)


@pytest.mark.parametrize("token", ["1.2.3", "-", ".", "+", "e5", "5e", "1e+", "1e5.5", "--1", "1-2", "0x1", "nan",
                                   "inf", "1_0", "+-1", "1e5e5", "1ee5", "-.e1", "." * 30, "1" * 30 + "x", "1,5"])
def test_what_is_not_a_plain_decimal_is_refused(token):
    assert _read(["1.5", token]) is None
    assert _read(["0.25"] * 40000 + [token]) is None      # also in a later step than the first


def test_tokens_at_the_start_of_a_short_buffer():
    for tokens in (["5"], ["-7.25"], ["1e3", "2"], ["123456789.5"], ["0.000001", "-1"]):
        _assert_as_float(tokens, _read(tokens))
    buf, starts, ends = _layout(["7"])
    assert integers(buf, starts, ends).tolist() == [[7]]


def test_integers_are_exact_and_refuse_what_is_not_an_id():
    ids = ["0", "5", "007", "1234567", "12345678", str(2 ** 53 + 1), str(2 ** 63 - 1), "0" * WIDTH]
    got = integers(*_layout(ids))
    assert got is not None and got.ravel().tolist() == [int(t) for t in ids]
    for token in (str(2 ** 63), "99999999999999999999", "-1", "+1", "1.0", "1e5", "0" * (WIDTH + 1), "1a", " "):
        assert integers(*_layout(["1", token])) is None, token
    many = [str(k) for k in range(100000)]
    np.testing.assert_array_equal(integers(*_layout(many, columns=2)).ravel(), np.arange(100000))


def _rows_layout(rows: list[list[str]], seps: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lines of tokens, row i's tokens joined by ``seps[i]``; (k, c) starts and ends."""
    data, starts, ends = "", [], []
    for row, sep in zip(rows, seps):
        for j, token in enumerate(row):
            if j:
                data += sep
            starts.append(len(data))
            data += token
            ends.append(len(data))
        data += "\n"
    c = len(rows[0])
    return np.frombuffer(data.encode(), np.uint8), np.array(starts).reshape(-1, c), np.array(ends).reshape(-1, c)


@pytest.mark.parametrize("change", ["none", "last digit", "longer", "separator", "first row", "every row"])
def test_a_column_of_one_repeated_token_gives_every_row_its_own_value(change):
    """Columns repeated on every row are read once; a row that differs anywhere (a digit, the
    length, the blanks inside a run of such columns) is read on its own."""
    k = 3000
    rows = [[f"{0.1 * i!r}", "399.99999999999994", "0", "0", "199.99999999999997", "-2.5e-3"] for i in range(k)]
    seps = [" "] * k
    if change == "last digit":
        rows[-1][1] = "399.99999999999995"
    elif change == "longer":
        rows[k // 2][2] = "0.0"
    elif change == "separator":
        seps[7] = "  "
    elif change == "first row":
        rows[0][4] = "199.99999999999999"
    elif change == "every row":
        rows = [[row[0], str(i), *row[2:]] for i, row in enumerate(rows)]
    buf, starts, ends = _rows_layout(rows, seps)
    got = decimals.decimals(buf, starts, ends)
    want = np.array([[float(t) for t in row] for row in rows])
    np.testing.assert_array_equal(got, want)
    varies = {"none": [], "last digit": [1], "longer": [2], "separator": [], "first row": [4], "every row": [1]}
    expected = np.ones(6, bool)
    expected[[0, *varies[change]]] = False
    np.testing.assert_array_equal(decimals._constant_columns(buf, starts, ends), expected)
