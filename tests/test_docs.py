"""The documentation site builds with warnings as errors, offline, and its references are complete.

One build (Sphinx, ``-W``, into a temporary directory) serves every test here; it is skipped only
when Sphinx or one of the site's extensions is not installed (the ``docs`` extra).
"""
from __future__ import annotations

import html
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import click
import pytest

import posecrb
from posecrb.cli import cli

ROOT = Path(__file__).resolve().parent.parent
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
    assert "alias of Literal[‘paper’, ‘sed’]" in text and "alias of Literal[‘auto’, ‘lazy’, ‘lazy-exact’, ‘jl’]" in text


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
