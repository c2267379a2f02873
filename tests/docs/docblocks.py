"""Execution of the code blocks of README.md and docs/**/*.md (tests/docs/test_doc_blocks.py).

The conventions (CONTRIBUTING.md, "Code blocks in the documentation"):

* ```` ```console ```` blocks: each line starting with ``$ `` is a command, run by bash (with
  ``pipefail``) in one scratch directory per page, with ``POSECRB_DATA`` set and this interpreter's
  ``posecrb`` first on ``PATH``; a command line ending in a backslash continues on the next line.
  The lines after a command, up to the next ``$ `` line, are its expected output (stdout and stderr
  as a terminal shows them). A line that is exactly ``...`` matches any number of lines, ``...``
  inside a line matches any text, runs of blanks match runs of blanks, and numbers are compared to
  the precision they are printed with. A command must exit 0 unless its expected output ends with
  a line ``[exit N]``.
* ```` ```python ```` blocks are doctests (ELLIPSIS, NORMALIZE_WHITESPACE and NUMBER); the blocks of
  one page share one namespace, in order, and run in the page's scratch directory.
* ```` ```text ```` blocks hold what is not code (formulas, diagrams, file excerpts); they may not
  contain a ``$ `` command or a ``>>>`` prompt, so nothing executable hides in them.
* MyST directives (```` ```{toctree} ````, ```` ```{eval-rst} ````, ...) from a fixed list.
* A block preceded by the line ``<!-- Not run by the docs tests: <reason>. -->`` is not run (and
  nothing else is skipped). The line is an HTML comment: it is for the tests and the page's
  editors, and readers of the site (or of README.md on a repository browser) do not see it.

Anything else is an error: a block in another language or without one, an indented code block, a
skip line that is not followed by a block, or a misspelt skip line.
"""
from __future__ import annotations

import doctest
import math
import os
import re
import subprocess
import sys
import tomllib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

from markdown_it import MarkdownIt

ROOT = Path(__file__).resolve().parents[2]

EXECUTED = frozenset({"console", "python"})
LITERAL = frozenset({"text"})
# MyST directives a page may use. Code-like directives ({code-block}, {code}, {sourcecode}) are
# not among them: code goes in a console or python block, where it is run.
DIRECTIVES = frozenset({
    "toctree", "include", "literalinclude", "image", "figure", "eval-rst", "note", "warning",
    "seealso", "important", "tip", "admonition", "contents", "list-table", "csv-table",
})
SKIP_LINE = re.compile(r"^<!-- Not run by the docs tests: (?P<reason>\S.*)\. -->$")
SKIP_MENTION = re.compile(r"not run by the docs tests", re.IGNORECASE)
COMMAND_TIMEOUT = 600   # seconds for one console command

# A number in expected output: not part of a word, an identifier or a dotted version.
NUMBER = r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?"
_EXPECTED_NUMBER = re.compile(rf"(?<![\w.]){NUMBER}(?![\w.])")
_EXPECTED_TOKEN = re.compile(rf"(?P<dots>\.\.\.)|(?P<num>(?<![\w.]){NUMBER}(?![\w.]))|(?P<ws>[ \t]+)")


class DocBlockError(Exception):
    """A page breaks the conventions (message: ``path:line: what``)."""


@dataclass
class Block:
    path: Path
    line: int                 # 1-based line of the opening fence
    lang: str
    text: str
    skip: str | None = None   # the reason of a preceding skip line

    @property
    def where(self) -> str:
        return f"{_rel(self.path)}:{self.line}"


@dataclass
class Command:
    line: int                 # 1-based line in the page
    command: str
    expected: list[str] = field(default_factory=list)
    exit_code: int = 0


def _rel(path: Path) -> str:
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


# ---- reading a page ------------------------------------------------------------------------------

def page_blocks(path: Path, text: str | None = None) -> list[Block]:
    """Every fenced block of the page, checked against the conventions (DocBlockError)."""
    text = path.read_text(encoding="utf-8") if text is None else text
    lines = text.splitlines()
    tokens = MarkdownIt("commonmark").parse(text)
    blocks: list[Block] = []
    in_code: set[int] = set()
    for tok in tokens:
        if tok.type == "code_block" and tok.map:
            raise DocBlockError(f"{_rel(path)}:{tok.map[0] + 1}: indented code block: use a fenced block "
                                "with a language (console, python or text)")
        if tok.type != "fence" or not tok.map:
            continue
        start, end = tok.map
        in_code.update(range(start, end))
        info = tok.info.strip()
        lang = info.split()[0] if info else ""
        where = f"{_rel(path)}:{start + 1}"
        if lang.startswith("{") and lang.endswith("}"):
            if lang[1:-1] not in DIRECTIVES:
                raise DocBlockError(f"{where}: directive {lang} is not allowed in the docs "
                                    f"(allowed: {', '.join(sorted(DIRECTIVES))}); code goes in a "
                                    "console or python block")
        elif lang not in EXECUTED | LITERAL:
            raise DocBlockError(f"{where}: code block in {'no language' if not lang else repr(lang)}: "
                                "use console, python or text")
        blocks.append(Block(path, start + 1, lang, tok.content))

    # Skip lines: exactly the documented form, each directly before a block (blank lines between).
    by_line = {b.line: b for b in blocks}
    for i, line in enumerate(lines):
        if i in in_code or not SKIP_MENTION.search(line):
            continue
        m = SKIP_LINE.match(line.strip())
        if not m:
            raise DocBlockError(f"{_rel(path)}:{i + 1}: skip line not in the form "
                                "'<!-- Not run by the docs tests: <reason>. -->'")
        j = i + 1
        while j < len(lines) and not lines[j].strip():
            j += 1
        block = by_line.get(j + 1)
        if block is None:
            raise DocBlockError(f"{_rel(path)}:{i + 1}: skip line not followed by a code block")
        if block.lang not in EXECUTED:
            raise DocBlockError(f"{block.where}: a skip line precedes a {block.lang or 'untagged'} "
                                "block, which is never run anyway")
        block.skip = m["reason"]

    for block in blocks:
        if block.lang in LITERAL:
            for k, line in enumerate(block.text.splitlines()):
                if line.startswith("$ ") or line.lstrip().startswith(">>>"):
                    raise DocBlockError(f"{_rel(path)}:{block.line + 1 + k}: a text block holds a command "
                                        "or prompt: make it a console or python block")
        elif block.lang == "python" and block.skip is None and ">>>" not in block.text:
            raise DocBlockError(f"{block.where}: a python block must be a doctest (>>> prompts with the "
                                "expected output)")
        elif block.lang == "console" and block.skip is None:
            parse_console(block)
    return blocks


def parse_console(block: Block) -> list[Command]:
    """The commands of a console block with their expected output and exit status."""
    lines = block.text.splitlines()
    commands: list[Command] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("$ "):
            first = i
            cmd = line[2:]
            while cmd.endswith("\\") and i + 1 < len(lines):
                i += 1
                cmd += "\n" + lines[i]      # bash reads the backslash-newline as a continuation
            commands.append(Command(block.line + 1 + first, cmd))
        elif not commands:
            if line.strip():
                raise DocBlockError(f"{block.where}: a console block starts with a '$ ' command line")
        else:
            commands[-1].expected.append(line)
        i += 1
    if not commands:
        raise DocBlockError(f"{block.where}: a console block without a '$ ' command")
    for c in commands:
        while c.expected and not c.expected[-1].strip():
            c.expected.pop()
        if c.expected:
            m = re.fullmatch(r"\[exit (\d+)\]", c.expected[-1].strip())
            if m:
                c.exit_code = int(m[1])
                c.expected.pop()
        for line in c.expected:
            if re.fullmatch(r"\s*\[exit \d+\]\s*", line):
                raise DocBlockError(f"{block.where}: [exit N] must be the last line of a command's output")
    return commands


# ---- which pages need what ---------------------------------------------------------------------------

@cache
def dataset_names() -> frozenset[str]:
    """The names of the manifest's datasets (what a page types to use real data)."""
    with open(ROOT / "posecrb" / "data" / "manifest.toml", "rb") as f:
        return frozenset(d["name"] for d in tomllib.load(f)["dataset"])


def needs_real_data(blocks: Sequence[Block]) -> bool:
    """Whether a run block names a dataset of the manifest (as a whole word)."""
    pattern = re.compile(r"(?<![\w-])(" + "|".join(map(re.escape, sorted(dataset_names()))) + r")(?![\w-])")
    return any(b.lang in EXECUTED and b.skip is None and pattern.search(b.text) for b in blocks)


def imported_modules(blocks: Sequence[Block]) -> set[str]:
    """Top-level modules imported by the page's python blocks."""
    names = set()
    for b in blocks:
        if b.lang == "python" and b.skip is None:
            names.update(re.findall(r"^\s*(?:>>>|\.\.\.)\s+(?:import|from)\s+(\w+)", b.text, re.M))
    return names


# ---- comparing output ----------------------------------------------------------------------------

def _unit(text: str) -> float:
    """One unit in the last digit of a printed number."""
    mantissa, _, exponent = text.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 10.0 ** (int(exponent or 0) - decimals)


def numbers_agree(expected: str, actual: str) -> bool:
    """Whether ``actual`` is ``expected`` to the precision ``expected`` is printed with.

    Integers written without a point or exponent must be equal; any other number may differ by
    one unit in the last digit shown, as with pytest's NUMBER option (so ``30194.33`` stands for
    30194.331732..., and a value that rounds the other way on another machine still matches).
    """
    try:
        e, a = float(expected), float(actual)
    except ValueError:
        return False
    if not (math.isfinite(e) and math.isfinite(a)):
        return e == a
    plain = re.fullmatch(r"[-+]?\d+", expected) and re.fullmatch(r"[-+]?\d+", actual)
    if plain:
        return int(expected) == int(actual)
    return abs(a - e) <= _unit(expected) * (1 + 1e-9) + 1e-300


@cache
def _line_pattern(expected: str) -> tuple[re.Pattern[str], tuple[str, ...]]:
    parts, numbers, pos = [], [], 0
    for m in _EXPECTED_TOKEN.finditer(expected):
        parts.append(re.escape(expected[pos:m.start()]))
        if m["dots"]:
            parts.append(".*?")
        elif m["num"]:
            parts.append(f"({NUMBER})")
            numbers.append(m["num"])
        else:
            parts.append(r"[ \t]+")
        pos = m.end()
    parts.append(re.escape(expected[pos:]))
    return re.compile("".join(parts)), tuple(numbers)


def line_matches(expected: str, actual: str) -> bool:
    expected, actual = expected.rstrip(), actual.rstrip()
    if expected == actual:
        return True
    pattern, numbers = _line_pattern(expected)
    m = pattern.fullmatch(actual)
    return bool(m) and all(numbers_agree(e, a) for e, a in zip(numbers, m.groups()))


def output_matches(expected: Sequence[str], actual: Sequence[str]) -> bool:
    """Line-wise match with ``...`` lines standing for any number of lines (none included)."""
    expected = [e.rstrip() for e in expected]
    actual = [a.rstrip() for a in actual]
    while actual and not actual[-1]:
        actual.pop()
    memo: dict[tuple[int, int], bool] = {}

    def match(i: int, j: int) -> bool:
        key = (i, j)
        if key in memo:
            return memo[key]
        if i == len(expected):
            result = j == len(actual)
        elif expected[i].strip() == "...":
            result = any(match(i + 1, k) for k in range(j, len(actual) + 1))
        else:
            result = j < len(actual) and line_matches(expected[i], actual[j]) and match(i + 1, j + 1)
        memo[key] = result
        return result

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 4 * (len(expected) + len(actual)) + 1000))
    return match(0, 0)


# ---- running a page ------------------------------------------------------------------------------

def console_env(scratch: Path) -> dict[str, str]:
    """The environment of console commands: this interpreter's posecrb first on PATH, a private
    cache, a non-interactive matplotlib and a fixed terminal width for tables."""
    env = dict(os.environ)
    bindir = str(Path(sys.executable).parent)
    env["PATH"] = bindir + os.pathsep + env.get("PATH", "")
    env["XDG_CACHE_HOME"] = str(scratch / ".cache")
    env["MPLBACKEND"] = "Agg"
    env["COLUMNS"] = "120"
    env.pop("NO_COLOR", None)
    return env


def run_console(block: Block, scratch: Path) -> Iterator[str]:
    """Run the block's commands; yield one failure description per mismatching command."""
    env = console_env(scratch)
    for c in parse_console(block):
        proc = subprocess.run(["bash", "-o", "pipefail", "-c", c.command], cwd=scratch, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              timeout=COMMAND_TIMEOUT, stdin=subprocess.DEVNULL)
        actual = proc.stdout.splitlines()
        problems = []
        if proc.returncode != c.exit_code:
            problems.append(f"exit status {proc.returncode}, expected {c.exit_code}")
        if not output_matches(c.expected, actual):
            problems.append("output differs")
        if problems:
            yield (f"{_rel(block.path)}:{c.line}: $ {c.command}\n  " + "; ".join(problems)
                   + "\n--- expected\n" + "\n".join(c.expected) + "\n--- actual\n" + proc.stdout)


NUMBER_FLAG = doctest.register_optionflag("NUMBER")
DOCTEST_FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE | NUMBER_FLAG


class NumberChecker(doctest.OutputChecker):
    """doctest's checker with NUMBER: a float in the expected output matches the value printed to
    the precision it is written with (as pytest's NUMBER option)."""

    def check_output(self, want: str, got: str, optionflags: int) -> bool:
        if super().check_output(want, got, optionflags):
            return True
        if not optionflags & NUMBER_FLAG:
            return False
        wanted = list(_EXPECTED_NUMBER.finditer(want))
        gotten = list(_EXPECTED_NUMBER.finditer(got))
        if len(wanted) != len(gotten):
            return False
        pieces, pos = [], 0
        for w, g in zip(wanted, gotten):
            pieces.append(got[pos:g.start()])
            pieces.append(w.group() if numbers_agree(w.group(), g.group()) else g.group())
            pos = g.end()
        pieces.append(got[pos:])
        return super().check_output(want, "".join(pieces), optionflags)


def run_python(blocks: Sequence[Block], globs: dict[str, object]) -> Iterator[str]:
    """Run python blocks as doctests in the namespace ``globs`` (updated in place, so that a page's
    blocks share it in order); yield the report of each failing block."""
    parser = doctest.DocTestParser()
    for block in blocks:
        test = parser.get_doctest(block.text, globs, name=block.where, filename=str(block.path),
                                  lineno=block.line)
        report: list[str] = []
        runner = doctest.DocTestRunner(checker=NumberChecker(), optionflags=DOCTEST_FLAGS)
        runner.run(test, out=report.append, clear_globs=False)
        globs.update(test.globs)
        if runner.failures:
            yield "".join(report)


def page_paths() -> list[Path]:
    """README.md and every markdown page of the documentation site."""
    docs = ROOT / "docs"
    pages = [p for p in sorted(docs.rglob("*.md")) if "_build" not in p.relative_to(docs).parts]
    return [ROOT / "README.md", *pages]
