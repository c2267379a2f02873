"""One integer parser for options, files and the library (posecrb.core.integers): integers of
thousands of digits, where Python's int(str) and repr(int) raise "Exceeds the limit (4300 digits)",
are usage errors, parse errors with the line and ArgumentErrors, never internal errors."""
from __future__ import annotations

import importlib
import inspect
import sys

import click
import pytest

import posecrb
from posecrb.cli import cli
from posecrb.cli.options import PlainInt, PoseId, RepeatCount
from posecrb.core.errors import ArgumentError, ParseError, PosecrbError
from posecrb.core.integers import INT64_MAX, IntegerError, check_int, parse_int, shown, shown_text

from ..helpers import run_cli

HUGE = 10 ** 5000 + 7                        # beyond sys.get_int_max_str_digits() (4300)
HUGE_TEXT = "1" * 5000


def test_huge_is_beyond_pythons_own_limit():
    assert 0 < sys.get_int_max_str_digits() < 5000
    with pytest.raises(ValueError, match="4300"):
        int(HUGE_TEXT)


@pytest.mark.parametrize("text", ["0", "7", "-7", "+7", " 42 ", "0042", "-0", "9223372036854775807",
                                  "-9223372036854775808", "0" * 6000 + "5"],
                         ids=lambda t: t if len(t) < 30 else f"{len(t)} chars")
def test_parse_int_reads_plain_digits_as_int_does(text):
    assert parse_int(text) == int(text.strip().lstrip("+-").lstrip("0") or "0") * (-1 if "-" in text else 1)


@pytest.mark.parametrize("text", ["", "1_0", "١٢", "1 2", "1.0", "1e3", "0x10", "--1", "+", HUGE_TEXT + "x",
                                  "9223372036854775808", "-9223372036854775809", HUGE_TEXT, "-" + HUGE_TEXT],
                         ids=lambda t: t if len(t) < 30 else f"{len(t)} chars")
def test_parse_int_refuses_anything_else_before_int(text):
    with pytest.raises(IntegerError):
        parse_int(text)


def test_parse_int_range_and_the_digits_of_its_bound():
    assert parse_int("1000", lo=1, hi=1000) == 1000
    for text in ("0", "1001", "00001001", "1" * 10 ** 6):
        with pytest.raises(IntegerError, match=r"is not in 1\.\.1000"):
            parse_int(text, lo=1, hi=1000)


def test_check_int_and_shown_take_huge_integers():
    with pytest.raises(IntegerError, match=r"is not in 0\.\."):
        check_int(HUGE, lo=0, hi=INT64_MAX)
    for bad in (True, 1.0, "1", None):
        with pytest.raises(IntegerError):
            check_int(bad)
    assert shown(HUGE) == "<an integer of about 5001 digits>" and shown_text([1, HUGE]) == f"1 {shown(HUGE)}"
    assert shown(2 ** 63) == repr(2 ** 63) and len(shown(HUGE_TEXT)) < 70
    assert str(ArgumentError("anchor", HUGE, "is not a pose id")).startswith("anchor=<an integer of about")


# ---------------------------------------------------------------- every command's integer options
INTEGER_TYPES = (PlainInt, PoseId, RepeatCount)
# Integers read from the text of a string option by the command (not by the option's type).
TEXT_INTEGERS = {("select", "--budget"), ("crlb", "--poses")}


def _commands(group=cli, path=()):
    for name in group.list_commands(None):
        cmd = group.get_command(None, name)
        if isinstance(cmd, click.Group):
            yield from _commands(cmd, (*path, name))
        else:
            yield (*path, name), cmd


def _integer_options():
    out = []
    for path, cmd in _commands():
        for p in cmd.params:
            if isinstance(p, click.Option) and (isinstance(p.type, INTEGER_TYPES) or (path[-1], p.opts[0]) in
                                                TEXT_INTEGERS):
                out.append((path, cmd, p.opts[0]))
    return out


def test_the_integer_options_are_those_of_the_finding():
    names = {opt for _, _, opt in _integer_options()}
    assert {"--anchor", "--every", "--repeat", "--budget", "--seed", "--r0", "--jobs", "--poses", "--from",
            "--trials", "--max-iter"} <= names


@pytest.fixture(scope="module")
def tiny_g2o(tmp_path_factory):
    path = tmp_path_factory.mktemp("ints") / "tiny.g2o"
    path.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 1 1 0\n"
                    "EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000\nEDGE_SE2 1 2 0 1 0 100 0 0 100 0 1000\n"
                    "EDGE_SE2 0 2 1 1 0 100 0 0 100 0 1000\n")
    return path


@pytest.mark.parametrize("value", [HUGE_TEXT, "-" + HUGE_TEXT], ids=["huge", "-huge"])
@pytest.mark.parametrize("path,cmd,option", [pytest.param(*x, id=" ".join((*x[0], x[2]))) for x in _integer_options()])
def test_every_integer_option_of_every_command_refuses_a_huge_value(path, cmd, option, value, tiny_g2o, tmp_path,
                                                                   capsys):
    argv = list(path)
    for p in cmd.params:
        if isinstance(p, click.Argument) and p.required:
            argv.append("grid2d" if p.name == "kind" else str(tiny_g2o))
        elif isinstance(p, click.Option) and p.required and p.opts[0] != option:
            argv += [p.opts[0], str(tmp_path / "out.g2o") if p.opts[0] == "--out" else "1"]
    code, out, err = run_cli([*argv, option, value], capsys)
    assert code == 2, (argv, err)
    assert "internal error" not in err and "4300" not in err
    assert len(err) < 1000                              # the value is shown shortened


# ---------------------------------------------------------------- g2o and TORO ids
# One valid file per format, dimension and record kind; the ids are replaced one position at a time.
FILES = {
    "g2o 2D": ["VERTEX_SE2 {a} 0 0 0", "VERTEX_SE2 {b} 1 0 0", "EDGE_SE2 {a} {b} 1 0 0 1 0 0 1 0 1"],
    "g2o 3D": ["VERTEX_SE3:QUAT {a} 0 0 0 0 0 0 1", "VERTEX_SE3:QUAT {b} 1 0 0 0 0 0 1",
               "EDGE_SE3:QUAT {a} {b} 1 0 0 0 0 0 1 " + " ".join(
                   "1" if c == r else "0" for r in range(6) for c in range(r, 6))],
    "toro 2D": ["VERTEX2 {a} 0 0 0", "VERTEX2 {b} 1 0 0", "EDGE2 {a} {b} 1 0 0 1 0 1 1 0 0"],
    "toro 3D": ["VERTEX3 {a} 0 0 0 0 0 0", "VERTEX3 {b} 1 0 0 0 0 0",
                "EDGE3 {a} {b} 1 0 0 0 0 0 " + " ".join("1" if c == r else "0" for r in range(6) for c in range(r, 6))],
}


def _variants():
    for name, lines in FILES.items():
        for k, line in enumerate(lines):
            for slot in ("a", "b"):
                if "{" + slot + "}" in line:
                    for huge in (HUGE_TEXT, "0" * 5000 + "1" * 20):
                        text = "\n".join(ln.format(a=huge if (i == k and slot == "a") else "0",
                                                   b=huge if (i == k and slot == "b") else "1")
                                         for i, ln in enumerate(lines)) + "\n"
                        yield pytest.param(text, k + 1, id=f"{name} line {k + 1} {slot} {len(huge)}")


@pytest.mark.parametrize("name", list(FILES))
def test_the_files_are_valid_with_small_ids(name):
    g = posecrb.parse("\n".join(ln.format(a="0", b="1") for ln in FILES[name]) + "\n")
    assert g.n == 2 and g.m == 1


@pytest.mark.parametrize("text,line", list(_variants()))
def test_huge_ids_in_every_record_type_are_parse_errors_with_the_line(text, line, tmp_path):
    path = tmp_path / "huge.g2o"
    path.write_text(text)
    for read in (lambda: posecrb.parse(text), lambda: posecrb.load(path)):   # bytes (fast path first) and str
        with pytest.raises(ParseError) as info:
            read()
        assert info.value.line == line and "fits 64 bits" in str(info.value) and len(str(info.value)) < 400


def test_long_ids_with_leading_zeros_are_their_value():
    g = posecrb.parse("VERTEX_SE2 " + "0" * 5000 + "3 0 0 0\nVERTEX_SE2 4 1 0 0\nEDGE_SE2 3 4 1 0 0 1 0 0 1 0 1\n")
    assert g.ids.tolist() == [3, 4]


# ---------------------------------------------------------------- every public function's integer keywords
def _annotation(fn, annotation) -> str:
    """The annotation as text, a type alias of the function's module spelled out."""
    text = str(annotation)
    alias = getattr(importlib.import_module(fn.__module__), text, None)
    return str(alias) if isinstance(alias, str) else text


def _integer_keywords():
    out = []
    for name in posecrb.__all__:
        fn = getattr(posecrb, name)
        if not inspect.isfunction(fn):
            continue
        for p in inspect.signature(fn).parameters.values():
            if "int" in _annotation(fn, p.annotation) and p.kind is p.KEYWORD_ONLY:
                out.append((name, p.name))
    return out


def test_the_integer_keywords_are_those_of_the_finding():
    assert {("crlb", "poses"), ("select", "budget"), ("timeline", "every"), ("solve", "anchor")} <= set(
        _integer_keywords())


@pytest.mark.parametrize("value", [HUGE, -HUGE, [HUGE], HUGE_TEXT, HUGE_TEXT + "%"],
                         ids=["huge", "-huge", "[huge]", "huge text", "huge percent"])
@pytest.mark.parametrize("name,keyword", _integer_keywords())
def test_every_integer_keyword_of_every_public_function_refuses_a_huge_integer(name, keyword, value, tiny_g2o):
    kwargs = {"budget": 1} if name == "select" and keyword != "budget" else {}
    if name in ("bounds", "fim", "crlb", "timeline"):
        kwargs["estimate"] = "vertices"
    if name == "verify":
        kwargs["estimate"] = tiny_g2o
    with pytest.raises(PosecrbError) as info:
        getattr(posecrb, name)(posecrb.load(tiny_g2o), **kwargs, **{keyword: value})
    assert len(str(info.value)) < 1000
