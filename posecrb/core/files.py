"""The file layer: every file posecrb reads or writes goes through this module.

docs/howto/output-files.md lists, per command option, what it writes and the extensions it
accepts; docs/design.md#files gives the rules. A test walks the whole command tree and tries every
path-writing option against them, and another fails if any other module opens a file for writing.

Inputs
------
``read_input`` is the one way to read a data file (a graph, a pairs file, an estimate, an expected
file):

* only a regular file is opened: a directory, FIFO, socket or device is reported as what it is
  (a FIFO would block, ``/dev/zero`` would fill the memory); the type is checked with ``stat``
  before opening and again on the open descriptor, which is opened non-blocking;
* its size is checked against the memory available before it is read (``INPUT_EXPANSION`` bytes
  of working memory per byte of input), and the read itself stops at that bound (a file that
  grows meanwhile cannot get around it);
* gzip is recognised by its magic bytes, whatever the name, and decompressed transparently,
  with the same bound on the decompressed size (a gzip bomb is refused, not expanded);
* every failure is a ``ParseError`` naming the file (exit 1).

Text inputs are split by the pose-graph readers' line rules (``split_lines``, ``split_fields``):
lines end at ``\\n``, ``\\r\\n`` or ``\\r`` only (``str.splitlines`` would also break at form
feed, vertical tab, ``\\x1c``-``\\x1e``, NEL and U+2028/U+2029, turning the tail of a ``#``
comment into data and shifting every later line number), and fields are separated by ASCII
blanks only. ``read_lines`` gives the lines of a text file with their numbers.

Outputs
-------
Every file or directory posecrb writes is validated *before the work* and written atomically:

* ``check_output_file`` / ``check_output_dir``: the path is not empty; its parent directory
  exists and is writable (probed by creating an anonymous file: ``os.access`` says yes to root on a
  read-only file system); the extension is one the option accepts; an existing target is a regular
  file (or a directory for ``check_output_dir``); and the target is none of the inputs of the same
  call (same file after following symbolic links, or the same inode: a hard link). Violations are
  ``UsageError`` (exit 2), raised before anything is written.
* ``atomic_write`` is the only way posecrb writes a file: the bytes go to a unique temporary in
  the target directory, created exclusively (``O_EXCL``: never an existing file, never through a
  symbolic link), flushed and fsynced, then renamed onto the target with ``os.replace`` (atomic on
  POSIX; a symbolic link at the target is replaced, not followed). On any exception --
  ``KeyboardInterrupt`` and the ``Terminated`` exception the CLI raises on SIGTERM included -- the
  temporary is removed and the previous file, if any, is untouched. A write the system refuses
  (disk full, permission denied, read-only file system) is an ``OutputError`` with the path and
  the reason (exit 1), never a traceback.
* ``make_output_dir`` creates an output directory (one level: its parent must exist).
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import signal
import stat
import tempfile
import threading
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, cast

from .errors import OutputError, ParseError, UsageError
from .resources import available_memory, format_bytes

# Temporary files of writes in progress; ``remove_temporaries`` deletes them (last resort
# of the CLI when a signal arrives while a temporary is being created or renamed).
_LIVE: set[str] = set()

# Reading a pose graph needs about 12 bytes of working memory per byte of file (the text, its
# token boundaries, the numeric blocks and the graph's arrays; measured on an 80 MB 3D graph,
# 1 GB peak); 16 leaves a margin. Inputs whose size times this exceeds the available memory are
# refused before they are read.
INPUT_EXPANSION = 16
# Without a memory figure from the system, inputs are capped at this many bytes (decompressed).
DEFAULT_INPUT_LIMIT = 16 * 1024 ** 3
GZIP_MAGIC = b"\x1f\x8b"
# Figures: the format follows the extension (matplotlib writes each without a display).
FIGURE_EXTENSIONS = (".png", ".svg", ".pdf")
GRAPH_EXTENSIONS = (".g2o",)           # graphs written by posecrb (the g2o writer)
_CHUNK = 1 << 20

# Write errors that are the system's answer about the storage, not a bug: reported with the path.
_STORAGE_ERRNOS = frozenset(getattr(errno, name) for name in (
    "ENOSPC", "EDQUOT", "EFBIG", "EROFS", "EACCES", "EPERM", "EIO", "ENOENT", "ENOTDIR", "EISDIR",
    "ENAMETOOLONG", "ELOOP", "EEXIST", "EXDEV", "EBUSY", "ETXTBSY") if hasattr(errno, name))


class Terminated(BaseException):
    """Raised in the main thread on SIGTERM (installed by ``handle_sigterm``) so that every
    ``finally`` and ``atomic_write`` clean-up runs before the process exits."""

    def __init__(self, signum: int = signal.SIGTERM):
        self.signum = signum
        super().__init__(f"terminated by signal {signum}")


def path_kind(st: os.stat_result) -> str:
    """'a directory', 'a FIFO (named pipe)', ... for a stat result."""
    mode = st.st_mode
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISREG, "a regular file")):
        if test(mode):
            return name
    return "not a regular file"


# ============================================================================ inputs
def input_limit() -> int:
    """Largest input (decompressed) read: the available memory / ``INPUT_EXPANSION``."""
    avail = available_memory()
    return DEFAULT_INPUT_LIMIT if avail is None else max(avail // INPUT_EXPANSION, _CHUNK)


def _too_large(name: str, size: int | str, limit: int) -> ParseError:
    return ParseError(name, None, f"{size} bytes need about {INPUT_EXPANSION} times as much memory to read; "
                                  f"more than the {format_bytes(limit * INPUT_EXPANSION)} available "
                                  f"(largest input here: {format_bytes(limit)})")


def _open_regular(name: str) -> tuple[IO[bytes], os.stat_result]:
    """An open binary handle of ``name`` once it is known to be a regular file (module docstring)."""
    if not name:
        raise ParseError("''", None, "empty path; give a file name")
    if "\0" in name:
        raise ParseError(repr(name), None, "a path cannot contain a NUL character")
    try:
        st = os.stat(name)
    except FileNotFoundError:
        raise ParseError(name, None, "no such file") from None
    except OSError as exc:
        raise ParseError(name, None, f"cannot read file: {exc.strerror or exc}") from None
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


def _read_bounded(fh: IO[bytes], name: str, limit: int) -> bytes:
    data = fh.read(limit + 1)
    if len(data) > limit:
        raise _too_large(name, f"more than {limit}", limit)
    return data


def _guarded(path: str | os.PathLike, max_bytes: int | None, read: bool) -> bytes | None:
    name = os.fspath(path)
    limit = input_limit() if max_bytes is None else max_bytes
    fh, st = _open_regular(name)
    with fh:
        if st.st_size > limit:
            raise _too_large(name, st.st_size, limit)
        return _read_bounded(fh, name, limit) if read else None


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
    corrupt or truncated, or decompresses to more than ``limit`` bytes (default ``input_limit()``)."""
    limit = input_limit() if limit is None else limit
    out: list[bytes] = []
    total = 0
    rest = data
    try:
        while rest:
            d = zlib.decompressobj(16 + zlib.MAX_WBITS)   # one gzip member
            src = rest
            while True:
                chunk = d.decompress(src, _CHUNK)
                total += len(chunk)
                if total > limit:
                    raise _too_large(name, f"more than {limit} (decompressed)", limit)
                out.append(chunk)
                src = d.unconsumed_tail
                if d.eof or not (src or chunk):
                    break
            if not d.eof:
                raise ParseError(name, None, "truncated gzip data (the stream ends before its end marker)")
            rest = d.unused_data
            if rest and not rest.startswith(GZIP_MAGIC):
                if rest.strip(b"\0"):
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
    name = os.fspath(path)
    limit = input_limit() if max_bytes is None else max_bytes
    raw = read_regular_file(name, max_bytes=limit)
    digest = hashlib.sha256(raw).hexdigest()
    if raw.startswith(GZIP_MAGIC):
        return InputData(name, gunzip(raw, name, limit), digest, True)
    return InputData(name, raw, digest, False)


# ---------------------------------------------------------------------------- line rules
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


# ============================================================================ outputs
def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when ``a`` and ``b`` name the same file (hard links and symlinks included)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        try:
            return os.path.realpath(a) == os.path.realpath(b)
        except (OSError, ValueError):
            return False


def _shown(option: str | None, shown: str) -> str:
    return f"{option} {shown}" if option else shown


def _probe_writable(directory: Path, option: str | None, shown: str) -> None:
    """Create (and at once drop) an anonymous file in ``directory``: the only reliable test
    (``os.access`` says yes to root on a read-only file system)."""
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        raise UsageError(f"{_shown(option, shown)}: cannot write in {directory}: {exc.strerror or exc}") from None


def _check_name(path: str | os.PathLike, option: str | None) -> str:
    shown = os.fspath(path)
    if not shown.strip():
        raise UsageError(f"{option + ': ' if option else ''}empty path; give a file name")
    if "\0" in shown:
        raise UsageError(f"{_shown(option, repr(shown))}: a path cannot contain a NUL character")
    return shown


def check_extension(path: str | os.PathLike, extensions: Sequence[str], option: str | None = None) -> None:
    """UsageError unless ``path`` ends in one of ``extensions`` (case-insensitive)."""
    shown = os.fspath(path)
    if not any(shown.lower().endswith(e.lower()) for e in extensions):
        suffix = Path(shown).suffix
        raise UsageError(f"{_shown(option, shown)}: the extension must be {' or '.join(extensions)} "
                         f"(got {suffix or 'none'}); the format follows the extension")


def _name_max(directory: str | os.PathLike) -> int:
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def _check_name_length(directory: Path, name: str, option: str | None, shown: str) -> None:
    """UsageError when ``name`` is longer than the file system of ``directory`` allows (found
    before the work, not as ENAMETOOLONG after it)."""
    limit = _name_max(directory)
    size = len(os.fsencode(name))
    if size > limit:
        raise UsageError(f"{_shown(option, shown)}: the file name is {size} bytes long; the file system of "
                         f"{directory} allows {limit}")


def check_output_file(path: str | os.PathLike, inputs: Sequence[str | os.PathLike | None] = (), *,
                      option: str | None = "--out", extensions: Sequence[str] | None = None) -> Path:
    """Validate an output file before any work (module docstring): UsageError (exit 2) when the
    path is empty, has an extension not in ``extensions``, is a directory or another non-regular
    file, its directory is missing or not writable, or it is one of ``inputs``. Returns the path."""
    shown = _check_name(path, option)
    p = Path(os.path.abspath(shown))
    if os.path.lexists(p):
        try:
            st = os.stat(p)
        except OSError:
            st = None                       # a dangling symbolic link: replaced by the write
        if st is not None and not stat.S_ISREG(st.st_mode):
            raise UsageError(f"{_shown(option, shown)}: is {path_kind(st)}; give a file name")
    if shown.endswith(os.sep) or (os.altsep and shown.endswith(os.altsep)):
        raise UsageError(f"{_shown(option, shown)}: names a directory; give a file name")
    if extensions is not None:
        check_extension(shown, extensions, option)
    for inp in inputs:
        if inp is not None and os.path.lexists(p) and same_file(p, inp):
            raise UsageError(f"{_shown(option, shown)} is the input file {os.fspath(inp)}: refusing to overwrite "
                             "an input; write to another path")
    _check_parent(p, shown, option)
    return Path(shown)


def _check_parent(p: Path, shown: str, option: str | None) -> None:
    """The directory of the absolute target ``p`` exists, is writable and takes its name."""
    parent = p.parent
    parent_shown = os.path.dirname(shown.rstrip(os.sep)) or "."   # as the user wrote it
    if parent.is_dir():
        _probe_writable(parent, option, shown)
        _check_name_length(parent, p.name, option, shown)
    elif os.path.lexists(parent):
        raise UsageError(f"{_shown(option, shown)}: {parent_shown} is not a directory")
    else:
        raise UsageError(f"{_shown(option, shown)}: directory {parent_shown} does not exist")


def check_output_dir(path: str | os.PathLike, inputs: Sequence[str | os.PathLike | None] = (),
                     names: Sequence[str] = (), *, option: str | None = "--out") -> Path:
    """Validate an output directory (created by ``make_output_dir`` if missing): UsageError (exit 2)
    when the path is empty, exists and is not a directory, is missing and so is its parent, cannot
    be written, or when one of the ``names`` it will receive is one of ``inputs``."""
    shown = _check_name(path, option)
    p = Path(os.path.abspath(shown))
    if os.path.lexists(p):
        try:
            st = os.stat(p)
        except OSError:
            raise UsageError(f"{_shown(option, shown)}: is a dangling symbolic link, not a directory") from None
        if not stat.S_ISDIR(st.st_mode):
            raise UsageError(f"{_shown(option, shown)}: is {path_kind(st)}, not a directory")
        _probe_writable(p, option, shown)
    else:
        _check_parent(p, shown, option)
    for name in names:
        _check_name_length(p if p.is_dir() else p.parent, name, option, shown)
    for inp in inputs:
        if inp is None:
            continue
        if os.path.lexists(p) and same_file(p, inp):
            raise UsageError(f"{_shown(option, shown)} is the input {os.fspath(inp)}; write to another directory")
        for name in names:
            if os.path.lexists(p / name) and same_file(p / name, inp):
                raise UsageError(f"{_shown(option, shown)}: would overwrite the input file {os.fspath(inp)} "
                                 f"(as {name}); write to another directory")
    return Path(shown)


def make_output_dir(path: str | os.PathLike, *, parents: bool = False) -> Path:
    """Create the output directory ``path`` unless it exists (its parent must exist, unless
    ``parents``: the user cache ``~/.cache/posecrb``); OutputError when the system refuses."""
    p = Path(_check_name(path, None))
    try:
        p.mkdir(parents=parents, exist_ok=True)
    except OSError as exc:
        raise OutputError(os.fspath(path), exc.strerror or str(exc)) from None
    if not p.is_dir():
        raise OutputError(os.fspath(path), "exists and is not a directory")
    return p


def scratch_dir(prefix: str = "posecrb-") -> Path:
    """A new private directory under the system's temporary directory (mode 0700)."""
    try:
        return Path(tempfile.mkdtemp(prefix=prefix))
    except OSError as exc:
        raise OutputError(tempfile.gettempdir(), exc.strerror or str(exc)) from None


# ---------------------------------------------------------------------------- atomic writes
def _file_mode(target: str) -> int:
    try:
        return stat.S_IMODE(os.stat(target).st_mode)   # keep an existing file's permissions
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask                          # mkstemp's 0600 is wrong for results


def _fsync_dir(directory: str) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _target(path: str | os.PathLike) -> str:
    """The absolute target of a write; UsageError for an empty path or an existing directory."""
    shown = _check_name(path, None)
    target = os.path.abspath(shown)
    if os.path.isdir(target):
        raise UsageError(f"{shown}: is a directory; give a file name")
    return target


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", *, encoding: str | None = "utf-8",
                 newline: str | None = None, suffix: str = ".tmp",
                 before_replace: Callable[[Path], None] | None = None) -> Iterator[IO]:
    """Open a temporary next to ``path`` for writing; on a normal exit it replaces ``path``.

    ``mode`` is ``"w"`` (text) or ``"wb"``. The temporary is ``.<name>.<random><suffix>`` in
    the same directory (so the rename never crosses a file system), created by ``mkstemp``
    (``O_EXCL``: never an existing file of the user's, never through a symbolic link), flushed and
    fsynced before ``os.replace``. ``before_replace(temporary)`` runs after the fsync and may raise
    to cancel the write (``fetch`` verifies the checksum there). On any exception,
    KeyboardInterrupt and ``Terminated`` (SIGTERM) included, the temporary is removed and ``path``
    is untouched. The system refusing the write (full disk, permissions, read-only file system,
    missing directory) is an ``OutputError`` naming ``path``.
    """
    if mode not in ("w", "wb"):
        raise UsageError(f"atomic_write mode must be 'w' or 'wb', not {mode!r}")
    target = _target(path)
    directory, base = os.path.split(target)
    # the temporary's name fits the file system whatever the target's length (8 random characters)
    room = _name_max(directory) - len(os.fsencode(suffix)) - 10
    prefix = "." + os.fsdecode(os.fsencode(base)[:max(room, 1)]).rstrip("\ufffd") + "."
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=directory)
    except OSError as exc:
        raise OutputError(os.fspath(path), exc.strerror or str(exc)) from None
    _LIVE.add(tmp)
    try:
        kwargs: dict[str, Any] = {} if mode == "wb" else {"encoding": encoding, "newline": newline}
        with os.fdopen(fd, mode, **kwargs) as fh:
            try:
                yield fh
            except OSError as exc:
                if exc.errno in _STORAGE_ERRNOS and exc.filename is None:
                    raise OutputError(os.fspath(path), exc.strerror or str(exc)) from None
                raise
            try:
                fh.flush()
                os.fsync(fh.fileno())
            except OSError as exc:
                raise OutputError(os.fspath(path), exc.strerror or str(exc)) from None
        if before_replace is not None:
            before_replace(Path(tmp))
        try:
            os.chmod(tmp, _file_mode(target))
            os.replace(tmp, target)
        except OSError as exc:
            raise OutputError(os.fspath(path), exc.strerror or str(exc)) from None
        _fsync_dir(directory)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    finally:
        _LIVE.discard(tmp)


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Atomically write ``text`` (UTF-8) to ``path``."""
    with atomic_write(path, "w") as fh:
        fh.write(text)
    return Path(path)


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Atomically write ``data`` to ``path``."""
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def save_figure(fig: Any, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Write a matplotlib figure through ``atomic_write``; the format follows the extension, one of
    ``FIGURE_EXTENSIONS`` (UsageError otherwise: ``x.xyz`` is never a PNG under another name). The
    figure is closed either way; SVG text stays text (searchable, smaller than glyph paths)."""
    import matplotlib.pyplot as plt  # noqa: PLC0415 -- matplotlib only for figures

    p = Path(path)
    try:
        check_extension(p, FIGURE_EXTENSIONS)
        fig.tight_layout()
        with atomic_write(p, "wb") as fh, plt.rc_context({"svg.fonttype": "none"}):
            fig.savefig(fh, dpi=dpi, format=p.suffix[1:].lower())
    finally:
        plt.close(fig)
    return p


def remove_temporaries() -> None:
    """Delete the temporaries of writes still in progress (called by the CLI on a signal)."""
    for tmp in list(_LIVE):
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _LIVE.discard(tmp)


# ---------------------------------------------------------------------------- SIGTERM
_MAIN_PID: int | None = None


def _on_sigterm(signum, frame):  # pragma: no cover - exercised in a subprocess test
    if os.getpid() != _MAIN_PID:
        # A forked worker (process pool) inherited the handler: die as SIGTERM intends.
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    raise Terminated(signum)


@contextlib.contextmanager
def handle_sigterm() -> Iterator[None]:
    """While active (main thread only), SIGTERM raises ``Terminated`` instead of killing the
    process outright, so temporaries are removed and partial downloads discarded."""
    global _MAIN_PID

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _MAIN_PID = os.getpid()
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except (ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


__all__ = ["DEFAULT_INPUT_LIMIT", "FIGURE_EXTENSIONS", "INPUT_EXPANSION", "InputData", "Line", "Terminated",
           "atomic_write", "check_extension", "check_input_file", "check_output_dir", "check_output_file",
           "decode_utf8", "gunzip", "handle_sigterm", "input_limit", "make_output_dir", "path_kind", "read_input",
           "read_lines", "read_regular_file", "remove_temporaries", "same_file", "save_figure", "scratch_dir",
           "split_fields",
           "split_lines", "write_bytes", "write_text"]
