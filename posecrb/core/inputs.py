"""The input layer: every data file posecrb reads (a graph, a pairs file, an estimate, an expected
file, a saved result) is opened here.

docs/design.md#files gives the rules; ``posecrb.core.archives`` reads ``.npz`` archives on top of
this module and ``posecrb.io.lines`` splits text inputs into lines and fields.

* Only a regular file is opened: a directory, FIFO, socket or device is reported as what it is (a
  FIFO would block, ``/dev/zero`` would fill the memory); the type is checked with ``stat`` before
  opening and again on the open descriptor, which is opened non-blocking.
* Its size is checked against the memory available before it is read (``INPUT_EXPANSION`` bytes of
  working memory per byte of input), and the read itself stops at that bound (a file that grows
  meanwhile cannot get around it).
* gzip is recognised by its magic bytes, whatever the name, and decompressed with the same bound on
  the decompressed size (a gzip bomb is refused, not expanded). The compressed input is fed to zlib
  in slices of ``_INPUT_SLICE`` bytes, so that each call's unconsumed input, which zlib hands back as
  a copy, is at most one slice: the work is linear in the input, never quadratic.
* An empty path or one with a NUL character is refused before the system sees it.
* Every failure is a ``ParseError`` naming the file (exit 1).
"""
from __future__ import annotations

import errno
import hashlib
import os
import stat
import zlib
from dataclasses import dataclass
from typing import IO, cast

from .errors import ArgumentError, ParseError
from .resources import available_memory, format_bytes

# Reading a pose graph needs about 5 bytes of working memory per byte of file (the text, its
# token boundaries, the numbers and the graph's arrays; measured: 1.44 GB above the interpreter's
# own for the 330 MB 2D grid of a million poses, 114 MB for a 21 MB 3D grid; 12 before the
# vectorised converter); 16 leaves a margin. Inputs whose size times this exceeds the available
# memory are refused before they are read.
INPUT_EXPANSION = 16
# Without a memory figure from the system, inputs are capped at this many bytes (decompressed).
DEFAULT_INPUT_LIMIT = 16 * 1024 ** 3
GZIP_MAGIC = b"\x1f\x8b"
# Decompressed bytes returned by one zlib call, and compressed bytes given to it (see the docstring).
_CHUNK = 1 << 20
_INPUT_SLICE = 1 << 16


def path_kind(st: os.stat_result) -> str:
    """'a directory', 'a FIFO (named pipe)', ... for a stat result."""
    mode = st.st_mode
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISREG, "a regular file")):
        if test(mode):
            return name
    return "not a regular file"


def unresolvable(exc: OSError) -> str:
    """What a path whose ``stat`` failed with ``exc`` is, for a path that exists as a name
    (``os.path.lexists``): a symbolic link loop is not a dangling link."""
    if exc.errno == errno.ELOOP:
        return "a symbolic link loop"
    if exc.errno in (errno.ENOENT, errno.ENOTDIR):
        return "a dangling symbolic link"
    return f"unreadable ({exc.strerror or exc})"


def checked_name(path: str | os.PathLike) -> str:
    """``path`` as a string once it can name a file: ParseError for an empty path or a NUL character
    (which the system would refuse with a raw ``ValueError``), ArgumentError for what is no path."""
    if not isinstance(path, (str, bytes, os.PathLike)):
        raise ArgumentError("path", path, "is not a file name (a str or os.PathLike)")
    name = os.fspath(path)
    if not isinstance(name, str):
        name = os.fsdecode(name)
    if not name:
        raise ParseError("''", None, "empty path; give a file name")
    if "\0" in name:
        raise ParseError(repr(name), None, "a path cannot contain a NUL character")
    return name


# ============================================================================ inputs
def input_limit() -> int:
    """Largest input (decompressed) read: the available memory / ``INPUT_EXPANSION``."""
    avail = available_memory()
    return DEFAULT_INPUT_LIMIT if avail is None else max(avail // INPUT_EXPANSION, _CHUNK)


def too_large(name: str, size: int | str, limit: int, expansion: int = INPUT_EXPANSION) -> ParseError:
    """The ParseError of an input of ``size`` bytes above ``limit`` (reading needs ``expansion`` times it)."""
    return ParseError(name, None, f"{size} bytes need about {expansion} times as much memory to read; "
                                  f"more than the {format_bytes(limit * expansion)} available "
                                  f"(largest input here: {format_bytes(limit)})")


def _open_regular(name: str) -> tuple[IO[bytes], os.stat_result]:
    """An open binary handle of ``name`` once it is known to be a regular file (module docstring)."""
    name = checked_name(name)
    try:
        st = os.stat(name)
    except FileNotFoundError:
        if os.path.lexists(name):
            raise ParseError(name, None, "is a dangling symbolic link") from None
        raise ParseError(name, None, "no such file") from None
    except OSError as exc:
        what = unresolvable(exc) if os.path.lexists(name) else f"unreadable ({exc.strerror or exc})"
        raise ParseError(name, None, f"cannot read file: is {what}") from None
    if not stat.S_ISREG(st.st_mode):
        raise ParseError(name, None, f"is {path_kind(st)}, not a regular file")
    try:
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise ParseError(name, None, f"cannot read file: {exc.strerror or exc}") from None
    fh = os.fdopen(fd, "rb")
    st = os.fstat(fh.fileno())
    if not stat.S_ISREG(st.st_mode):
        fh.close()
        raise ParseError(name, None, f"is {path_kind(st)}, not a regular file")
    return fh, st


def _guarded(path: str | os.PathLike, max_bytes: int | None, read: bool) -> bytes | None:
    name = checked_name(path)
    limit = input_limit() if max_bytes is None else max_bytes
    fh, st = _open_regular(name)
    with fh:
        if st.st_size > limit:
            raise too_large(name, st.st_size, limit)
        if not read:
            return None
        try:
            # The size stat gave, plus one byte to see growth: read(limit + 1) would allocate the
            # whole limit and copy the data into a smaller object at the end; a file that grew
            # since is read on up to the limit.
            data = fh.read(st.st_size + 1)
            if len(data) > st.st_size:
                data += fh.read(limit + 1 - len(data))
        except OSError as exc:
            raise ParseError(name, None, f"cannot read file: {exc.strerror or exc}") from None
        if len(data) > limit:
            raise too_large(name, f"more than {limit}", limit)
        return data


def check_input_file(path: str | os.PathLike, *, max_bytes: int | None = None) -> None:
    """The guards of ``read_regular_file`` without reading (options checked before the work):
    ParseError unless ``path`` is an existing regular file no larger than ``max_bytes``."""
    _guarded(path, max_bytes, read=False)


def read_regular_file(path: str | os.PathLike, *, max_bytes: int | None = None) -> bytes:
    """The bytes of ``path`` as stored; ParseError (exit 1) unless it is an existing regular file
    no larger than ``max_bytes`` (default ``input_limit()``)."""
    return cast(bytes, _guarded(path, max_bytes, read=True))


def gunzip(data: bytes, name: str, limit: int | None = None) -> bytes:
    """The decompressed content of gzip ``data`` (every member); ParseError when the stream is
    corrupt or truncated, or decompresses to more than ``limit`` bytes (default ``input_limit()``).

    The input goes to zlib in slices of ``_INPUT_SLICE`` bytes (module docstring)."""
    limit = input_limit() if limit is None else limit
    view = memoryview(data)
    out: list[bytes] = []
    total = 0
    pos = 0
    try:
        while pos < len(view):
            d = zlib.decompressobj(16 + zlib.MAX_WBITS)   # one gzip member
            while not d.eof:
                if pos >= len(view):
                    raise ParseError(name, None, "truncated gzip data (the stream ends before its end marker)")
                src: bytes | memoryview = view[pos: pos + _INPUT_SLICE]
                pos += len(src)
                while True:
                    chunk = d.decompress(src, _CHUNK)
                    total += len(chunk)
                    if total > limit:
                        raise too_large(name, f"more than {limit} (decompressed)", limit)
                    out.append(chunk)
                    src = d.unconsumed_tail               # at most one slice
                    if d.eof or not (src or chunk):
                        break
            pos -= len(d.unused_data)                     # the next member starts in this slice
            if pos < len(view) and view[pos: pos + 2] != GZIP_MAGIC:
                if bytes(view[pos:]).strip(b"\0"):
                    raise ParseError(name, None, "trailing data after the gzip stream")
                break
    except zlib.error as exc:
        raise ParseError(name, None, f"corrupt gzip data ({exc})") from None
    return b"".join(out)


@dataclass(frozen=True)
class InputData:
    """A data file as read by ``read_input``: ``data`` (decompressed when the file is gzip),
    ``sha256`` of the bytes as stored (what identifies the file), ``compressed``."""

    path: str
    data: bytes
    sha256: str
    compressed: bool


def read_input(path: str | os.PathLike, *, max_bytes: int | None = None) -> InputData:
    """Read a data file through the guards of the module docstring (regular file, size, gzip)."""
    name = checked_name(path)
    limit = input_limit() if max_bytes is None else max_bytes
    raw = read_regular_file(name, max_bytes=limit)
    digest = hashlib.sha256(raw).hexdigest()
    if raw.startswith(GZIP_MAGIC):
        return InputData(name, gunzip(raw, name, limit), digest, True)
    return InputData(name, raw, digest, False)


__all__ = ["DEFAULT_INPUT_LIMIT", "GZIP_MAGIC", "INPUT_EXPANSION", "InputData", "check_input_file", "checked_name",
           "gunzip", "input_limit", "path_kind", "read_input", "read_regular_file", "too_large", "unresolvable"]
