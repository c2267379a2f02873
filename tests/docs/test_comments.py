"""The code's comments and docstrings state the present, and ``--help`` names no file of the repository.

A comment that quotes seconds measured on one machine is wrong on the next; it gives the reason in
words and cites the decision note (docs/decisions/) that holds the numbers with their date, commit
and machine. A comment may not point into the old performance logbook (docs/performance.md) or name
a benchmark script that is no longer in the tree. ``--help`` is read where no checkout exists, so it
names pages of the documentation in words, never a path such as ``docs/howto/x.md``.
"""
from __future__ import annotations

import ast
import bisect
import io
import itertools
import re
import tokenize
from collections.abc import Iterator
from pathlib import Path

import click
import pytest

import posecrb
from posecrb.cli import cli

PACKAGE = Path(posecrb.__file__).resolve().parent
REPOSITORY = PACKAGE.parent

# A time: a number (or a range of two) followed by a unit of time, optionally after "~"; and a
# speed ratio: "1.8x slower", "3x the time", "3-4 times faster".
_NUMBER = r"\d+(?:[.,]\d+)*(?:\s*(?:-|to)\s*\d+(?:[.,]\d+)*)?"
_TIME = re.compile(
    rf"(?<![\w.^*/-])~?{_NUMBER}\s*(?:s|ms|us|µs|ns|secs?|seconds?|milliseconds?|microseconds?|minutes?)\b"
    r"(?!\.\w|\s*(?:\^|\*|I\b|\())")
_RATIO = re.compile(
    rf"(?<![\w.])~?{_NUMBER}\s*(?:x|times)\s+(?:faster|slower|quicker|cheaper|longer|as long|the time)\b")
# ... and a time in words: "a tenth of a second", "tenths of a second", "half a second".
_WORDED_TIME = re.compile(r"\b(?:(?:a|one|two|three|a few)\s+)?(?:tenths?|hundredths?|quarters?|thirds?|halfs?|half)"
                          r"\s+(?:of\s+)?an?\s+(?:second|millisecond|minute)\b", re.IGNORECASE)
_LOGBOOK = re.compile(r"performance\.md")
_BENCHMARK_PATH = re.compile(r"\bbenchmarks/[\w./-]*\w")

# Times that are not measurements: the settings of the timing protocol (posecrb.core.timing) as the
# docstrings describe them. Each entry: (file, the phrase as written). A symbol named s after an
# operator (``tr G + 2 s``) is not a time either (``_after_operator``).
ALLOWED_TIMES = {
    ("posecrb/api/bounds.py", "1 s"),   # --repeat auto: one run when a stage takes 1 s or more
    ("posecrb/api/bounds.py", "2 s"),   # ... else the runs that fit in about 2 s (AUTO_BUDGET)
    ("posecrb/cli/commands/bounds.py", "1 s"),
}


def _comments_and_docstrings(source: str) -> Iterator[tuple[int, str]]:
    """(line, text) of every comment and every string that stands alone as a statement (module,
    class and function docstrings, attribute docstrings)."""
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            yield node.lineno, node.value.value


def _after_operator(before: str) -> bool:
    """Whether a match follows an operator, the start of an inline literal or the word "shift":
    then its ``s`` is a symbol (``tr G + 2 s``, ````2 s w^2````, ``the shift 2 s``)."""
    return bool(re.search(r"(?:[-+*/=]|``|\bshift)\s*$", before))


def offences(path: Path, source: str, root: Path = REPOSITORY) -> list[str]:
    """What a file's comments and docstrings say that they should not, as ``file:line: ...``.
    ``root``: the checkout whose benchmarks/ the named scripts must be in."""
    name = path.relative_to(root).as_posix() if path.is_relative_to(root) else path.as_posix()
    found = []
    for first, text in _comments_and_docstrings(source):
        # each line's words joined by single spaces, so that a phrase may wrap; ``starts`` maps an
        # offset of ``flat`` back to the line it came from
        lines = [" ".join(raw.split()) for raw in text.split("\n")]
        starts = list(itertools.accumulate((len(w) + 1 for w in lines[:-1]), initial=0))
        flat = " ".join(lines)

        def where(m: re.Match[str], starts: list[int] = starts, first: int = first) -> str:
            return f"{name}:{first + bisect.bisect_right(starts, m.start()) - 1}"

        for m in _TIME.finditer(flat):
            phrase = re.sub(r"^~|\s+", lambda s: "" if s[0] == "~" else " ", m[0])
            if (name, phrase) not in ALLOWED_TIMES and not _after_operator(flat[:m.start()]):
                found.append(f"{where(m)}: a measured time, {m[0]!r}")
        found += [f"{where(m)}: a measured speed ratio, {m[0]!r}" for m in _RATIO.finditer(flat)]
        found += [f"{where(m)}: a measured time, {m[0]!r}" for m in _WORDED_TIME.finditer(flat)]
        found += [f"{where(m)}: points into the performance logbook" for m in _LOGBOOK.finditer(flat)]
        found += [f"{where(m)}: names {m[0]}, which is not in the tree"
                  for m in _BENCHMARK_PATH.finditer(flat) if not (root / m[0]).exists()]
    return found


def test_no_comment_quotes_a_measured_time_the_logbook_or_a_missing_script():
    found = [o for path in sorted(PACKAGE.rglob("*.py")) for o in offences(path, path.read_text("utf-8"))]
    assert not found, "say it in words and cite the decision note (docs/decisions/):\n" + "\n".join(found)


@pytest.mark.parametrize("text", [
    "# the factorization takes 2.2-2.5 s with two threads",
    "# costs ~45 ms per process",
    "# 0.7-0.9 s in a fresh process",
    "# (~2 us per block)",
    "# took 1.63 s in-process instead of 0.20 s",
    "# about 1.8x slower on city10000",
    "# about 3x the time with two threads",
    "# a call of 20 seconds",
    "# its import costs a tenth of a second",
    "# (tenths of a second under load)",
    "# docs/performance.md, \"Threads\"",
    "# measured with benchmarks/orderings.py --options",
    '"""Measured by `python benchmarks/selinv_paths.py`."""',
])
def test_each_kind_is_found(tmp_path: Path, text: str):
    """Not vacuous: each kind the test exists for is an offence, in a comment and in a docstring."""
    path = tmp_path / "module.py"
    assert offences(path, text + "\n", root=tmp_path)


@pytest.mark.parametrize("text", [
    '"""Seconds per step (the ``times`` of the JSON)."""',
    "# (K - 1) rows, the shift 2 s I on the diagonal",
    "# dsymm ``2 s^2 w``, dgemm ``2 s w^2``",
    "# sqrt(G) = (G + s I) / sqrt(tr G + 2 s)",
    "# K's Schur complement only its shift 2 s.",
    "# 1.4-1.7x the entries",
    "# rounding error within 1e-9 s.e.",
    "# see docs/decisions/blas-threads.md and benchmarks/suite/bench_load.py",
    "# re-count at most once a second (SOLVE_LOAD_SECONDS)",
])
def test_what_is_not_an_offence(tmp_path: Path, text: str):
    """Units that describe outputs or settings, symbols named s, and sizes are not measurements; a
    benchmark file that exists may be named."""
    (tmp_path / "benchmarks" / "suite").mkdir(parents=True)
    (tmp_path / "benchmarks" / "suite" / "bench_load.py").touch()
    assert offences(tmp_path / "module.py", text + "\n", root=tmp_path) == []


def test_the_protocol_settings_are_allowed_only_where_they_are():
    """The allow-list names files that still describe the timing protocol with those phrases (an
    entry that no longer matches anything is stale)."""
    stale = []
    for name, phrase in sorted(ALLOWED_TIMES):
        source = (REPOSITORY / name).read_text("utf-8")
        texts = [" ".join(t.split()) for _, t in _comments_and_docstrings(source)]
        if not any(re.search(rf"(?<![\w.]){re.escape(phrase)}\b", t) for t in texts):
            stale.append((name, phrase))
    assert not stale, f"allow-list entries that match nothing: {stale}"


def _commands(group: click.Command, ctx: click.Context) -> Iterator[tuple[str, click.Command]]:
    yield ctx.command_path, group
    if isinstance(group, click.Group):
        for name in group.list_commands(ctx):
            sub = group.get_command(ctx, name)
            assert sub is not None
            yield from _commands(sub, click.Context(sub, info_name=name, parent=ctx))


_DOCS_FILE = re.compile(r"(?:\bdocs/[\w./-]*\w|\b[\w-]+\.md\b)")


def _help_texts() -> Iterator[tuple[str, str]]:
    for path, command in _commands(cli, click.Context(cli, info_name="posecrb")):
        for text in (command.help, command.short_help, command.epilog):
            if text:
                yield path, text
        for param in command.params:
            if isinstance(param, click.Option) and param.help:
                yield f"{path} {param.opts[0]}", param.help


def test_no_help_text_names_a_docs_file():
    """``--help`` is read without a checkout: it names a page of the documentation in words."""
    named = [f"{where}: {m[0]}" for where, text in _help_texts() for m in _DOCS_FILE.finditer(text)]
    assert not named, f"--help names files of the repository: {named}"


def test_the_help_check_sees_every_option():
    """Not vacuous: the walk reaches the options of commands below groups (the lazy ones too)."""
    wheres = {where for where, _ in _help_texts()}
    assert "posecrb bounds --ordering" in wheres and "posecrb experiment sparsify --quick" in wheres
    assert _DOCS_FILE.search("metis (measured, see docs/performance.md)")
