"""The documentation site builds with warnings as errors, offline, and its references are complete.

One build (Sphinx, ``-W``, into a temporary directory) serves the tests of the built site; they are
skipped only when Sphinx or one of the site's extensions is not installed (the ``docs`` extra).
The tests of the pages' sources (options that exist, public imports only, figures in use) need no
build. Each checks one kind of defect a reader met on an earlier version of the site.
"""
from __future__ import annotations

import html
import importlib.util
import json
import re
import shlex
import subprocess
import sys
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path

import click
import pytest
from markdown_it import MarkdownIt

import posecrb
from posecrb.cli import cli

from .docblocks import page_blocks, page_paths, parse_console

ROOT = Path(__file__).resolve().parents[2]
EXTENSIONS = ("sphinx", "myst_parser", "pydata_sphinx_theme", "numpydoc", "sphinx_click")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    missing = [m for m in EXTENSIONS if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"the docs build needs {', '.join(missing)} (pip install -e '.[docs]')")
    out = tmp_path_factory.mktemp("docs")
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html",
         "-d", str(out / "doctrees"), str(ROOT / "docs"), str(out / "html")],
        capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, f"sphinx -W failed:\n{proc.stdout}\n{proc.stderr}"
    return out / "html"


def _ids(page: Path) -> set[str]:
    return {html.unescape(m) for m in re.findall(r'\bid="([^"]+)"', page.read_text(encoding="utf-8"))}


def test_api_reference_lists_every_public_name(site: Path) -> None:
    ids = _ids(site / "reference" / "api.html")
    missing = [name for name in posecrb.__all__ if f"posecrb.{name}" not in ids]
    assert not missing, f"not in the API reference: {missing}"


def test_api_reference_shows_the_typed_signatures(site: Path) -> None:
    """Each signature with its types, and each choice's type with its values."""
    text = html.unescape(re.sub(r"<[^>]+>", "", (site / "reference" / "api.html").read_text(encoding="utf-8")))
    assert "model: Model = 'paper'" in text and "budget: int | float" in text and "gains: Gains = 'auto'" in text
    assert "alias of Literal['paper', 'sed']" in text
    assert "alias of Literal['auto', 'exact', 'rounds', 'lazy', 'lazy-exact', 'jl']" in text


def _commands(group: click.Command, ctx: click.Context, path: tuple[str, ...]):
    """(command path, command) for the group and every command below it, lazy ones included."""
    yield path, group
    if isinstance(group, click.Group):
        for name in group.list_commands(ctx):
            sub = group.get_command(ctx, name)
            assert sub is not None, f"{' '.join(path)} lists {name} but cannot load it"
            yield from _commands(sub, click.Context(sub, info_name=name, parent=ctx), (*path, name))


def test_cli_reference_lists_every_command_and_option(site: Path) -> None:
    ids = _ids(site / "reference" / "cli.html")
    missing = []
    for path, command in _commands(cli, click.Context(cli, info_name="posecrb"), ("posecrb",)):
        if command.hidden:
            continue
        if "-".join(path) not in ids:
            missing.append(" ".join(path))
        for param in command.params:
            if not isinstance(param, click.Option) or param.hidden:
                continue
            for opt in param.opts + param.secondary_opts:
                anchor = "cmdoption-" + "-".join(path) + "-" + opt.lstrip("-")
                if anchor not in ids:
                    missing.append(f"{' '.join(path)} {opt}")
    assert len(missing) == 0, f"not in the CLI reference: {missing}"
    assert len([i for i in ids if i.startswith("posecrb-")]) >= 10


def test_site_fetches_nothing_from_the_network(site: Path) -> None:
    """Scripts, styles, images and fonts all come from the site itself (it works offline)."""
    remote = re.compile(r'<(?:script|link|img)\b[^>]*\b(?:src|href)="(?:https?:)?//', re.I)
    offenders = [str(p.relative_to(site)) for p in site.rglob("*.html") if remote.search(p.read_text("utf-8"))]
    assert not offenders, f"pages loading remote resources: {offenders}"


def test_every_page_is_built(site: Path) -> None:
    pages = [p.relative_to(ROOT / "docs").with_suffix(".html")
             for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts]
    missing = [str(p) for p in pages if not (site / p).is_file()]
    assert not missing, missing


# ---- what a reader sees in the built site --------------------------------------------------------

class _Text(HTMLParser):
    """The text of a page as a browser shows it (no scripts, styles or comments), leaving out what
    is inside the tags ``outside`` (links, code)."""

    def __init__(self, outside: tuple[str, ...] = ()) -> None:
        super().__init__()
        self.parts: list[str] = []
        self._outside = ("script", "style", *outside)
        self._depth = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self._depth += tag in self._outside

    def handle_endtag(self, tag: str) -> None:
        self._depth -= tag in self._outside and self._depth > 0

    def handle_data(self, data: str) -> None:
        if not self._depth:
            self.parts.append(data)


def _pages(site: Path) -> list[Path]:
    return sorted(p for p in site.rglob("*.html") if not {"_static", "_sources"} & set(p.relative_to(site).parts))


def _visible_text(page: Path, outside: tuple[str, ...] = ()) -> str:
    parser = _Text(outside)
    parser.feed(page.read_text(encoding="utf-8"))
    return "".join(parser.parts)


def test_no_dash_is_typeset_before_an_option_name(site: Path) -> None:
    """``--data-dir`` shows as typed: an en- or em-dash glued to a name is a ``--`` that typography
    turned into a dash (smartquotes), and breaks when copied."""
    dash = re.compile(r"(?<![\w\u2013\u2014])[\u2013\u2014](?=[A-Za-z])")
    found = {}
    for page in _pages(site):
        text = _visible_text(page)
        hits = [text[max(0, m.start() - 20):m.end() + 15] for m in dash.finditer(text)]
        if hits:
            found[str(page.relative_to(site))] = hits[:3]
    assert not found, f"dashes before names: {found}"


def test_notes_for_the_tests_are_not_shown(site: Path) -> None:
    """The line that keeps a block out of the docs tests is for the page's editors only."""
    shown = [str(p.relative_to(site)) for p in _pages(site) if "Not run by the docs tests" in _visible_text(p)]
    assert not shown, f"the docs tests' note is visible on {shown}"


def test_pages_named_in_running_text_are_links(site: Path) -> None:
    """``see docs/performance.md`` in a docstring or a --help text is a link in the site."""
    named = {}
    for page in _pages(site):
        hits = re.findall(r"docs/[\w/-]+\.md\S*", _visible_text(page, ("a", "code", "pre")))
        if hits:
            named[str(page.relative_to(site))] = hits[:3]
    assert not named, f"pages named but not linked: {named}"


def test_no_raw_markup_in_the_reference(site: Path) -> None:
    """Docstrings render: no reST markup (``literal``, :role:) shows as typed in the reference."""
    raw = {}
    for page in sorted((site / "reference").glob("*.html")):
        text = _visible_text(page, ("code", "pre"))
        hits = [text[max(0, m.start() - 30):m.end() + 30] for m in re.finditer(r"``|:(?:py:)?\w+:`", text)]
        if hits:
            raw[page.name] = hits[:3]
    assert not raw, f"raw reST in the reference: {raw}"


def test_table_output_fits_the_column(site: Path) -> None:
    """From a 1400 px window on, a code block's table rows fit the content column without
    scrolling (posecrb_docs.TABLE_CHARS at the code font, WIDE_TABLE_CHARS at the smaller font of
    wide tables); other long lines wrap (docs/_static/posecrb.css)."""
    sys.path.insert(0, str(ROOT / "docs" / "_ext"))
    from posecrb_docs import TABLE_CHARS, WIDE_TABLE_CHARS, table_rows
    too_wide = []
    block = re.compile(r'<div class="([^"]*)"><div class="highlight"><pre>(.*?)</pre>', re.S)
    for page in _pages(site):
        for m in block.finditer(page.read_text(encoding="utf-8")):
            rows = table_rows(html.unescape(re.sub(r"<[^>]+>", "", m[2])))
            limit = WIDE_TABLE_CHARS if "posecrb-wide" in m[1].split() else TABLE_CHARS
            if rows and max(map(len, rows)) > limit:
                too_wide.append(f"{page.relative_to(site)}: {max(map(len, rows))} > {limit}: {rows[0][:50]}")
    assert not too_wide, f"tables wider than the column: {too_wide}"


def test_internal_links_reach_their_targets(site: Path) -> None:
    """Every link inside the site reaches an existing page and, with a ``#fragment``, an element
    of that page (the pages' own links and the ``docs/<page>.md#anchor`` mentions turned into
    links)."""
    ids: dict[Path, set[str]] = {}
    broken = []
    for page in _pages(site):
        for href in re.findall(r'<a [^>]*href="([^"]+)"', page.read_text(encoding="utf-8")):
            href = html.unescape(href)
            if re.match(r"[a-z]+:", href) or href.startswith("//"):
                continue
            path, _, fragment = href.partition("#")
            target = (page.parent / path).resolve() if path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                broken.append(f"{page.relative_to(site)}: {href}")
                continue
            if fragment and target.suffix == ".html":
                if target not in ids:
                    ids[target] = _ids(target)
                if fragment not in ids[target]:
                    broken.append(f"{page.relative_to(site)}: {href}")
    assert not broken, f"links to nowhere: {sorted(set(broken))}"


def test_every_figure_is_shown_by_a_page(site: Path) -> None:
    """A figure in docs/figures that no page shows is stale or forgotten."""
    shown = {p.name for p in (site / "_images").iterdir()} if (site / "_images").is_dir() else set()
    unused = [p.name for p in sorted((ROOT / "docs" / "figures").iterdir()) if p.name not in shown]
    assert not unused, f"figures no page shows: {unused}"


# ---- what the pages' sources say -----------------------------------------------------------------

PAGES = page_paths()


@pytest.mark.parametrize("section", ["tutorials", "howto"])
def test_section_index_describes_every_page(section: str) -> None:
    """A section's index lists each of its pages with a line on what it shows, not a bare list."""
    folder = ROOT / "docs" / section
    index = (folder / "index.md").read_text(encoding="utf-8")
    items = re.findall(r"^\* \*\*\[[^]]+\]\(([\w-]+)\.md\)\*\*: (\S.{10,})$", index, re.M)
    described = {name for name, _ in items}
    pages = {p.stem for p in folder.glob("*.md")} - {"index"}
    assert pages <= described, f"docs/{section}/index.md does not describe {sorted(pages - described)}"
_CTX = click.Context(cli, info_name="posecrb")


def _options(command: click.Command) -> set[str]:
    return {o for p in command.params for o in (*p.opts, *p.secondary_opts)} | {"--help", "-h"}


def _every_option(group: click.Command = cli, ctx: click.Context = _CTX) -> set[str]:
    found = set(_options(group))
    if isinstance(group, click.Group):
        for name in group.list_commands(ctx):
            sub = group.get_command(ctx, name)
            assert sub is not None
            found |= _every_option(sub, click.Context(sub, info_name=name, parent=ctx))
    return found


def _unknown_options(words: list[str]) -> list[str]:
    """The options of ``posecrb WORDS...`` (the words after ``posecrb``) that its command does not
    have, or the command that does not exist."""
    command, ctx, path, i = cli, _CTX, ["posecrb"], 0
    while isinstance(command, click.Group):
        while i < len(words) and words[i].startswith("-"):
            if not _is_option(words[i], _options(command)):
                return [f"{' '.join(path)} {words[i]}"]
            i += 1
        if i == len(words) or not re.fullmatch(r"[a-z][a-z0-9-]*", words[i]):
            return []                   # `posecrb --help`, `posecrb COMMAND`
        sub = command.get_command(ctx, words[i])
        if sub is None:
            return [f"{' '.join(path)} {words[i]}: no such command"]
        ctx, command = click.Context(sub, info_name=words[i], parent=ctx), sub
        path.append(words[i])
        i += 1
    options = _options(command)
    return [f"{' '.join(path)} {w}" for w in words[i:]
            if re.fullmatch(r"--?[A-Za-z][\w-]*(=.*)?", w) and not _is_option(w, options)]


def _is_option(word: str, options: set[str]) -> bool:
    name = word.split("=")[0]
    # a repeated short flag (-vv) is the count of one
    return name in options or bool(re.fullmatch(r"-([a-z])\1+", name)) and name[:2] in options


def _posecrb_invocations(text: str) -> Iterator[list[str]]:
    """The words after ``posecrb`` of every posecrb command in a shell line (pipes and lists split)."""
    for part in re.split(r"\|\||&&|;|\||\$\(|`", text.replace("\\\n", " ")):
        try:
            words = shlex.split(part, comments=True)
        except ValueError:
            words = part.split()
        words = [w for w in words if not re.fullmatch(r"[A-Z_]+=\S*", w)]   # VAR=value prefixes
        if words and words[0] == "posecrb":
            yield words[1:]


def _inline_code(page: Path) -> list[str]:
    tokens = MarkdownIt("commonmark").parse(page.read_text(encoding="utf-8"))
    return [c.content for t in tokens if t.type == "inline" for c in t.children or [] if c.type == "code_inline"]


# Options of the benchmark scripts, which the performance page quotes by themselves.
# Pages that quote the options of other programs by themselves: the benchmark scripts (the
# performance page) and the study scripts the decision notes record.
_OTHER_PROGRAMS = {ROOT / "docs" / "performance.md", *(ROOT / "docs" / "decisions").glob("*.md")}


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_options_named_in_the_docs_exist(page: Path) -> None:
    """Every ``posecrb`` command in a console block or in inline code names a command and options
    that ``--help`` lists; an option quoted by itself (`--estimate vertices`) is one of some
    command."""
    unknown = []
    for block in page_blocks(page):
        if block.lang != "console":
            continue
        for line in block.text.replace("\\\n", " ").splitlines():
            if line.startswith("$ "):
                for words in _posecrb_invocations(line[2:]):
                    unknown += _unknown_options(words)
    every = _every_option()
    for code in _inline_code(page):
        for words in _posecrb_invocations(code):
            unknown += _unknown_options(words)
        m = re.fullmatch(r"(--[a-z][\w-]*)(?:[ =]\S+)?", code)
        if m and page not in _OTHER_PROGRAMS and m[1] not in every:
            unknown.append(f"`{code}`")
    assert not unknown, f"{page.relative_to(ROOT)}: not in posecrb's --help: {unknown}"


def test_one_install_story() -> None:
    """posecrb is not on PyPI: every page installs it from a clone (``pip install .``, with
    ``'.[extra]'`` for the extras), none by name from a package index."""
    by_name = re.compile(r"pip install\s+(?:-\S+\s+)*['\"]?posecrb(?:\[|==|>=|['\"\s]|$)", re.M)
    files = [*PAGES, *sorted((ROOT / "examples").rglob("*.*")), ROOT / "CONTRIBUTING.md"]
    offenders = [str(f.relative_to(ROOT)) for f in files if f.is_file() and by_name.search(f.read_text("utf-8"))]
    assert not offenders, f"installs posecrb from an index: {offenders}"
    assert "git clone https://github.com/posecrb/posecrb" in (ROOT / "docs" / "getting-started.md").read_text("utf-8")


def _dotted(obj: object, key: str) -> object:
    for part in key.split("."):
        assert isinstance(obj, dict) and part in obj, f"no key {key}"
        obj = obj[part]
    return obj


def test_bounds_columns_are_mapped_to_their_json_keys(tmp_path: Path) -> None:
    """Getting started maps each column of the ``bounds`` table to its JSON key: on one graph,
    every mapped column is in the table and shows the value of its key (times aside)."""
    page = (ROOT / "docs" / "getting-started.md").read_text(encoding="utf-8")
    table = page[page.index("| column | JSON key | what |"):].split("\n\n")[0].splitlines()[2:]
    pairs = []
    for row in table:
        columns, keys = (c.strip() for c in row.strip("|").split("|")[:2])
        names, key_names = columns.split(", "), re.findall(r"`([\w.]+)`", keys)
        assert len(names) == len(key_names), row
        pairs += zip(names, key_names)
    graph = tmp_path / "g.g2o"

    def posecrb_cli(*args: str) -> str:
        return subprocess.run([sys.executable, "-m", "posecrb", *args], check=True, capture_output=True,
                              text=True, cwd=tmp_path).stdout

    posecrb_cli("datasets", "synth", "grid2d", "--poses", "16", "--noise", "0.01", "--seed", "3", "--out", str(graph))
    row = json.loads(posecrb_cli("bounds", str(graph), "--estimate", "vertices", "--format", "json"))
    header, _, values = posecrb_cli("bounds", str(graph), "--estimate", "vertices", "--format", "markdown").splitlines()
    unescape = lambda cell: re.sub(r"\\(.)", r"\1", cell.strip())
    shown = dict(zip(map(unescape, header.strip("|").split("|")), map(unescape, values.strip("|").split("|"))))
    assert set(shown) == {name for name, _ in pairs}, "the table's columns and the mapped ones differ"
    for name, key in pairs:
        value = _dotted(row, key)
        if key.startswith("times."):
            continue
        if isinstance(value, float):
            assert float(shown[name]) == pytest.approx(value, rel=1e-4), (name, key)
        else:
            assert shown[name] == str(value), (name, key)


_MESSAGE = re.compile(r"^posecrb: (?:error|usage error|warning):")
_CSV_HEADER = re.compile(r"[A-Za-z_][\w.]*(?:,[A-Za-z_][\w.]*)+")


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_outputs_are_shown_verbatim(page: Path) -> None:
    """Expected output elides (``...``) only what changes from run to run (times, paths, versions,
    checksums), never a message's reason, part of a table row, or fields of a CSV row."""
    elided = []
    for block in page_blocks(page):
        if block.lang != "console" or block.skip is not None:
            continue
        for command in parse_console(block):
            fields = None
            for line in command.expected:
                where = f"{block.where} ({line.strip()[:60]})"
                if _CSV_HEADER.fullmatch(line.strip()):
                    fields = line.count(",")
                elif fields is not None and "," in line and line.count(",") != fields:
                    elided.append(f"{where}: a CSV row with other fields than its header")
                if "..." not in line or line.strip() == "...":
                    continue
                if _MESSAGE.match(line):
                    elided.append(f"{where}: a message elided")
                elif re.match(r"\s*[│┃]", line):
                    elided.append(f"{where}: a table row elided")
                elif line.lstrip().startswith("|") and any(
                        "..." in c and c.strip() != "..." for c in line.strip().strip("|").split("|")):
                    elided.append(f"{where}: part of a table cell elided")
    assert not elided, f"{page.relative_to(ROOT)}: output shown as a pattern: {elided}"


_POSECRB_NAME = re.compile(r"\bposecrb\.([A-Za-z_]\w*)")


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_examples_use_only_the_public_api(page: Path) -> None:
    """Code a reader copies uses ``posecrb.<name>`` for names of ``posecrb.__all__`` only: the
    modules inside the package are internal and change without notice."""
    private = []
    for block in page_blocks(page):
        if block.lang == "python":
            code = [ln.lstrip()[4:] for ln in block.text.splitlines() if ln.lstrip().startswith((">>> ", "... "))]
        elif block.lang == "console":
            code = [ln for ln in block.text.splitlines() if ln.startswith("$ ") and "python" in ln]
        else:
            continue
        for line in code:
            m = re.match(r"\s*from\s+posecrb\s+import\s+\(?([\w ,]+)", line)
            if m:
                private += [f"{block.where}: posecrb.{n}" for n in re.findall(r"\w+", m[1])
                            if n not in posecrb.__all__ and n != "as"]
                continue
            for m in re.finditer(r"(?:^|[;\"'\s])(?:from|import)\s+(posecrb(?:\.\w+)+)", line):
                private.append(f"{block.where}: import of {m[1]}")
            private += [f"{block.where}: posecrb.{m[1]}" for m in _POSECRB_NAME.finditer(line)
                        if m[1] not in posecrb.__all__ and not re.search(r"(?:from|import)\s+posecrb\.", line)]
    assert not private, f"internal names in examples: {private}"
