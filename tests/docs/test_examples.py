"""Every script in examples/ runs, in a scratch directory and in bounded time.

Conventions (CONTRIBUTING.md, "Examples"): figures go to the scratch directory (the current
directory, or ``--figures DIR`` / ``$POSECRB_FIGURES``); exit status 77 means "cannot run here"
(the reason on stderr) and is reported as a skip; an example that names a dataset of the manifest
is skipped without ``$POSECRB_DATA``.
"""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import click
import pytest

from posecrb.cli import cli

from .docblocks import dataset_names

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
SKIPPED = 77
TIME_LIMIT = 300   # seconds per example


def _names_a_dataset(text: str) -> bool:
    pattern = r"(?<![\w-])(" + "|".join(map(re.escape, sorted(dataset_names()))) + r")(?![\w-])"
    return re.search(pattern, text) is not None


def test_there_are_examples() -> None:
    assert EXAMPLES, "examples/ has no script"


@pytest.mark.parametrize("script", [
    pytest.param(p, id=p.name, marks=[pytest.mark.slow] if _names_a_dataset(p.read_text()) else [])
    for p in EXAMPLES])
def test_example_runs(script: Path, tmp_path: Path) -> None:
    data = os.environ.get("POSECRB_DATA", "")
    if _names_a_dataset(script.read_text()) and not (data and Path(data.split(os.pathsep)[0]).is_dir()):
        pytest.skip("the example uses the real datasets: set POSECRB_DATA to their directory")
    figures = ROOT / "docs" / "figures"
    before = {f.name: f.stat().st_mtime_ns for f in figures.iterdir()}
    env = {**os.environ, "MPLBACKEND": "Agg", "POSECRB_FIGURES": str(tmp_path),
           "XDG_CACHE_HOME": str(tmp_path / ".cache")}
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=TIME_LIMIT, stdin=subprocess.DEVNULL)
    if proc.returncode == SKIPPED:
        pytest.skip(f"{script.name}: {proc.stderr.strip()}")
    assert proc.returncode == 0, f"{script.name} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    after = {f.name: f.stat().st_mtime_ns for f in figures.iterdir()}
    assert after == before, f"{script.name} wrote into docs/figures without being asked"


def _workflow_commands(path: Path) -> list[list[str]]:
    """The ``posecrb ...`` invocations in the ``run:`` steps of a workflow file."""
    commands = []
    for line in path.read_text().splitlines():
        m = re.match(r"\s*(?:-\s*)?run:\s*(.+)$", line)
        if not m:
            continue
        for part in re.split(r"&&|\|\||;|\|", m[1]):
            words = shlex.split(part.split(">>")[0].split(">")[0])
            if words and words[0] == "posecrb":
                commands.append(words[1:])
    return commands


def test_workflow_example_calls_real_commands_and_options() -> None:
    """The CI how-to's workflow file runs posecrb commands with options that exist."""
    workflow = ROOT / "examples" / "ci" / "posecrb-regression.yml"
    commands = _workflow_commands(workflow)
    assert commands, "the workflow runs no posecrb command"
    ctx = click.Context(cli, info_name="posecrb")
    for args in commands:
        command = cli.get_command(ctx, args[0])
        assert command is not None, f"posecrb {args[0]}: no such command"
        options = {opt for param in command.params for opt in (*param.opts, *param.secondary_opts)}
        unknown = [a for a in args[1:] if a.startswith("-") and a.split("=")[0] not in options]
        assert not unknown, f"posecrb {' '.join(args)}: unknown options {unknown}"
