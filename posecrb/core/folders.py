"""Multi-file outputs (``tables --out DIR``, ``experiment ... --out DIR``): a folder swapped in whole.

The promise: after a failure or a signal, posecrb's own files in the folder are all of the old run
or all of the new one, never a mix; files in the folder that posecrb did not write are never
touched. ``output_folder(path)`` keeps it:

1. The run writes its files into a private staging directory on the folder's file system, so
   that every later step is a rename: inside the folder when it exists
   (``.posecrb-staging-<random>``: the folder is the one directory known to be writable, even
   when it is a symbolic link to another file system), next to it otherwise
   (``.<name>.posecrb-<random>``). Each file goes through ``posecrb.core.outputs.atomic_write``
   as any other output; a failure is reported with the folder's path of the file, not the
   staging one.
2. On success the staging directory receives the manifest ``MANIFEST``: the name and sha256 of
   every file of the run.
3. Commit. A folder that does not exist yet is the staging directory renamed into place (one
   atomic rename). An existing folder gets a swap: posecrb's files of the previous run -- those its
   manifest lists whose content still has the listed sha256, and any file the new run replaces --
   are moved aside into the staging directory, then the new files are moved in. A rename the system
   refuses rolls back every rename done so far. SIGINT, SIGTERM and SIGHUP arriving during the
   commit are held and re-raised once it is done (``deferred_signals``), so a signal cannot cut
   the swap in half: it sees the old run or the new one.
4. The staging directory (with the old files) is removed.

A failure or a signal before the commit removes the staging directory; the folder is untouched.
A file whose name the manifest lists but whose content changed since is the user's now: left alone.
Only a process killed outright (SIGKILL, power loss) can leave a staging directory behind.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, overload

from .._version import __version__
from .errors import OutputError, ParseError
from .inputs import read_regular_file
from .outputs import checked_output_name, default_mode, fsync_dir, name_max, write_text

log = logging.getLogger("posecrb")

MANIFEST = ".posecrb-files.json"
MANIFEST_SCHEMA = 1
_DEFERRED = tuple(getattr(signal, s) for s in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, s))


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """While active, SIGINT, SIGTERM and SIGHUP are recorded instead of handled; on exit the
    previous handlers are restored and each recorded signal is raised again (so the CLI's handler,
    Python's KeyboardInterrupt or the default action follows, after the critical section).

    Python runs signal handlers in the main thread only; elsewhere this does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    previous: dict[int, Any] = {}
    try:
        for sig in _DEFERRED:
            previous[sig] = signal.signal(sig, lambda signum, frame: pending.append(signum))
    except (ValueError, OSError):        # not the main interpreter, or the platform refuses
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        yield
        return
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        for sig in dict.fromkeys(pending):
            signal.raise_signal(sig)


def _sha256(path: Path) -> str | None:
    """The sha256 of the regular file ``path`` (never through a symbolic link), None otherwise."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return None
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        return hashlib.file_digest(fh, "sha256").hexdigest()


def _plain_name(name: Any) -> bool:
    return (isinstance(name, str) and name not in ("", ".", "..") and "\0" not in name
            and os.path.basename(name) == name and (os.altsep is None or os.altsep not in name))


class _Staging:
    """The staging directory of one folder output and its commit (module docstring)."""

    def __init__(self, path: str | os.PathLike):
        self.shown = checked_output_name(path, None)
        self.final = Path(os.path.realpath(os.path.abspath(self.shown)))    # a symbolic link's target
        if self.final.is_dir():
            where, prefix = self.final, ".posecrb-staging-"
        else:
            where, base = self.final.parent, self.final.name
            room = name_max(where) - len(".posecrb-") - 10
            prefix = "." + os.fsdecode(os.fsencode(base)[:max(room, 1)]).rstrip("\ufffd") + ".posecrb-"
        self.kept = False
        try:
            self.staging = Path(tempfile.mkdtemp(prefix=prefix, dir=where))
        except OSError as exc:
            raise OutputError(self.shown, exc.strerror or str(exc)) from None

    def shown_path(self, path: str) -> str:
        """A path inside the staging directory as the user will see it: inside the folder."""
        staged = os.fspath(self.staging)
        if path == staged or path.startswith(staged + os.sep):
            return os.path.join(self.shown, os.path.relpath(path, staged))
        return path

    def abandon(self) -> None:
        """Remove the staging directory, unless it holds previous files a failed swap could not
        put back (``_swap``): those are the user's only copy."""
        if not self.kept:
            shutil.rmtree(self.staging, ignore_errors=True)

    def _previous(self, new: list[str]) -> list[str]:
        """posecrb's files of the previous run in the folder (module docstring, step 3)."""
        old = {n for n in new if os.path.lexists(self.final / n)}
        manifest = self.final / MANIFEST
        if not os.path.lexists(manifest):
            return sorted(old)
        try:
            files = json.loads(read_regular_file(manifest, max_bytes=1 << 22))["files"]
            listed = {n: d for n, d in files.items() if _plain_name(n)}
        except (ParseError, ValueError, KeyError, TypeError, AttributeError):
            log.warning("%s is unreadable: files of an earlier run that this run does not write are left in place",
                        os.path.join(self.shown, MANIFEST))
            return sorted(old)
        old |= {n for n, digest in listed.items() if n not in old and _sha256(self.final / n) == digest}
        return sorted(old)

    def _manifest(self, new: list[str]) -> None:
        digests = {n: _sha256(self.staging / n) for n in new}
        text = json.dumps({"schema": MANIFEST_SCHEMA, "written_by": f"posecrb {__version__}", "files": digests},
                          indent=2) + "\n"
        write_text(self.staging / MANIFEST, text)

    def commit(self) -> list[str]:
        """Swap the new files in (module docstring, steps 2-4); returns their names."""
        new = sorted(p.name for p in self.staging.iterdir() if p.is_file() and p.name != MANIFEST)
        self._manifest(new)
        with deferred_signals():
            if not os.path.lexists(self.final):
                os.chmod(self.staging, default_mode(directory=True))
                try:
                    os.rename(self.staging, self.final)
                except OSError:
                    pass                      # created meanwhile: swap into it below
                else:
                    fsync_dir(self.final.parent)
                    return new
            self._swap([*new, MANIFEST])
            self.abandon()
        return new

    def _swap(self, new: list[str]) -> None:
        old = self._previous(new)
        aside = self.staging / ".previous"
        out: list[str] = []
        done: list[str] = []
        try:
            aside.mkdir()
            for name in old:
                os.rename(self.final / name, aside / name)
                out.append(name)
            for name in new:
                os.rename(self.staging / name, self.final / name)
                done.append(name)
        except OSError as exc:
            failed = exc.filename if isinstance(exc.filename, str) else os.fspath(self.final)
            try:
                for name in reversed(done):
                    os.rename(self.final / name, self.staging / name)
                for name in reversed(out):
                    os.rename(aside / name, self.final / name)
            except OSError as undo:
                self.kept = True
                raise OutputError(self.shown_path(failed), f"{exc.strerror or exc}; restoring the previous files "
                                                           f"failed too ({undo.strerror or undo}): the folder "
                                                           "holds files of both runs, and the previous files not "
                                                           f"put back are in {aside}") from None
            raise OutputError(self.shown_path(failed), exc.strerror or str(exc)) from None
        fsync_dir(self.final)


@overload
def output_folder(path: None) -> contextlib.AbstractContextManager[None]: ...


@overload
def output_folder(path: str | os.PathLike) -> contextlib.AbstractContextManager[Path]: ...


def output_folder(path: str | os.PathLike | None) -> contextlib.AbstractContextManager[Path | None]:
    """Write a folder output whole (module docstring): a context manager giving the staging
    directory to write the files into (with the layer's writers), which swaps them into ``path``
    when the block ends without an exception. An ``OutputError`` raised inside names the file's path
    in the folder. ``None`` (no folder asked for) gives ``None`` and does nothing."""
    return contextlib.nullcontext() if path is None else _folder(path)


@contextlib.contextmanager
def _folder(path: str | os.PathLike) -> Iterator[Path]:
    stage = _Staging(path)
    try:
        try:
            yield stage.staging
            names = stage.commit()
        except OutputError as exc:
            raise OutputError(stage.shown_path(exc.path), exc.reason) from None
    except BaseException:
        stage.abandon()
        raise
    log.info("wrote %s/{%s}", stage.shown, ",".join(names))


__all__ = ["MANIFEST", "deferred_signals", "output_folder"]
