"""Arguments of the library checked once, before any work, with the error naming the argument.

Choices (``posecrb.core.choices``) and flags, and paths: the library's side of the command line's
path options (``posecrb.cli.paths``), the same rules of the file layer (``posecrb.core.inputs``,
``posecrb.core.outputs``), raised as ``ArgumentError`` in Python terms (``path='x.npz': directory d does not exist``).
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from .errors import ArgumentError, UsageError
from .outputs import check_output_file, same_file


def choice(parameter: str, value: Any, choices: Sequence[str]) -> Any:
    """``value`` when it is one of ``choices`` (strings; typed ``Any``, so that it fills the
    ``Literal`` of those choices)."""
    if not isinstance(value, str) or value not in choices:
        raise ArgumentError(parameter, value, f"is not one of {', '.join(map(repr, choices))}")
    return value


def flag(parameter: str, value: Any) -> bool:
    """``value`` when it is a bool (``numpy.bool_`` included: its type's name is ``bool_``/``bool``)."""
    if not isinstance(value, bool) and type(value).__name__ not in ("bool_", "bool"):
        raise ArgumentError(parameter, value, "is not True or False")
    return bool(value)



def check_output_argument(parameter: str, path: Any, inputs: tuple[str | os.PathLike[str] | None, ...] = (), *,
                          extensions: tuple[str, ...] | None = None, append: str | None = None) -> str:
    """``posecrb.core.outputs.check_output_file`` for a library argument: the same checks (the
    extension among ``extensions`` included), before any work, with the error naming
    ``parameter`` (an ``ArgumentError``: ``path='x.npz': ...``; the command line shows
    ``--path x.npz: ...``). ``append``: a suffix added unless present (numpy's rule for
    ``.npz``), after checking that ``path`` names a file. Returns the path as a string."""
    shown = check_input_argument(parameter, path)
    if append and not shown.endswith(append):
        if shown.endswith(os.sep) or os.path.basename(shown) in ("", ".", ".."):
            raise ArgumentError(parameter, shown, "names a directory; give a file name", sep=": ")
        if os.path.lexists(shown) and not os.path.isfile(shown):
            # the path as given names a directory or a device (/dev/null): never write beside it
            _checked_output(parameter, shown, inputs, None)
        shown += append
    _checked_output(parameter, shown, inputs, extensions)
    return str(shown)


def _checked_output(parameter: str, shown: str, inputs: tuple[str | os.PathLike[str] | None, ...],
                    extensions: tuple[str, ...] | None) -> None:
    """``check_output_file`` with its ``UsageError`` as an ``ArgumentError`` naming ``parameter``."""
    try:
        check_output_file(shown, inputs, option=None, extensions=extensions)
    except UsageError as exc:
        text = str(exc)
        reason = text[len(shown):] if text.startswith(shown) else f": {text}"
        colon = reason.startswith(":")
        raise ArgumentError(parameter, shown, reason[1:].strip() if colon else reason.strip(),
                            sep=": " if colon else " ") from None


def refuse_inputs(parameter: str, path: Any, inputs: Sequence[str | os.PathLike[str] | None]) -> None:
    """``ArgumentError`` naming ``parameter`` when ``path`` is one of ``inputs`` (links included):
    what a writer given a graph or a result checks, so that it never replaces the data it came from."""
    text = check_input_argument(parameter, path)
    for inp in inputs:
        if inp is not None and os.path.lexists(text) and same_file(text, inp):
            raise ArgumentError(parameter, text, f"is the input file {os.fspath(inp)}: refusing to overwrite an "
                                "input; write to another path", sep=": ")


def check_input_argument(parameter: str, path: Any) -> str:
    """``path`` as a string when it can name a file: a non-empty str or os.PathLike without NUL
    characters (``ArgumentError`` naming ``parameter`` otherwise)."""
    if not isinstance(path, (str, os.PathLike)) or isinstance(path, bytes):
        raise ArgumentError(parameter, path, "is not a file name (a non-empty str or os.PathLike)")
    text = os.fspath(path)
    if not isinstance(text, str) or not text:
        raise ArgumentError(parameter, path, "is not a file name (a non-empty str or os.PathLike)")
    if "\0" in text:
        raise ArgumentError(parameter, text, "contains a NUL character, which no file name can")
    return text
