"""The input layer (posecrb/core/inputs.py, posecrb/io/lines.py) and every reader behind it.

Guards: only regular files, a size bound from the available memory, gzip recognised by its magic
bytes and bounded when decompressed, the readers' line rules for every text input. Then
property-based fuzzing (hypothesis, derandomized: the same examples every run) of every reader:
whatever the bytes, the result is a parsed value or a ``ParseError`` naming the file, never
another exception.
"""
from __future__ import annotations

import gzip
import hashlib
import json
import math
import os
import re
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from posecrb.cli import main
from posecrb.core import inputs
from posecrb.core.errors import DisconnectedGraph, ParseError, PosecrbError
from posecrb.core.graph import PoseGraph
from posecrb.core.inputs import gunzip, read_input
from posecrb.datasets.manifest import ManifestError, parse_manifest
from posecrb.evaluation.regress import parse_expected
from posecrb.io import load, parse_bytes
from posecrb.io.lines import Line, decode_utf8, read_lines, split_fields, split_lines

from ..hostile.corpus import INFO2, ODD_SEPARATORS, graph2, graph3, text

FUZZ = settings(derandomize=True, max_examples=300, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# ---------------------------------------------------------------- guards
def test_gzip_graph_reads_as_the_plain_one(tmp_path, capsys):
    """Datasets are often distributed as .g2o.gz: read transparently, same numbers; the sha256 is the
    stored file's."""
    plain = tmp_path / "g.g2o"
    plain.write_text(text(graph2()))
    packed = tmp_path / "g.g2o.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    a, b = load(plain), load(packed)
    np.testing.assert_array_equal(a.trans, b.trans)
    np.testing.assert_array_equal(a.info, b.info)
    assert (a.src.tolist(), a.dst.tolist()) == (b.src.tolist(), b.dst.tolist())
    assert b.sha256 == hashlib.sha256(packed.read_bytes()).hexdigest() != a.sha256
    capsys.readouterr()
    assert main(["info", str(packed), "--format", "json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert (row["dataset"], row["edges"]) == ("g", 6)


def test_a_bare_name_finds_its_gzip_file(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    (tmp_path / "mine.g2o.gz").write_bytes(gzip.compress(text(graph2()).encode()))
    capsys.readouterr()
    assert main(["info", "mine", "--data-dir", str(tmp_path), "--format", "json"]) == 0
    assert json.loads(capsys.readouterr().out)["poses"] == 5


@pytest.mark.parametrize("damage, reason", [(lambda z: z[: len(z) // 2], "truncated gzip data"),
                                            (lambda z: z[:12] + bytes(b ^ 0xFF for b in z[12:40]) + z[40:],
                                             "corrupt gzip data"),
                                            (lambda z: z + b"trailing garbage", "trailing data after the gzip")])
def test_damaged_gzip_is_a_parse_error_naming_the_file(tmp_path, damage, reason):
    f = tmp_path / "g.g2o.gz"
    f.write_bytes(damage(gzip.compress(text(graph2()).encode())))
    with pytest.raises(ParseError, match=reason) as exc:
        load(f)
    assert exc.value.path == str(f)


def test_a_gzip_bomb_stops_at_the_bound(tmp_path):
    """The decompressed size is bounded like the file's own: 64 MiB of zeros against a 1 MiB bound."""
    bomb = gzip.compress(b"\0" * (64 << 20), compresslevel=9)
    f = tmp_path / "bomb.g2o.gz"
    f.write_bytes(bomb)
    assert len(bomb) < 1 << 20
    with pytest.raises(ParseError, match="need about 16 times as much memory"):
        read_input(f, max_bytes=1 << 20)


def test_a_file_larger_than_its_stat_is_read_whole_up_to_the_bound():
    """The read asks for the size stat gave plus one byte; a file with more (one that grew, or a
    /proc file whose stat says 0 bytes) is read on up to the bound, and beyond it refused."""
    status = Path("/proc/self/status")
    if not status.is_file() or status.stat().st_size:
        pytest.skip("no /proc file whose stat size is 0 here")
    data = inputs.read_regular_file(status)
    assert len(data) > 1 and data.startswith(b"Name:") and data.endswith(b"\n")
    with pytest.raises(ParseError, match="more than 10 bytes need about 16 times as much memory"):
        inputs.read_regular_file(status, max_bytes=10)


def test_size_guard_is_derived_from_the_available_memory(tmp_path, monkeypatch):
    f = tmp_path / "g.g2o"
    f.write_text(text(graph2()) + "# " + "x" * (2 << 20) + "\n")     # above the 1 MiB floor of the bound
    size = f.stat().st_size
    monkeypatch.setattr(inputs, "available_memory", lambda: inputs.INPUT_EXPANSION * (size - 1))
    with pytest.raises(ParseError, match=f"{size} bytes need about 16 times as much memory to read"):
        load(f)
    monkeypatch.setattr(inputs, "available_memory", lambda: inputs.INPUT_EXPANSION * (1 << 30))
    assert load(f).m == 6


@pytest.mark.timeout(60)
def test_devices_and_fifos_are_named_not_read(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path, what in ((fifo, "a FIFO (named pipe)"), ("/dev/zero", "a character device"),
                       (tmp_path, "a directory")):
        for reader in (read_input, read_lines, inputs.check_input_file):
            with pytest.raises(ParseError, match=re.escape(f"is {what}, not a regular file")):
                reader(path)


def test_line_rules_are_the_graph_readers(tmp_path):
    """read_lines: lines end at \\n, \\r\\n, \\r only; fields split at ASCII blanks only; numbers exact."""
    body = "1 2\f# 3 4\r\n5\v6\u2028# x\r7\xa08\n\n9 10  # tail\n"
    f = tmp_path / "pairs.txt"
    f.write_bytes(body.encode())
    lines = read_lines(f)
    assert [ln.number for ln in lines] == [1, 2, 3, 4, 5]
    assert [ln.fields() for ln in lines] == [["1", "2"], ["5", "6\u2028"], ["7\xa08"], [], ["9", "10"]]
    assert lines[0].fields(comment=None) == ["1", "2", "#", "3", "4"]
    assert split_lines("a\fb\x1cc\x85d\u2029e") == ["a\fb\x1cc\x85d\u2029e"]
    assert split_fields("a\x1cb c") == ["a\x1cb", "c"]
    f.write_bytes(gzip.compress(body.encode()))
    assert read_lines(f) == lines                      # gzip transparently
    f.write_bytes(b"1 2\n3 \xff4\n")
    with pytest.raises(ParseError, match=r"pairs.txt:2: not a text file \(invalid UTF-8\)"):
        read_lines(f)


# ---------------------------------------------------------------- fuzzing every reader
_TAGS = ["EDGE_SE2", "VERTEX_SE2", "EDGE_SE3:QUAT", "VERTEX_SE3:QUAT", "EDGE2", "VERTEX2", "EDGE3", "VERTEX3",
         "FIX", "#", "# comment", "EDGE_SE2_XY", "UNKNOWN", "edge_se2", ""]
_NUMBERS = ["0", "1", "2", "3", "-1", "1.5", "1e3", "1e-300", "1e300", "1e308", "1e309", "5e-324", "nan", "inf",
            "-inf", "1_0", "\u0661", "+0", ".5", "5.", "1e", "e5", "--1", "0x10", "9223372036854775807",
            "9223372036854775808", "18446744073709551616", "500", "1000", "0.7071", "-0.7071"]
_SEPARATORS = [" ", "  ", "\t", *ODD_SEPARATORS.values(), "\xa0", "\u3000"]
_LINE_ENDS = ["\n", "\r\n", "\r", "\f", "\u2028", "\x85", ""]


@st.composite
def _graph_text(draw) -> str:
    """Text near the readers' grammar: valid graphs with mutated lines, odd separators and line ends,
    numbers at and beyond every limit."""
    base = draw(st.sampled_from([graph2(), graph2(vertices=False), graph3(), []]))
    lines = list(base)
    for _ in range(draw(st.integers(0, 6))):
        tag = draw(st.sampled_from(_TAGS))
        fields = draw(st.lists(st.sampled_from(_NUMBERS), min_size=0, max_size=31))
        sep = draw(st.sampled_from(_SEPARATORS))
        new = sep.join([tag, *fields])
        if lines and draw(st.booleans()):
            lines[draw(st.integers(0, len(lines) - 1))] = new
        else:
            lines.insert(draw(st.integers(0, len(lines))), new)
    end = draw(st.sampled_from(_LINE_ENDS))
    return end.join(lines) + draw(st.sampled_from(["", "\n"]))


@st.composite
def _graph_numbers(draw) -> bytes:
    """Valid graphs in the fast tokeniser's alphabet whose poses and measurements are any finite
    numbers, written in every common notation: both tokenisers must convert them alike."""
    out = []
    for line in draw(st.sampled_from([graph2(), graph3()])):
        f = line.split()
        start = 3 if f[0].startswith("EDGE") else 2
        for i in range(start, start + (3 if f[0].endswith("SE2") else 7)):
            x = draw(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6))
            f[i] = draw(st.sampled_from(["{!r}", "{:.17g}", "{:.3e}", "{:.20f}", "{:g}", "{:+.6E}"])).format(x)
        out.append(draw(st.sampled_from([" ", "\t", "  "])).join(f))
    return ("\n".join(out) + "\n").encode("ascii")


_ANY_BYTES = st.one_of(
    _graph_text().map(lambda t: t.encode("utf-8")),
    _graph_text().map(lambda t: gzip.compress(t.encode("utf-8"))),
    st.binary(max_size=400),
    st.binary(max_size=200).map(lambda b: b"\x1f\x8b" + b),                # gzip magic, then anything
    _graph_text().map(lambda t: gzip.compress(t.encode("utf-8"))[: max(2, len(t) // 3)]),
)


def _write(tmp_path_factory, data: bytes) -> Path:
    f = tmp_path_factory.mktemp("fuzz") / "input"
    f.write_bytes(data)
    return f


@FUZZ
@given(data=_ANY_BYTES)
def test_fuzz_graph_reader_parses_or_raises_parse_error(tmp_path_factory, data):
    """load = read_input + both tokenisers + every check of the reader (graphs and --estimate files)."""
    f = _write(tmp_path_factory, data)
    try:
        g = load(f)
    except ParseError as exc:
        assert exc.path == str(f)
        return
    assert isinstance(g, PoseGraph) and g.m >= 1
    assert np.isfinite(g.info).all() and np.isfinite(g.trans).all() and np.isfinite(g.rot).all()


@FUZZ
@given(data=st.one_of(_graph_numbers(), _ANY_BYTES))
def test_fuzz_fast_and_reference_tokenisers_agree(data):
    """parse_bytes (the fast tokeniser where it applies) against the reference tokeniser alone: the
    same graph, or the same error at the same line."""
    from posecrb.io.formats import FORMATS
    from posecrb.io.reader import parse
    from posecrb.io.text import split_text

    def outcome(read):
        try:
            return read()
        except ParseError as exc:
            assert exc.path == "x.g2o"
            return exc

    got = outcome(lambda: parse_bytes(data, path="x.g2o"))
    ref = outcome(lambda: parse(split_text(decode_utf8(data, "x.g2o")), FORMATS, "x.g2o", None))
    if isinstance(ref, ParseError):
        assert isinstance(got, ParseError) and str(got) == str(ref)
        return
    assert isinstance(got, PoseGraph) and isinstance(ref, PoseGraph)
    for field in ("ids", "src", "dst", "rot", "trans", "info", "vertex_rot", "vertex_trans"):
        np.testing.assert_array_equal(getattr(got, field), getattr(ref, field), err_msg=field)


@FUZZ
@given(data=_ANY_BYTES)
def test_fuzz_text_lines_reader(tmp_path_factory, data):
    """read_lines (the pairs file's reader): its lines, numbered from 1, or a ParseError."""
    f = _write(tmp_path_factory, data)
    try:
        lines = read_lines(f)
    except ParseError as exc:
        assert exc.path == str(f)
        return
    assert [ln.number for ln in lines] == list(range(1, len(lines) + 1))
    assert all(isinstance(ln, Line) and "\n" not in ln.text and "\r" not in ln.text for ln in lines)


@FUZZ
@given(data=st.binary(max_size=300))
def test_fuzz_gunzip(data):
    try:
        out = gunzip(b"\x1f\x8b" + data, "x.gz", limit=1 << 16)
    except ParseError as exc:
        assert exc.path == "x.gz"
        return
    assert isinstance(out, bytes)


_JSON_LEAVES = st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=False),
                         st.text(max_size=5))
_JSON = st.recursive(_JSON_LEAVES, lambda kids: st.one_of(st.lists(kids, max_size=4),
                                                         st.dictionaries(st.text(max_size=8), kids, max_size=4)),
                     max_leaves=12)
_EXPECTED = st.one_of(
    _JSON.map(json.dumps),
    st.dictionaries(st.sampled_from(["lb", "ub", "ub_lambda", "fim_logdet", "objective", "trace_crlb", "sha256",
                                     "fim_variant", "trace_crlb_error_bound", "other"]), _JSON_LEAVES, max_size=6)
    .map(lambda v: json.dumps({"version": 1, "datasets": {"CSAIL": v}})),
    st.text(max_size=200),
    st.just('{"datasets": {"a": {"lb": 1e400}}}'), st.just("[" * 5000 + "]" * 5000),
)


@FUZZ
@given(content=_EXPECTED)
def test_fuzz_expected_file_reader(content):
    """regress's expected file: a dict compare() can use (every number finite), or a ParseError."""
    try:
        data = parse_expected(content, "e.json")
    except ParseError as exc:
        assert exc.path == "e.json"
        return
    for values in data["datasets"].values():
        for k in ("lb", "ub", "ub_lambda", "fim_logdet", "objective", "trace_crlb"):
            v = values.get(k)
            assert v is None or (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v))


_MANIFEST = st.one_of(
    st.text(max_size=300),
    st.builds(lambda name, file, sub, url, checksum: (
        f'[[dataset]]\nname = {json.dumps(name)}\nfile = {json.dumps(file)}\nsubdir = {json.dumps(sub)}\n'
        f'format = "g2o"\ndim = 2\nposes = 3\nedges = 3\nurl = {json.dumps(url)}\n{checksum}\n'),
        st.text(max_size=8), st.sampled_from(["a.g2o", "../a.g2o", "/etc/a.g2o", "d/a.g2o", "", ".", "..", "a\0b"]),
        st.sampled_from(["", "toro", "../..", "/abs", "a/../..", "a//b"]),
        st.sampled_from(["https://x/y", "http://x/y", "file:///etc"]),
        st.sampled_from(['sha256 = "00"', 'git_blob = "00"', ""])),
)


@FUZZ
@given(content=_MANIFEST)
def test_fuzz_manifest_reader(content):
    """The manifest (package data, or a user's file): entries confined to their directory, or a
    ManifestError naming the file (the manifest's own error type: exit 1, never a traceback)."""
    try:
        man = parse_manifest(content, "m.toml")
    except ManifestError as exc:
        assert str(exc).startswith("m.toml")
        return
    for e in man:
        assert ".." not in e.relpath.split("/") and not e.relpath.startswith("/") and "\0" not in e.relpath


def _pairs_graph() -> PoseGraph:
    from posecrb.io import parse_text

    return parse_text(text(graph2(vertices=False) + [f"EDGE_SE2 0 2 1 1 1 {INFO2}"]), "g.g2o")


@settings(FUZZ)
@given(data=_ANY_BYTES)
def test_fuzz_pairs_file_reader(tmp_path_factory, data):
    """--fixed FILE: an edge split, or a ParseError (or the fixed set does not connect the graph)."""
    from posecrb.selection.budget import DisconnectedFixedSet, EdgeSplit, split_edges

    f = _write(tmp_path_factory, data)
    try:
        res = split_edges(_pairs_graph(), fixed=str(f))
    except (ParseError, DisconnectedFixedSet, DisconnectedGraph) as exc:
        assert str(f) in str(exc)
        return
    assert isinstance(res, EdgeSplit)


@pytest.mark.parametrize("spec", ["1e308", "1:1e300", "1:2:1e-300", "nan", "1,,2", "0", "-1", "1:", ":", "1e309",
                                  "\u0661", "1_0", "1" * 400])
def test_option_parsers_give_usage_errors(spec):
    from posecrb.cli.options import parse_pose_ids
    from posecrb.experiments.crlb_sweep import parse_levels

    for parse in (parse_levels, parse_pose_ids):
        try:
            parse(spec)
        except PosecrbError:
            pass


def test_gzip_3d_and_toro_are_read_too(tmp_path):
    for lines in (graph3(), ["EDGE2 0 1 1 0 0 500 0 500 1000 0 0", "EDGE2 1 2 1 0 0 500 0 500 1000 0 0"]):
        f = tmp_path / "g.gz"
        f.write_bytes(zlib.compress(b"not gzip"))     # zlib, not gzip: read as text and refused
        with pytest.raises(ParseError):
            load(f)
        f.write_bytes(gzip.compress(text(lines).encode()))
        assert load(f).m == len([ln for ln in lines if ln.startswith("EDGE")])
