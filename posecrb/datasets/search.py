"""Dataset lookup: a bare name resolves through the search path of docs/design.md#datasets.

Search path, first hit wins: ``--data-dir``, ``$POSECRB_DATA`` (one or more directories,
``os.pathsep``-separated; an entry that is not an existing directory is an error, never silently
skipped), ``./datasets``, the user cache ``~/.cache/posecrb``. Each directory is searched together
with its ``toro/`` subfolder; a name without extension also finds its gzip-compressed file
(``intel`` -> ``intel.g2o.gz``), read transparently.

A bare name that resolves to a file of the manifest is checked against the manifest's checksum:
a copy that does not match (an edited or corrupted file found before the verified one) is
reported with a warning naming the verified copy, or is an error under ``strict_checksums``
(``posecrb --strict``).

The second half ties the search path to the manifest (``posecrb.datasets.manifest``):
``locate`` an entry's file, ``list_datasets`` (found / missing / checksum mismatch)
and ``verify_files`` (every file on the path against its entry). ``resolve`` falls
back on the manifest's names and the paper's names (``garage``, ``KITTI``) only
when the plain file search fails.
"""
from __future__ import annotations

import contextlib
import logging
import os
import shlex
from collections.abc import Iterator
from contextvars import ContextVar
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

from ..core.errors import DatasetNotFound, ParseError, PosecrbError, UsageError
from ..core.inputs import checked_name, path_kind, unresolvable

if TYPE_CHECKING:
    from .manifest import DatasetEntry, Manifest

EXTENSIONS = (".g2o", ".graph", ".toro")
COMPRESSED = ".gz"            # a dataset file may be gzip-compressed (read transparently)

log = logging.getLogger("posecrb")

_STRICT: ContextVar[bool] = ContextVar("posecrb_strict_checksums", default=False)


class ChecksumMismatch(PosecrbError):
    """A dataset name resolved to a file that does not match the manifest's checksum (``--strict``)."""


@contextlib.contextmanager
def strict_checksums(strict: bool = True) -> Iterator[None]:
    """While active, a bare name resolving to a file that fails the manifest checksum raises
    ``ChecksumMismatch`` instead of warning (``posecrb --strict``)."""
    token = _STRICT.set(strict)
    try:
        yield
    finally:
        _STRICT.reset(token)


def _is_dataset_file(name: str) -> bool:
    low = name.lower()
    return low.endswith(EXTENSIONS) or low.endswith(tuple(e + COMPRESSED for e in EXTENSIONS))


def env_data_dirs() -> list[Path]:
    """The directories of ``$POSECRB_DATA``; UsageError (exit 2) for an entry that is not an
    existing directory (a file, a typo, a directory not created yet): silently skipping it would
    make names resolve elsewhere, or not at all, without saying why."""
    env = os.environ.get("POSECRB_DATA")
    out: list[Path] = []
    for p in (env.split(os.pathsep) if env else []):
        if not p:
            continue
        if not os.path.isdir(p):
            if os.path.lexists(p):
                try:
                    kind = path_kind(os.stat(p))
                except OSError as exc:
                    kind = unresolvable(exc)      # a dangling link, a symbolic link loop, ...
                what = f"is {kind}, not a directory"
            else:
                what = "does not exist"
            raise UsageError(f"$POSECRB_DATA entry {p} {what}; set POSECRB_DATA to existing directories "
                             f"separated by {os.pathsep!r}")
        out.append(Path(p))
    return out


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "posecrb"


def search_path(data_dir: str | os.PathLike | None = None) -> list[Path]:
    dirs: list[Path] = []
    if data_dir:
        dirs.append(Path(checked_name(data_dir)))
    dirs += env_data_dirs()
    dirs.append(Path("datasets"))
    dirs.append(cache_dir())
    out: list[Path] = []
    for d in dirs:
        for sub in (d, d / "toro"):
            if sub not in out:
                out.append(sub)
    return out


def _resolve_on_path(name_or_path: str | os.PathLike, data_dir: str | os.PathLike | None = None) -> Path:
    """An existing path is returned as is; a bare name (with or without extension) is searched."""
    name = checked_name(name_or_path)        # ParseError for '' and NUL, never a raw ValueError
    p = Path(name)
    if p.is_file():
        return p
    if os.sep in name or (os.altsep and os.altsep in name):

        _not_regular(name)
        raise ParseError(name, None, "no such file")
    candidates = ([name] if _is_dataset_file(name) else
                  [name + ext for ext in EXTENSIONS] + [name + ext + COMPRESSED for ext in EXTENSIONS])
    dirs = search_path(data_dir)
    for d in dirs:
        if not d.is_dir():
            continue
        for c in candidates:
            f = d / c
            if f.is_file():
                return f
        # case-insensitive match (users type `csail` for CSAIL.g2o)
        lowered = {c.lower() for c in candidates}
        for f in sorted(d.iterdir()):
            if f.is_file() and f.name.lower() in lowered:
                return f
    raise DatasetNotFound(name, [str(d) for d in dirs if d.is_dir()])


def _is_name(name_or_path: str | os.PathLike) -> bool:
    """A bare name (looked up on the search path), not a path the user typed."""
    text = os.fspath(name_or_path)
    return not (os.sep in text or (os.altsep and os.altsep in text) or os.path.isfile(text))


def _not_regular(name: str | os.PathLike) -> None:
    """ParseError saying what ``name`` is when it exists but is not a regular file (a
    directory, FIFO or device is never read as a dataset nor reported as missing)."""
    try:
        st = os.stat(name)
    except OSError:
        return

    raise ParseError(str(name), None, f"is {path_kind(st)}, not a regular file")


# ---- the manifest on the search path -------------------------------------------
# Everything below extends the lookup above with the manifest (posecrb.datasets.manifest):
# which paper/shared datasets are present, where, and whether their bytes are the
# published ones.


def locate(entry: DatasetEntry, data_dir: str | os.PathLike | None = None) -> Path | None:
    """First file named ``entry.file`` on the search path (each directory and its ``toro/``), or None."""
    for d in search_path(data_dir):
        f = d / entry.file
        if f.is_file():
            return f
    return None


def resolve(name_or_path: str | os.PathLike, data_dir: str | os.PathLike | None = None,
            manifest: Manifest | None = None) -> Path:
    """An existing path is returned as is; a bare name (with or without extension) is searched.

    Only when that search fails, the manifest's aliases are tried: dataset names
    (``csail-toro``) and the paper's names (``garage``, ``KITTI``, ``sphere``) map to
    their files on the search path. Raises DatasetNotFound (with the fetch hint).
    """
    found = locate_input(name_or_path, data_dir, manifest)
    if _is_name(name_or_path):
        _check_manifest_copy(found, data_dir, manifest)
    return found


def locate_input(name_or_path: str | os.PathLike, data_dir: str | os.PathLike | None = None,
                 manifest: Manifest | None = None) -> Path:
    """``resolve`` without the manifest checksum check (which file a name stands for)."""
    try:
        return _resolve_on_path(name_or_path, data_dir)
    except DatasetNotFound as exc:
        from .manifest import load_manifest  # noqa: PLC0415 -- start-up: a path argument never needs the manifest

        entry = (manifest or load_manifest()).find(str(name_or_path))
        found = locate(entry, data_dir) if entry is not None else None
        if found is None:
            _not_regular(name_or_path)
            if entry is None:                # `datasets fetch` would not know the name either
                raise DatasetNotFound(exc.name, exc.searched, _not_fetchable(exc.name)) from None
            if entry.name != str(name_or_path):
                raise DatasetNotFound(entry.name, exc.searched) from None
            raise
        return found


def _not_fetchable(name: str) -> str:
    """What to do about a name that is neither on the search path nor in the manifest."""
    if "," in name:
        return ("give one dataset per argument: a comma does not separate names "
                f"({' '.join(shlex.quote(n.strip()) for n in name.split(',') if n.strip())})")
    return "see `posecrb datasets list` for the datasets posecrb can fetch"


@lru_cache(maxsize=64)
def _verifies(path: str, size: int, mtime_ns: int, algorithm: str, expected: str) -> tuple[bool, str]:
    from .manifest import _HASHERS  # noqa: PLC0415 -- hashing only for manifest names

    actual = _HASHERS[algorithm](path)
    return actual == expected, actual


def verifies(entry: DatasetEntry, path: str | os.PathLike) -> tuple[bool, str]:
    """(whether ``path`` matches ``entry``'s checksum, its digest); cached by size and mtime."""
    st = os.stat(path)
    algo, expected = entry.checksum
    return _verifies(os.fspath(Path(path).resolve()), st.st_size, st.st_mtime_ns, algo, expected)


def _check_manifest_copy(found: Path, data_dir: str | os.PathLike | None, manifest: Manifest | None) -> None:
    """Warn (``strict_checksums``: raise) when a name resolved to a manifest file whose bytes are
    not the manifest's, naming the verified copy when the search path has one."""
    from .manifest import load_manifest  # noqa: PLC0415 -- start-up: a path argument never needs the manifest

    man = manifest or load_manifest()
    entry = next((e for e in man if e.file == found.name), None) or \
        next((e for e in man if e.file.lower() == found.name.lower()), None)
    if entry is None:
        return
    ok, actual = verifies(entry, found)
    if ok:
        return
    algo, expected = entry.checksum
    others = [f for f in _copies(entry, data_dir) if not f.samefile(found) and verifies(entry, f)[0]]
    where = (f"the verified copy is {others[0]} (pass that path, or put its directory first with --data-dir)"
             if others else f"no verified copy on the search path: `posecrb datasets fetch {shlex.quote(entry.name)} "
                            "--dest DIR` downloads one")
    message = (f"{found} does not match the manifest's {algo} of {entry.name} (expected {expected[:16]}..., "
               f"got {actual[:16]}...): an edited or corrupted copy; {where}")
    if _STRICT.get():
        raise ChecksumMismatch(message + " (--strict)")
    log.warning("%s", message)


def _copies(entry: DatasetEntry, data_dir: str | os.PathLike | None) -> list[Path]:
    """Every file named ``entry.file`` on the search path, in search order."""
    out: list[Path] = []
    for d in search_path(data_dir):
        f = d / entry.file
        if f.is_file() and not any(f.samefile(o) for o in out):
            out.append(f)
    return out


def dataset_files(data_dir: str | os.PathLike | None = None, *, first_per_name: bool = False) -> list[Path]:
    """Every dataset file in every search directory, in search order, each file once; with
    ``first_per_name`` only the first hit of each name (what a bare name resolves to)."""
    seen: set[object] = set()
    out: list[Path] = []
    for d in search_path(data_dir):
        if not d.is_dir():
            continue
        for f in sorted(d.iterdir()):
            if f.is_file() and _is_dataset_file(f.name):
                key = f.name.lower().removesuffix(COMPRESSED).rsplit(".", 1)[0] if first_per_name else f.resolve()
                if key not in seen:
                    seen.add(key)
                    out.append(f)
    return out


