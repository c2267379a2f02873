"""The vectorised tokeniser (posecrb.io.text.scan_bytes) against the reference one (split_text).

``load`` tries the fast tokeniser first and falls back to the reference one wherever the fast
one gives up, so every input must give the same graph, bit for bit, or the same error (file,
line, reason) whichever path decides. Checked on every real dataset (which must all take the
fast path), on the hostile corpus, on numbers against Python's ``float`` (correctly rounded),
and on generated files with odd tokens, blank lines, comments, indentation, tabs, CRLF and
interleaved records.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from posecrb.core.errors import ParseError
from posecrb.io import FORMATS, parse_bytes
from posecrb.io.lines import decode_utf8
from posecrb.io.reader import parse
from posecrb.io.text import Fallback, scan_bytes, split_text

from ..hostile.corpus import CASES

ARRAYS = ("ids", "src", "dst", "rot", "trans", "info", "vertex_rot", "vertex_trans", "edge_lines")
PROPERTY = settings(derandomize=True, max_examples=50, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])
INFO2 = "500 0 0 500 0 1000"


def _reference(data: bytes, path: str = "t.g2o"):
    return parse(split_text(decode_utf8(data, path)), FORMATS, path)


def _outcome(fn):
    try:
        return "graph", fn()
    except ParseError as exc:
        return "error", (exc.line, str(exc))


def _assert_same_graph(a, b) -> None:
    assert (a.dim, a.format, a.skipped, a.path) == (b.dim, b.format, b.skipped, b.path)
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape, name
            assert np.array_equal(x, y), name
    np.testing.assert_array_equal(a.tau, b.tau)
    np.testing.assert_array_equal(a.kappa, b.kappa)


def _assert_same_outcome(data: bytes, path: str = "t.g2o") -> None:
    got = _outcome(lambda: parse_bytes(data, path))
    want = _outcome(lambda: _reference(data, path))
    assert got[0] == want[0], (got, want)
    if got[0] == "error":
        assert got[1] == want[1]
    else:
        _assert_same_graph(got[1], want[1])


def test_every_real_dataset_takes_the_fast_path_and_gives_the_reference_graph(shared_datasets):
    files = sorted(p for p in shared_datasets.rglob("*") if p.suffix in (".g2o", ".graph", ".toro"))
    assert len(files) >= 16
    for path in files:
        data = path.read_bytes()
        fast = parse(scan_bytes(data), FORMATS, str(path))   # no Fallback on real files
        _assert_same_graph(fast, _reference(data, str(path)))


@pytest.mark.parametrize("name", sorted(CASES))
def test_hostile_corpus_same_outcome_on_both_paths(name):
    case = CASES[name]
    data = case.text if isinstance(case.text, bytes) else case.text.encode("utf-8")
    _assert_same_outcome(data)


def test_fast_path_gives_up_rather_than_guess():
    """Inputs outside the fast path's alphabet or grammar go to the reference tokeniser."""
    line = f"EDGE_SE2 0 1 1 0 0 {INFO2}\n"
    odd = (line.replace("\n", "\r"), line + "\r" + line, line.replace(" 1 0 0", " 1\x1c0 0"), "# \u00e9\n" + line,
           line.replace(" 1 0 0", " 1\x7f 0 0"))
    bad_ids = (line.replace("0 1", f"0 {2 ** 63}"), line.replace("0 1", "0 +1"), line.replace("0 1", "0 1.0"),
               line.replace("0 1", "0 " + "0" * 24 + "1"))
    bad_numbers = tuple(line.replace("1 0 0", f"{token} 0 0") for token in ("nan", "1_0", "1e5e5"))
    for data in odd + bad_ids + bad_numbers:
        with pytest.raises(Fallback):
            parse(scan_bytes(data.encode("utf-8")), FORMATS, "t.g2o")
        _assert_same_outcome(data.encode("utf-8"))


def test_fast_path_takes_every_plain_layout():
    """CRLF, tabs, vertical tabs and form feeds between fields, indentation, trailing blanks, empty
    lines, interleaved records and ids up to 2^63 - 1 are read by the fast tokeniser, as the
    reference reads them."""
    line = f"EDGE_SE2 0 1 1 0 0 {INFO2}\n"
    vertex = "VERTEX_SE2 {} 0 0 0\n"
    for data in (line.replace("\n", "\r\n") * 2, line.replace(" 1 0 0", " 1\f0\v0\t"), "\n\n  " + line + " \n",
                 line.replace("0 1", f"0 {2 ** 63 - 1}"), line.replace("0 1", f"0 {2 ** 53 + 1}"),
                 vertex.format(0) + line + vertex.format(1), line.replace("1 0 0", "1.5e-300 1E+2 -.5") + "\n\n",
                 line.replace("0 1", "00 0001"), line + "# a comment with \t a tab\n" + line.replace("0 1", "1 2")):
        data_bytes = data.encode()
        fast = parse(scan_bytes(data_bytes), FORMATS, "t.g2o")     # no Fallback
        _assert_same_graph(fast, _reference(data_bytes))


_NUMBER_FORMATS = ["{!r}", "{:.17g}", "{:.25g}", "{:.3e}", "{:.0f}", "{:+.20E}", "{:.40f}"]


@PROPERTY
@given(x=st.floats(allow_nan=False, allow_infinity=False, min_value=-1e40, max_value=1e40),
       fmt=st.sampled_from(_NUMBER_FORMATS))
def test_numbers_are_read_as_python_float_reads_them(x, fmt):
    token = fmt.format(x)
    graph = parse_bytes(f"EDGE_SE2 0 1 {token} 0 0 {INFO2}\n".encode(), "n.g2o")
    assert graph.trans[0, 0] == float(token)   # Python's float is correctly rounded


_TOKEN = st.text(alphabet="0123456789.eE+-", min_size=1, max_size=7)


@PROPERTY
@given(token=_TOKEN, field=st.integers(0, 10))
def test_odd_tokens_same_outcome(token, field):
    fields = f"0 1 1 0 0 {INFO2}".split()
    fields[field] = token
    _assert_same_outcome(f"EDGE_SE2 {' '.join(fields)}\nEDGE_SE2 1 2 1 0 0 {INFO2}\n".encode())


@st.composite
def _files(draw) -> bytes:
    """Small 2D graphs written with random layout: blank lines, comments, indentation, runs of
    blanks and tabs, CRLF, vertices before, after or between edges, skipped records, a bad field."""
    n = draw(st.integers(2, 6))
    records = [f"VERTEX_SE2 {i} {i} 0 0.5" for i in range(n)] if draw(st.booleans()) else []
    records += [f"EDGE_SE2 {i} {i + 1} 1 0 0.1 {INFO2}" for i in range(n - 1)]
    records += draw(st.lists(st.sampled_from(["# a comment", "#", "FIX 0", "", "   ", "\t"]), max_size=4))
    records = draw(st.permutations(records))
    sep = draw(st.sampled_from([" ", "  ", "\t", " \t "]))
    out = []
    for rec in records:
        lead = draw(st.sampled_from(["", "", " ", "\t"]))
        trail = draw(st.sampled_from(["", "", " ", "\t "]))
        out.append(lead + sep.join(rec.split(" ")) + trail)
    if draw(st.booleans()) and out:
        k = draw(st.integers(0, len(out) - 1))
        out[k] = out[k] + draw(st.sampled_from([" 7", " x", " 1e", " --1", " 0x1"]))
    end = draw(st.sampled_from(["\n", "\n", "\r\n"]))
    final = draw(st.sampled_from(["", end]))
    return (end.join(out) + final).encode()


@PROPERTY
@given(data=_files())
def test_layouts_same_outcome(data):
    _assert_same_outcome(data)


def _near_halfway(x: float, digits: int, up: bool) -> str:
    """A decimal with ``digits`` significant digits just below or above the midpoint between
    ``x`` and the next double up: the hardest inputs for a correctly rounded conversion."""
    from decimal import ROUND_CEILING, ROUND_FLOOR, Context, Decimal

    mid = (Decimal(x) + Decimal(np.nextafter(x, np.inf))) / 2
    ctx = Context(prec=digits, rounding=ROUND_CEILING if up else ROUND_FLOOR)
    return format(ctx.plus(mid), "f")


def test_fast_path_reads_numbers_as_python_float():
    """The fast tokeniser's numbers against Python's float (correctly rounded) on 7*10^4 tokens:
    random doubles in the formats files use, long random digit strings, and decimals within
    10^-19 relative of a halfway point between two doubles."""
    rng = np.random.default_rng(7)
    xs = rng.standard_normal(4000) * 10.0 ** rng.integers(-8, 9, 4000)
    fmts = ["{!r}", "{:.17g}", "{:.16g}", "{:.15g}", "{:.18g}", "{:.19g}", "{:.20g}", "{:.6g}", "{:.12e}",
            "{:.3f}", "{:+.9E}", "{:.0f}"]
    tokens = [f.format(float(x)) for x in xs for f in fmts]
    for _ in range(20000):
        digits = "".join(rng.choice(list("0123456789"), rng.integers(1, 22)))
        cut = int(rng.integers(0, len(digits) + 1))
        tokens.append(("-" if rng.random() < 0.5 else "") + digits[:cut] + "." + digits[cut:] + "0")
    tokens += [_near_halfway(float(abs(x)), d, up) for x in xs[:1500] for d in (17, 19) for up in (False, True)]
    tokens += ["0", "-0", "+0.0", "1e22", "1e-22", "9007199254740993", "9007199254740992.5", "0.1e+001", "5.e-3"]
    data = "".join(f"EDGE_SE2 {k} {k + 1} {t} 0 0 {INFO2}\n" for k, t in enumerate(tokens)).encode()
    got = parse(scan_bytes(data), FORMATS, "n.g2o").trans[:, 0]   # no Fallback
    want = np.array([float(t) for t in tokens])
    np.testing.assert_array_equal(got, want)
    assert np.array_equal(np.signbit(got), np.signbit(want))   # -0 stays -0
