"""The line rules of every text input: where a line ends, what separates fields, which text is valid.

Graphs (``posecrb.io.text``), ``--fixed`` pairs files, ``--estimate`` files and expected files
are all split by these rules, after ``posecrb.core.inputs.read_input`` has read the file (regular
file, size, gzip):

* lines end at ``\\n``, ``\\r\\n`` or ``\\r`` only (``str.splitlines`` would also break at form
  feed, vertical tab, ``\\x1c``-``\\x1e``, NEL and U+2028/U+2029, turning the tail of a ``#``
  comment into data and shifting every later line number);
* fields are separated by ASCII blanks only (space, tab, form feed, vertical tab);
* the text is UTF-8: an invalid byte is a ``ParseError`` at the line where it occurs.

``read_lines`` gives the lines of a text file with their numbers.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass

from ..core.errors import ParseError
from ..core.inputs import read_input

LINE_END = re.compile(r"\r\n|\r|\n")
# Characters str.split() treats as whitespace but the readers must not (no field separators).
ODD_SPACE = re.compile(r"[\x1c-\x1f\x85\xa0\u1680\u2000-\u200a\u2028\u2029\u202f\u205f\u3000]")
FIELD_SEP = re.compile(r"[ \t\f\v]+")


def decode_utf8(data: bytes, path: str) -> str:
    """The file's text; invalid UTF-8 is an error at the line where it starts."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = len(LINE_END.findall(data[: exc.start].decode("utf-8", "replace"))) + 1
        raise ParseError(path, line, "not a text file (invalid UTF-8)") from None


def split_lines(text: str) -> list[str]:
    """The lines of ``text``: ends at ``\\n``, ``\\r\\n`` and ``\\r`` only (module docstring)."""
    return LINE_END.split(text) if "\r" in text else text.split("\n")


def split_fields(line: str) -> list[str]:
    """The fields of one line, separated by ASCII blanks (space, tab, form feed, vertical tab)."""
    if ODD_SPACE.search(line) is None and "\f" not in line and "\v" not in line:
        return line.split()
    return [f for f in FIELD_SEP.split(line) if f]


@dataclass(frozen=True)
class Line:
    """One line of a text input: its 1-based ``number`` and its ``text`` (without the line end)."""

    number: int
    text: str

    def fields(self, comment: str | None = "#") -> list[str]:
        """The fields before ``comment`` (None: the whole line), by ``split_fields``."""
        text = self.text.split(comment, 1)[0] if comment else self.text
        return split_fields(text)


def read_lines(path: str | os.PathLike, *, max_bytes: int | None = None) -> list[Line]:
    """Every line of a text input with its number (``read_input`` then the line rules above):
    regular files only, size-guarded, gzip read transparently, UTF-8 (an invalid byte is a
    ParseError at its line)."""
    inp = read_input(path, max_bytes=max_bytes)
    text = decode_utf8(inp.data, inp.path)
    lines = split_lines(text)
    if lines and lines[-1] == "":
        lines.pop()            # the final line end does not start a line
    return [Line(k, t) for k, t in enumerate(lines, 1)]


__all__ = ["FIELD_SEP", "LINE_END", "ODD_SPACE", "Line", "decode_utf8", "read_lines", "split_fields", "split_lines"]
