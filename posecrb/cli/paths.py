"""Path options of the command line: the click side of the file layer (``posecrb.core.inputs``,
``posecrb.core.outputs``).

Every option or argument that names a file is declared with one of these types, and every command
is a ``Command`` (groups make their subcommands ``Command`` s), which checks, after the command
line is parsed and before the command runs, every output against the rules of the file layer and
against every input of the same call:

* ``OutputFile(extensions)``: a file the command writes (``--out``, ``--save``, ``--plot``);
  ``append`` adds an extension that is missing (``fim --save F`` writes ``F.npz``);
  ``only_with`` names a flag without which nothing is written (``regress --expected`` is rewritten
  only with ``--update``), ``rewrites_input`` says the file is also read (it may be its own input).
* ``OutputDir(names)``: a directory the command creates if needed and fills with ``names``.
* ``DatasetArg``: a graph given as a path or a bare dataset name (resolved on the search path).
* ``InputFile``: a data file (``--fixed``, ``--estimate``): guarded at once by the input layer
  (regular file, size); ``keywords`` are values that name no file (``odometry``, ``solve``).
* ``InputDir``: an existing directory that is read (``--data-dir``).

A new command complies by declaring its paths with these types; tests/files/test_output_options.py walks the
whole command tree and tries every output option against the rules (docs/howto/output-files.md).
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import click

from ..core.errors import PosecrbError, UsageError
from ..core.inputs import check_input_file
from ..core.outputs import GRAPH_EXTENSIONS, check_output_dir, check_output_file
from ..report.figures import FIGURE_EXTENSIONS


def flag(param: click.Parameter) -> str:
    """The option as the user writes it (``--out``), or the argument's name (``FILE``)."""
    longs = [o for o in param.opts if o.startswith("--")]
    return longs[0] if longs else (param.opts[0] if param.opts else (param.name or "").upper())


class OutputFile(click.ParamType):
    """A file the command writes (module docstring)."""

    name = "file"

    def __init__(self, extensions: Sequence[str], *, append: str | None = None, only_with: str | None = None,
                 rewrites_input: bool = False) -> None:
        self.extensions = tuple(extensions)
        self.append = append
        self.only_with = only_with
        self.rewrites_input = rewrites_input

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "FILE"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        path = os.fspath(value)
        if self.append and path.strip() and not path.endswith((self.append, os.sep)):
            path += self.append           # the file really written (numpy's rule for .npz)
        return path

    def active(self, params: dict[str, Any]) -> bool:
        return self.only_with is None or bool(params.get(self.only_with))


class OutputDir(click.ParamType):
    """A directory the command creates (one level) and fills with ``names``."""

    name = "directory"

    def __init__(self, names: Sequence[str] = ()) -> None:
        self.names = tuple(names)

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "DIR"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        return os.fspath(value)


class DatasetArg(click.ParamType):
    """A pose graph: a path (g2o/TORO, gzip read transparently) or a bare dataset name."""

    name = "file"

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "FILE"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        text = os.fspath(value)
        if not text.strip():
            raise UsageError(f"{flag(param) if param else 'FILE'}: empty; give a file or a dataset name")
        return text

    def input_paths(self, value: str, data_dir: str | None) -> list[str]:
        """The file ``value`` names; for a value that names none, the files of its comma-separated
        parts when each names one (the 0.1 form of ``--datasets``, ``posecrb.cli.options.dataset_names``)."""
        from ..datasets.search import locate_input  # noqa: PLC0415 -- the manifest only when a name needs it

        for names in ([value], value.split(",") if "," in value else []):
            try:
                return [os.fspath(locate_input(n.strip(), data_dir)) for n in names]
            except PosecrbError:
                continue
        return []          # not found: the command itself reports it


class InputFile(click.ParamType):
    """A data file read by the command, checked at once by the input layer (regular file, size);
    ``keywords`` are values that name no file."""

    name = "file"

    def __init__(self, keywords: Sequence[str] = ()) -> None:
        self.keywords = tuple(keywords)

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "|".join((*self.keywords, "FILE"))

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        text = os.fspath(value)
        if text in self.keywords:
            return text
        if not text.strip():
            raise UsageError(f"{flag(param) if param else 'FILE'}: empty path; give "
                             + (f"{' or '.join(self.keywords)} or " if self.keywords else "") + "a file name")
        check_input_file(text)      # ParseError (exit 1): not a regular file, too large
        return text

    def input_paths(self, value: str, data_dir: str | None) -> list[str]:
        return [] if value in self.keywords else [value]


class InputDir(click.ParamType):
    """An existing directory that is read (``--data-dir``)."""

    name = "directory"

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "DIR"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        text = os.fspath(value)
        if not os.path.isdir(text):
            what = "does not exist" if not os.path.lexists(text) else "is not a directory"
            raise UsageError(f"{flag(param) if param else 'DIR'} {text}: {what}")
        return text


INPUT_TYPES = (DatasetArg, InputFile)
OUTPUT_TYPES = (OutputFile, OutputDir)


def _values(value: Any) -> list[str]:
    if value is None:
        return []
    if isinstance(value, (tuple, list)):
        return [v for v in value if v is not None]
    return [value]


def check_paths(command: click.Command, params: dict[str, Any]) -> None:
    """Every output of one call against the file layer's rules and every input (module docstring).

    Raises UsageError (exit 2) before the command runs; nothing is written."""
    data_dir = params.get("data_dir")
    inputs: list[tuple[str, str]] = []            # (parameter, path) of every input file of the call
    for p in command.params:
        name = p.name or ""
        if isinstance(p.type, INPUT_TYPES):
            for v in _values(params.get(name)):
                inputs += [(name, path) for path in p.type.input_paths(v, data_dir)]
        elif isinstance(p.type, OutputFile) and p.type.rewrites_input:
            inputs += [(name, v) for v in _values(params.get(name)) if os.path.lexists(v)]
    written: list[tuple[str, str]] = []          # (option, absolute path) of every file written
    for p in command.params:
        t = p.type
        if not isinstance(t, OUTPUT_TYPES):
            continue
        for v in _values(params.get(p.name or "")):
            option = flag(p)
            if isinstance(t, OutputFile):
                if not t.active(params):
                    continue
                # an option that rewrites its own input on purpose (regress --update --expected) is exempt
                # from that one input only, never from the others of the call
                others = [path for name, path in inputs if not (t.rewrites_input and name == p.name)]
                check_output_file(v, others, option=option, extensions=t.extensions)
                written.append((option, os.path.abspath(v)))
            else:
                check_output_dir(v, [path for _, path in inputs], t.names, option=option)
                written += [(option, os.path.abspath(os.path.join(v, n))) for n in t.names]
    seen: dict[str, str] = {}
    for option, path in written:
        if path in seen and seen[path] != option:
            raise UsageError(f"{option} and {seen[path]} would both write {path}; give them different paths")
        seen.setdefault(path, option)


class Command(click.Command):
    """A click command whose paths are checked (``check_paths``) before it runs."""

    def invoke(self, ctx: click.Context) -> Any:
        check_paths(self, ctx.params)
        return super().invoke(ctx)


class Group(click.Group):
    """A click group whose subcommands are ``Command`` s (and subgroups ``Group`` s)."""

    command_class = Command
    group_class = type      # subgroups of a Group are Groups


__all__ = ["FIGURE_EXTENSIONS", "GRAPH_EXTENSIONS", "INPUT_TYPES", "OUTPUT_TYPES", "Command", "DatasetArg",
           "Group", "InputDir", "InputFile", "OutputDir", "OutputFile", "check_paths", "flag"]
