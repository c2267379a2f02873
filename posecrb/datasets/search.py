"""Dataset lookup: a bare name resolves through the search path of docs/design.md#datasets.

Search path, first hit wins: ``--data-dir``, ``$POSECRB_DATA`` (one or more directories,
``os.pathsep``-separated), ``./datasets``, the user cache ``~/.cache/posecrb``.
Each directory is searched together with its ``toro/`` subfolder.

The second half ties the search path to the manifest (``posecrb.datasets.manifest``):
``locate`` an entry's file, ``list_datasets`` (found / missing / checksum mismatch)
and ``verify_files`` (every file on the path against its entry). ``resolve`` falls
back on the manifest's names and the paper's names (``garage``, ``KITTI``) only
when the plain file search fails.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from ..core.errors import DatasetNotFound, ParseError
from ..core.files import path_kind

if TYPE_CHECKING:
    from .manifest import DatasetEntry, Manifest

EXTENSIONS = (".g2o", ".graph", ".toro")


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "posecrb"


def search_path(data_dir: str | os.PathLike | None = None) -> list[Path]:
    dirs: list[Path] = []
    if data_dir:
        dirs.append(Path(data_dir))
    env = os.environ.get("POSECRB_DATA")
    if env:
        dirs += [Path(p) for p in env.split(os.pathsep) if p]
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
    p = Path(name_or_path)
    if p.is_file():
        return p
    name = str(name_or_path)
    if os.sep in name or (os.altsep and os.altsep in name):

        _not_regular(name)
        raise ParseError(name, None, "no such file")
    candidates = [name] if name.endswith(EXTENSIONS) else [name + ext for ext in EXTENSIONS]
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
    try:
        return _resolve_on_path(name_or_path, data_dir)
    except DatasetNotFound as exc:
        from .manifest import load_manifest  # noqa: PLC0415 -- start-up: a path argument never needs the manifest

        entry = (manifest or load_manifest()).find(str(name_or_path))
        found = locate(entry, data_dir) if entry is not None else None
        if found is None:
            _not_regular(name_or_path)
            if entry is not None and entry.name != str(name_or_path):
                raise DatasetNotFound(entry.name, exc.searched) from None
            raise
        return found


def dataset_files(data_dir: str | os.PathLike | None = None, *, first_per_name: bool = False) -> list[Path]:
    """Every dataset file in every search directory, in search order, each file once; with
    ``first_per_name`` only the first hit of each name (what a bare name resolves to)."""
    seen: set[object] = set()
    out: list[Path] = []
    for d in search_path(data_dir):
        if not d.is_dir():
            continue
        for f in sorted(d.iterdir()):
            if f.is_file() and f.suffix in EXTENSIONS:
                key = f.stem.lower() if first_per_name else f.resolve()
                if key not in seen:
                    seen.add(key)
                    out.append(f)
    return out


