"""The output layer: every file posecrb writes is checked here before the work and written here.

docs/howto/output-files.md lists, per command option, what it writes and the extensions it
accepts; docs/design.md#files gives the rules. ``posecrb.core.folders`` writes the multi-file
outputs (a folder swapped in whole) on top of this module.

* ``check_output_file`` / ``check_output_dir``: the path is not empty and has no NUL character; its
  parent directory exists and is writable (probed by creating an anonymous file: ``os.access`` says
  yes to root on a read-only file system); the extension is one the option accepts; an existing
  target is a regular file (or a directory for ``check_output_dir``); and the target is none of the
  inputs of the same call (same file after following symbolic links, or the same inode: a hard
  link). Violations are ``UsageError`` (exit 2), raised before anything is written.
* ``atomic_write`` is the only way posecrb writes a file: the bytes go to a unique temporary in the
  target directory, created exclusively (``O_EXCL``: never an existing file, never through a
  symbolic link), flushed and fsynced, then renamed onto the target with ``os.replace`` (atomic on
  POSIX; a symbolic link at the target is replaced, not followed). On any exception --
  ``KeyboardInterrupt`` and the CLI's exception for SIGTERM included -- the temporary is removed
  and the previous file, if any, is untouched.
* A write the system refuses (disk full, permission denied, read-only file system) is an
  ``OutputError`` with the path and the reason (exit 1), never a traceback. The *first* error is the
  one reported: a buffered write that failed at its flush fails again when the file is closed, and
  that second failure is discarded, not raised in place of the first.
* Text is UTF-8. A file name that is not valid UTF-8 reaches Python as lone surrogates
  (``os.fsdecode``); written into text (a table, a JSON file, the terminal) each undecodable byte is
  shown as ``\\xNN`` (the ``posecrb-escape`` error handler, ``escape_surrogates``).
* ``make_output_dir`` creates an output directory (one level: its parent must exist).
"""
from __future__ import annotations

import codecs
import contextlib
import errno
import io
import os
import re
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO

from .errors import OutputError, UsageError
from .inputs import path_kind, unresolvable

# Temporaries of writes in progress; ``remove_temporaries`` deletes them (last resort of the
# CLI when a signal arrives while a temporary is being created or renamed).
_LIVE: set[str] = set()

GRAPH_EXTENSIONS = (".g2o",)           # graphs written by posecrb (the g2o writer)

# Write errors that are the system's answer about the storage, not a bug: reported with the path.
_STORAGE_ERRNOS = frozenset(getattr(errno, name) for name in (
    "ENOSPC", "EDQUOT", "EFBIG", "EROFS", "EACCES", "EPERM", "EIO", "ENOENT", "ENOTDIR", "EISDIR",
    "ENAMETOOLONG", "ELOOP", "EEXIST", "EXDEV", "EBUSY", "ETXTBSY") if hasattr(errno, name))

# The raw file under every write's buffer. Tests put a class here whose ``write`` fails the way a
# full disk does, so that the buffering above it behaves as with a real device.
RAW_FILE: Callable[..., io.FileIO] = io.FileIO

# ---------------------------------------------------------------------------- undecodable names
ESCAPE = "posecrb-escape"
_SURROGATE = re.compile("[\ud800-\udfff]")


def _escaped(char: str) -> str:
    code = ord(char)
    return f"\\x{code - 0xDC00:02x}" if 0xDC80 <= code <= 0xDCFF else f"\\u{code:04x}"


def escape_surrogates(text: str) -> str:
    """``text`` with each lone surrogate (an undecodable byte of a file name, ``os.fsdecode``) as
    ``\\xNN``; other text unchanged. For libraries that need valid text (matplotlib's titles)."""
    return _SURROGATE.sub(lambda m: _escaped(m.group()), text) if not text.isascii() else text


def _escape_error(exc: UnicodeError) -> tuple[str, int]:
    """Codec error handler ``posecrb-escape``: surrogates as ``\\xNN`` (``_escaped``), any other
    character the encoding lacks as ``\\uNNNN`` (text shown on a terminal of another encoding)."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    return "".join(_escaped(c) if _SURROGATE.match(c) else f"\\u{ord(c):04x}" if ord(c) <= 0xFFFF
                   else f"\\U{ord(c):08x}" for c in exc.object[exc.start: exc.end]), exc.end


codecs.register_error(ESCAPE, _escape_error)


# ---------------------------------------------------------------------------- checks
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


def checked_output_name(path: str | os.PathLike, option: str | None) -> str:
    """``path`` as a string once it can name a file: UsageError when empty or with a NUL character."""
    shown = os.fspath(path)
    if not isinstance(shown, str):
        shown = os.fsdecode(shown)
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


def name_max(directory: str | os.PathLike) -> int:
    """The longest file name (bytes) the file system of ``directory`` takes."""
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def _check_name_length(directory: Path, name: str, option: str | None, shown: str) -> None:
    """UsageError when ``name`` is longer than the file system of ``directory`` allows (found
    before the work, not as ENAMETOOLONG after it)."""
    limit = name_max(directory)
    size = len(os.fsencode(name))
    if size > limit:
        raise UsageError(f"{_shown(option, shown)}: the file name is {size} bytes long; the file system of "
                         f"{directory} allows {limit}")


def _existing_kind(p: Path) -> str | None:
    """What an existing ``p`` is when it is not a regular file (None for a regular file or nothing;
    a dangling symbolic link is replaced by the write)."""
    if not os.path.lexists(p):
        return None
    try:
        st = os.stat(p)
    except OSError as exc:
        return None if exc.errno == errno.ENOENT else unresolvable(exc)
    return None if stat.S_ISREG(st.st_mode) else path_kind(st)


def check_output_file(path: str | os.PathLike, inputs: Sequence[str | os.PathLike | None] = (), *,
                      option: str | None = "--out", extensions: Sequence[str] | None = None) -> Path:
    """Validate an output file before any work (module docstring): UsageError (exit 2) when the
    path is empty, has an extension not in ``extensions``, is a directory or another non-regular
    file, its directory is missing or not writable, or it is one of ``inputs``. Returns the path."""
    shown = checked_output_name(path, option)
    p = Path(os.path.abspath(shown))
    kind = _existing_kind(p)
    if kind is not None:
        raise UsageError(f"{_shown(option, shown)}: is {kind}; give a file name")
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
    """Validate an output directory (created when the output is written if missing): UsageError
    (exit 2) when the path is empty, exists and is not a directory, is missing and so is its parent,
    cannot be written, or when one of the ``names`` it will receive is one of ``inputs``."""
    shown = checked_output_name(path, option)
    p = Path(os.path.abspath(shown))
    if os.path.lexists(p):
        try:
            st = os.stat(p)
        except OSError as exc:
            raise UsageError(f"{_shown(option, shown)}: is {unresolvable(exc)}, not a directory") from None
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
    p = Path(checked_output_name(path, None))
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
def default_mode(directory: bool = False) -> int:
    """The permissions a new file (or directory) gets from the umask: ``mkstemp``'s and
    ``mkdtemp``'s private modes are wrong for results."""
    umask = os.umask(0)
    os.umask(umask)
    return (0o777 if directory else 0o666) & ~umask


def _file_mode(target: str) -> int:
    try:
        return stat.S_IMODE(os.stat(target).st_mode)   # keep an existing file's permissions
    except OSError:
        return default_mode()


def fsync_dir(directory: str | os.PathLike) -> None:
    """Make the renames in ``directory`` durable (ignored where directories cannot be fsynced)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _target(path: str | os.PathLike) -> str:
    """The absolute target of a write; UsageError for an empty path or an existing directory."""
    shown = checked_output_name(path, None)
    target = os.path.abspath(shown)
    if os.path.isdir(target):
        raise UsageError(f"{shown}: is a directory; give a file name")
    return target


def _storage_error(path: str | os.PathLike, exc: OSError) -> OutputError:
    return OutputError(os.fspath(path), exc.strerror or str(exc))


def _discard(fh: IO, raw: io.FileIO) -> None:
    """Close a handle whose write already failed, keeping that first error: closing flushes the
    buffer again, which fails again, and that second error is not the news."""
    with contextlib.suppress(OSError, ValueError):
        fh.close()
    if not raw.closed:
        with contextlib.suppress(OSError):
            raw.close()


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", *, encoding: str | None = "utf-8",
                 newline: str | None = None, suffix: str = ".tmp",
                 before_replace: Callable[[Path], None] | None = None) -> Iterator[IO]:
    """Open a temporary next to ``path`` for writing; on a normal exit it replaces ``path``.

    ``mode`` is ``"w"`` (text; undecodable file-name bytes escaped, module docstring) or ``"wb"``.
    The temporary is ``.<name>.<random><suffix>`` in the same directory (so the rename never crosses
    a file system), created by ``mkstemp`` (``O_EXCL``: never an existing file of the user's, never
    through a symbolic link), flushed and fsynced before ``os.replace``. ``before_replace(temporary)``
    runs after the fsync and may raise to cancel the write (``fetch`` verifies the checksum there).
    On any exception, KeyboardInterrupt and SIGTERM's included, the temporary is removed and ``path``
    is untouched. The system refusing the write (full disk, permissions, read-only file system,
    missing directory) is an ``OutputError`` naming ``path``: the first such error, never the
    repetition of it when the file is closed.
    """
    if mode not in ("w", "wb"):
        raise UsageError(f"atomic_write mode must be 'w' or 'wb', not {mode!r}")
    target = _target(path)
    directory, base = os.path.split(target)
    # the temporary's name fits the file system whatever the target's length (8 random characters)
    room = name_max(directory) - len(os.fsencode(suffix)) - 10
    prefix = "." + os.fsdecode(os.fsencode(base)[:max(room, 1)]).rstrip("\ufffd") + "."
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=directory)
    except OSError as exc:
        raise _storage_error(path, exc) from None
    _LIVE.add(tmp)
    try:
        raw = RAW_FILE(fd, "wb", closefd=True)
        buffered = io.BufferedWriter(raw)
        fh: IO = buffered if mode == "wb" else io.TextIOWrapper(buffered, encoding=encoding, errors=ESCAPE,
                                                                 newline=newline)
        closed = False
        try:
            try:
                yield fh
            except OSError as exc:
                if exc.errno in _STORAGE_ERRNOS and exc.filename is None:
                    raise _storage_error(path, exc) from None
                raise
            try:
                fh.flush()
                os.fsync(fh.fileno())
                fh.close()
                closed = True
            except OSError as exc:
                raise _storage_error(path, exc) from None
        finally:
            if not closed:
                _discard(fh, raw)
        if before_replace is not None:
            before_replace(Path(tmp))
        try:
            os.chmod(tmp, _file_mode(target))
            os.replace(tmp, target)
        except OSError as exc:
            raise _storage_error(path, exc) from None
        fsync_dir(directory)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    finally:
        _LIVE.discard(tmp)


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Atomically write ``text`` (UTF-8, undecodable file-name bytes escaped) to ``path``."""
    with atomic_write(path, "w") as fh:
        fh.write(text)
    return Path(path)


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Atomically write ``data`` to ``path``."""
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def remove_temporaries() -> None:
    """Delete the temporaries of writes still in progress (called by the CLI on a signal)."""
    for tmp in list(_LIVE):
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _LIVE.discard(tmp)


__all__ = ["ESCAPE", "GRAPH_EXTENSIONS", "RAW_FILE", "atomic_write", "check_extension", "check_output_dir",
           "check_output_file", "checked_output_name", "default_mode", "escape_surrogates", "fsync_dir",
           "make_output_dir", "name_max", "remove_temporaries", "same_file", "scratch_dir", "write_bytes",
           "write_text"]
