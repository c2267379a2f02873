"""The lazy command group: `posecrb --help` renders the command list from a static table without
importing any command module, and that table says what the commands themselves say."""
from __future__ import annotations

import subprocess
import sys

import click
import pytest

from posecrb.cli import _EXPLICIT_SHORT_HELP, COMMANDS, cli


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_table_matches_each_commands_own_help(name):
    command = cli.get_command(click.Context(cli), name)
    assert command is not None and command.name == name
    for limit in (20, 45, 80, 200):     # every width click may render at
        table = click.Command(name, short_help=COMMANDS[name][1] if name in _EXPLICIT_SHORT_HELP else None,
                              help=None if name in _EXPLICIT_SHORT_HELP else COMMANDS[name][1])
        assert table.get_short_help_str(limit) == command.get_short_help_str(limit)


def test_every_command_module_is_in_the_table():
    from importlib.resources import files

    modules = {p.name[:-3] for p in files("posecrb.cli.commands").iterdir()
               if p.name.endswith(".py") and not p.name.startswith("_")}
    assert modules == {module for module, _ in COMMANDS.values()}


def test_help_imports_no_command_module_and_no_numerics():
    code = ("import sys; from posecrb.cli import main; rc = main(['--help']); "
            "bad = sorted(m for m in sys.modules if m.startswith(('posecrb.cli.commands.', 'numpy', 'scipy', "
            "'numba', 'sksparse'))); print(rc, bad, file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stderr.strip().splitlines()[-1] == "0 []"
