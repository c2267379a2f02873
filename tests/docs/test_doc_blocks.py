"""Every code block of README.md and docs/**/*.md runs, and shows what it prints.

Conventions in tests/docs/docblocks.py and CONTRIBUTING.md. Pages whose blocks name a dataset of the
manifest need the real datasets ($POSECRB_DATA) and are skipped with that reason without them;
pages that import an optional package (gtsam, dask) are skipped with that reason where it is not
installed. Every page is checked against the conventions in any case (test_page_follows_conventions).
"""
from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest

from .docblocks import (
    ROOT,
    Block,
    DocBlockError,
    imported_modules,
    line_matches,
    needs_real_data,
    numbers_agree,
    output_matches,
    page_blocks,
    page_paths,
    parse_console,
    run_console,
    run_python,
)

PAGES = page_paths()
IDS = [str(p.relative_to(ROOT)) for p in PAGES]


def _runnable_pages() -> list[object]:
    """The pages with a block to run; those on the real datasets are marked slow (minutes in all)."""
    params = []
    for page, page_id in zip(PAGES, IDS):
        try:
            blocks = [b for b in page_blocks(page) if b.lang in ("console", "python") and b.skip is None]
        except DocBlockError:
            blocks = []     # reported by test_page_follows_conventions; still run below, and fail
            params.append(pytest.param(page, id=page_id))
            continue
        if blocks:
            marks = [pytest.mark.slow] if needs_real_data(blocks) else []
            params.append(pytest.param(page, id=page_id, marks=marks))
    return params


@pytest.mark.parametrize("page", PAGES, ids=IDS)
def test_page_follows_conventions(page: Path) -> None:
    page_blocks(page)


@pytest.mark.parametrize("page", _runnable_pages())
def test_page_blocks_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = [b for b in page_blocks(page) if b.lang in ("console", "python") and b.skip is None]
    data = os.environ.get("POSECRB_DATA", "")
    if needs_real_data(run) and not (data and Path(data.split(os.pathsep)[0]).is_dir()):
        pytest.skip("the page uses the real datasets: set POSECRB_DATA to their directory")
    for module in sorted(imported_modules(run)):
        if module != "posecrb" and importlib.util.find_spec(module) is None:
            pytest.skip(f"the page imports {module}, which is not installed here")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / ".cache"))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    failures: list[str] = []
    globs: dict[str, object] = {"__name__": "__docs__"}
    for block in run:
        if block.lang == "console":
            failures += run_console(block, tmp_path)
        else:
            failures += run_python([block], globs)   # one namespace for the page's python blocks
    if failures:
        pytest.fail("\n\n".join(failures), pytrace=False)


# ---- the machinery itself: each rule can fail ----------------------------------------------------

def _blocks(text: str) -> list[Block]:
    return page_blocks(Path("page.md"), text)


@pytest.mark.parametrize("text, message", [
    ("```sh\nls\n```\n", "'sh'"),
    ("```\nls\n```\n", "no language"),
    ("Para.\n\n    indented code\n", "indented code block"),
    ("<!-- Not run by the docs tests: needs a cluster. -->\n\nText.\n", "not followed by a code block"),
    ("<!-- Not run by the docs tests: needs a cluster. -->\n", "not followed by a code block"),
    ("<!-- Not run by the docs tests because it is slow. -->\n\n```console\n$ ls\n```\n", "not in the form"),
    # the visible form of earlier versions showed the note to every reader
    ("*Not run by the docs tests: needs a cluster.*\n\n```console\n$ ls\n```\n", "not in the form"),
    ("```{code-block} python\nx = 1\n```\n", "not allowed"),
    ("```python\nx = 1\n```\n", "must be a doctest"),
    ("```console\nls\n```\n", r"starts with a '\$ ' command"),
    ("```text\n$ rm -rf /\n```\n", "text block holds a command"),
    ("```console\n$ false\n[exit 1]\nmore\n```\n", "last line"),
])
def test_conventions_are_enforced(text: str, message: str) -> None:
    with pytest.raises(DocBlockError, match=message):
        _blocks(text)


def test_skip_line_skips_exactly_the_next_block() -> None:
    blocks = _blocks("<!-- Not run by the docs tests: needs a Dask cluster. -->\n\n"
                     "```console\n$ dask scheduler\n```\n\n```console\n$ echo hi\nhi\n```\n")
    assert [b.skip for b in blocks] == ["needs a Dask cluster", None]


def test_console_commands_and_exit_codes() -> None:
    (block,) = _blocks("```console\n$ echo a \\\n  b\na b\n$ false\n[exit 1]\n```\n")
    first, second = parse_console(block)
    assert first.command == "echo a \\\n  b" and first.expected == ["a b"] and first.exit_code == 0
    assert second.command == "false" and second.expected == [] and second.exit_code == 1


def test_continued_command_runs_as_one(tmp_path: Path) -> None:
    (block,) = _blocks("```console\n$ echo a \\\n  b\na b\n```\n")
    assert list(run_console(block, tmp_path)) == []


def test_console_block_runs_and_reports_mismatches(tmp_path: Path) -> None:
    ok, bad_output, bad_status = _blocks(
        "```console\n$ printf 'x 1.25\\ny\\n'; exit 3\nx 1.2...\n...\n[exit 3]\n```\n\n"
        "```console\n$ echo 30194.331\n30194.5\n```\n\n"
        "```console\n$ true\n[exit 2]\n```\n")
    assert list(run_console(ok, tmp_path)) == []
    assert "output differs" in "".join(run_console(bad_output, tmp_path))
    assert "exit status 0, expected 2" in "".join(run_console(bad_status, tmp_path))


def test_python_blocks_share_a_namespace_and_compare_numbers() -> None:
    first, second, wrong = _blocks("```python\n>>> x = 2.0 / 3\n```\n\n```python\n>>> x\n0.667\n```\n\n"
                                   "```python\n>>> x\n0.65\n```\n")
    globs: dict[str, object] = {}
    assert list(run_python([first, second], globs)) == []
    assert len(list(run_python([first, wrong], {}))) == 1


@pytest.mark.parametrize("expected, actual, ok", [
    ("30194.33", "30194.331732751136", True),
    ("30194.33", "30194.35", False),
    ("1.2e-05", "1.25e-05", True),
    ("1.2e-05", "1.4e-05", False),
    ("1728", "1729", False),
    ("1728", "1728", True),
    ("0.5", "0.6", True),                  # one unit in the last digit shown
    ("0.5", "0.62", False),
])
def test_numbers_to_the_printed_precision(expected: str, actual: str, ok: bool) -> None:
    assert numbers_agree(expected, actual) is ok


def test_line_and_output_wildcards() -> None:
    assert line_matches('  "lb": 30155.23,', '  "lb": 30155.23119770267,')
    assert line_matches("parse ... s", "parse 0.0123 s")
    assert line_matches("kitti_00 | 4541", "kitti_00 | 4541")
    assert not line_matches("kitti_00 | 4541", "kitti_01 | 4541")
    assert not line_matches("posecrb 0.2.0", "posecrb 0.3.0")
    assert output_matches(["a", "...", "z"], ["a", "b", "c", "z"])
    assert output_matches(["a", "...", "z"], ["a", "z"])
    assert not output_matches(["a", "z"], ["a", "b", "z"])
    assert not output_matches(["a"], ["a", "b"])
