"""Safe file access: inputs are read only when they are regular files, outputs never destroy data.

Inputs (``read_regular_file``): a directory, FIFO, socket or device given as a data file
is reported as what it is; it is never opened for reading (a FIFO would block, /dev/zero
would fill the memory).

Outputs:

* ``check_output_file`` / ``check_output_dir`` validate an output location BEFORE the work
  starts (a long solve must not end in "no such directory") and refuse a path that is one
  of the command's inputs (``solve X --out X`` would replace the data by the estimate).
* ``atomic_write`` is the only way posecrb writes a file: the bytes go to a unique temporary
  name in the target directory, are flushed and fsynced, and the temporary is renamed onto
  the target with ``os.replace`` (atomic on POSIX). On any exception -- including
  ``KeyboardInterrupt`` and the ``Terminated`` exception the CLI raises on SIGTERM -- the
  temporary is removed and the previous file, if any, is untouched.
"""
from __future__ import annotations

import contextlib
import os
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

from .errors import ParseError, UsageError

# Temporary files of writes in progress; ``remove_temporaries`` deletes them (last resort
# of the CLI when a signal arrives while a temporary is being created or renamed).
_LIVE: set[str] = set()


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


def read_regular_file(path: str | os.PathLike) -> bytes:
    """The bytes of ``path``; ParseError (exit 1) unless it is an existing regular file.

    The type is checked with ``stat`` before opening (opening a FIFO blocks) and again on
    the open descriptor (the path may have been replaced in between); ``O_NONBLOCK`` keeps
    even that second open from blocking.
    """
    name = os.fspath(path)
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
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fh.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise ParseError(name, None, f"is {path_kind(st)}, not a regular file")
        return fh.read()


# ---------------------------------------------------------------------------- output checks
def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when ``a`` and ``b`` name the same file (hard links and symlinks included)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def _probe_writable(directory: Path, option: str, shown: str) -> None:
    """Create (and at once drop) an anonymous file in ``directory``: the only reliable test
    (``os.access`` says yes to root on a read-only file system)."""
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        raise UsageError(f"{option} {shown}: cannot write in {directory}: {exc.strerror or exc}") from None


def _nearest_existing(p: Path) -> Path:
    for anc in (p, *p.parents):
        if os.path.lexists(anc):
            return anc
    return Path("/")


def check_output_file(path: str | os.PathLike, inputs: Sequence[str | os.PathLike | None] = (), *,
                      option: str = "--out", create_parents: bool = False) -> Path:
    """Validate an output file before any work: exit 2 (UsageError) when it is a directory or
    another non-regular file, when its directory is missing (unless ``create_parents``) or not
    writable, or when it is one of ``inputs``. Returns the path."""
    shown = os.fspath(path)
    p = Path(os.path.abspath(shown))
    if os.path.lexists(p):
        try:
            st = os.stat(p)
        except OSError:
            st = None
        if st is not None and not stat.S_ISREG(st.st_mode):
            raise UsageError(f"{option} {shown}: is {path_kind(st)}; give a file name")
    for inp in inputs:
        if inp is not None and os.path.exists(p) and same_file(p, inp):
            raise UsageError(f"{option} {shown} is the input file {os.fspath(inp)}: refusing to overwrite an "
                             "input; write to another path")
    parent = p.parent
    parent_shown = os.path.dirname(shown.rstrip(os.sep)) or "."   # as the user wrote it
    if parent.is_dir():
        _probe_writable(parent, option, shown)
    elif os.path.lexists(parent):
        raise UsageError(f"{option} {shown}: {parent_shown} is not a directory")
    elif not create_parents:
        raise UsageError(f"{option} {shown}: directory {parent_shown} does not exist")
    else:
        anc = _nearest_existing(parent)
        if not anc.is_dir():
            raise UsageError(f"{option} {shown}: {anc} is not a directory")
        _probe_writable(anc, option, shown)
    return Path(shown)


def check_output_dir(path: str | os.PathLike, inputs: Sequence[str | os.PathLike | None] = (),
                     names: Sequence[str] = (), *, option: str = "--out") -> Path:
    """Validate an output directory (created later if missing): exit 2 when it exists and is
    not a directory, when it cannot be created or written, or when one of the ``names`` it
    will receive is one of ``inputs``."""
    shown = os.fspath(path)
    p = Path(os.path.abspath(shown))
    if os.path.lexists(p) and not p.is_dir():
        try:
            kind = path_kind(os.stat(p))
        except OSError:
            kind = "a dangling symbolic link"
        raise UsageError(f"{option} {shown}: is {kind}, not a directory")
    anc = _nearest_existing(p)
    if not anc.is_dir():
        raise UsageError(f"{option} {shown}: {anc} is not a directory")
    _probe_writable(anc, option, shown)
    for name in names:
        for inp in inputs:
            if inp is not None and os.path.exists(p / name) and same_file(p / name, inp):
                raise UsageError(f"{option} {shown}: would overwrite the input file {os.fspath(inp)} "
                                 f"(as {name}); write to another directory")
    return Path(shown)


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


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", *, encoding: str | None = "utf-8",
                 newline: str | None = None, suffix: str = ".tmp",
                 before_replace: Callable[[Path], None] | None = None) -> Iterator[IO]:
    """Open a temporary next to ``path`` for writing; on a normal exit it replaces ``path``.

    ``mode`` is ``"w"`` (text) or ``"wb"``. The temporary is ``.<name>.<random><suffix>`` in
    the same directory (so the rename never crosses a file system), created by ``mkstemp``
    (never an existing file of the user's), flushed and fsynced before ``os.replace``.
    ``before_replace(temporary)`` runs after the fsync and may raise to cancel the write
    (``fetch`` verifies the checksum there). On any exception, KeyboardInterrupt and
    ``Terminated`` (SIGTERM) included, the temporary is removed and ``path`` is untouched.
    """
    if mode not in ("w", "wb"):
        raise UsageError(f"atomic_write mode must be 'w' or 'wb', not {mode!r}")
    target = os.path.abspath(os.fspath(path))
    directory, base = os.path.split(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=suffix, dir=directory)
    _LIVE.add(tmp)
    try:
        kwargs: dict[str, Any] = {} if mode == "wb" else {"encoding": encoding, "newline": newline}
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        if before_replace is not None:
            before_replace(Path(tmp))
        os.chmod(tmp, _file_mode(target))
        os.replace(tmp, target)
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


__all__ = ["Terminated", "atomic_write", "check_output_dir", "check_output_file", "handle_sigterm",
           "path_kind", "read_regular_file", "remove_temporaries", "same_file", "write_bytes", "write_text"]
