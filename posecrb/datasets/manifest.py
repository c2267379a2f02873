"""The dataset manifest (docs/design.md#datasets): what each third-party file is and how to check it.

The single source of truth is ``posecrb/data/manifest.toml`` (package data, so it is
found after ``pip install``); ``datasets/manifest.toml`` in the repository is a
relative symlink to it. Each entry carries the expected counts, the HTTPS URL at a
pinned commit, and a checksum: ``sha256`` of the bytes where the file was available
when the manifest was written, otherwise only the ``git_blob`` id
(``sha1(b"blob <size>\\0" + bytes)``, what ``git hash-object`` prints).
"""
from __future__ import annotations

import hashlib
import os
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path

from ..core.errors import PosecrbError

_CHUNK = 1 << 20


class ManifestError(PosecrbError):
    """The manifest file itself is malformed (a packaging bug, reported as exit 1)."""


@dataclass(frozen=True)
class DatasetEntry:
    name: str
    file: str
    format: str                      # "g2o" | "toro"
    dim: int
    poses: int
    edges: int
    url: str
    subdir: str = ""                 # layout under a data directory ("" or "toro")
    sha256: str | None = None
    git_blob: str | None = None
    size: int | None = None
    has_vertices: bool | None = None
    repo: str | None = None
    commit: str | None = None
    table: int | None = None         # 1 = Table I (2D), 2 = Table II (3D) of the paper
    paper_name: str | None = None
    paper_order: int | None = None
    note: str = ""

    @property
    def relpath(self) -> str:
        """Path under a data directory (TORO files in toro/)."""
        return f"{self.subdir}/{self.file}" if self.subdir else self.file

    @property
    def checksum(self) -> tuple[str, str]:
        """(algorithm, expected hex digest) used to verify this file: sha256 if known, else git blob."""
        if self.sha256:
            return "sha256", self.sha256
        return "git_blob", self.git_blob  # type: ignore[return-value]  # _validate guarantees one

    @property
    def table_label(self) -> str | None:
        return {1: "I", 2: "II"}.get(self.table) if self.table else None


@dataclass(frozen=True)
class Manifest:
    entries: tuple[DatasetEntry, ...]
    path: str
    version: int = 1
    _index: dict[str, DatasetEntry] = field(default_factory=dict, repr=False, compare=False)

    def __iter__(self) -> Iterator[DatasetEntry]:
        return iter(self.entries)

    def __len__(self) -> int:
        return len(self.entries)

    def names(self) -> list[str]:
        return [e.name for e in self.entries]

    def find(self, key: str) -> DatasetEntry | None:
        """Entry for a name, file name, file stem or paper name; exact match first, then case-insensitive."""
        key = os.path.basename(str(key))
        for k in (key, key.lower()):
            if k in self._index:
                return self._index[k]
        return None

    def get(self, key: str) -> DatasetEntry:
        entry = self.find(key)
        if entry is None:
            raise PosecrbError(f"{key!r} is not in the dataset manifest; known: {', '.join(self.names())}")
        return entry

    def paper(self, table: int | None = None) -> list[DatasetEntry]:
        """The paper's datasets in the order of its tables (Table I, then Table II)."""
        rows = [e for e in self.entries if e.table is not None and (table is None or e.table == table)]
        return sorted(rows, key=lambda e: (e.table, e.paper_order))


_REQUIRED = ("name", "file", "format", "dim", "poses", "edges", "url")
_FIELDS = set(DatasetEntry.__dataclass_fields__)


def _validate(raw: dict, where: str) -> DatasetEntry:
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        raise ManifestError(f"{where}: missing field(s) {', '.join(missing)}")
    unknown = set(raw) - _FIELDS
    if unknown:
        raise ManifestError(f"{where}: unknown field(s) {', '.join(sorted(unknown))}")
    entry = DatasetEntry(**raw)
    if entry.format not in ("g2o", "toro") or entry.dim not in (2, 3):
        raise ManifestError(f"{where}: format must be g2o|toro and dim 2|3")
    if not entry.url.startswith("https://"):
        # The manifest is what users download from: plain HTTP would defeat nothing (the
        # checksum still guards the bytes) but would leak what they fetch; keep it HTTPS.
        raise ManifestError(f"{where}: url must be https://, got {entry.url!r}")
    for what, value in (("file", entry.file), ("subdir", entry.subdir)):
        # a path from the manifest is joined to the user's directories: it must stay inside them
        parts = value.replace("\\", "/").split("/")
        if ("\0" in value or value.startswith(("/", "\\")) or (len(value) > 1 and value[1] == ":")
                or any(p in (".", "..") for p in parts) or (what == "file" and (len(parts) != 1 or not value))
                or (what == "subdir" and value and "" in parts)):
            raise ManifestError(f"{where}: {what} {value!r} must be a plain relative name (no '..', no absolute "
                                "path, no separator in a file name): it would leave the data directory")
    if not (entry.sha256 or entry.git_blob):
        raise ManifestError(f"{where}: needs sha256 or git_blob")
    if entry.table is not None and (entry.paper_name is None or entry.paper_order is None):
        raise ManifestError(f"{where}: table membership needs paper_name and paper_order")
    return entry


def default_manifest_path() -> Path:
    return Path(str(resources.files("posecrb") / "data" / "manifest.toml"))


def parse_manifest(text: str, path: str = "<manifest>") -> Manifest:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ManifestError(f"{path}: {exc}") from None
    entries = tuple(_validate(raw, f"{path}: dataset #{k + 1} ({raw.get('name', '?')})")
                    for k, raw in enumerate(data.get("dataset", [])))
    index: dict[str, DatasetEntry] = {}
    # Exact keys shadow case-folded ones, names shadow files, files shadow paper names,
    # so `csail` finds CSAIL.g2o while `csail.toro` still finds the TORO copy.
    for attr in ("name", "file", "stem", "paper_name"):
        for e in entries:
            value = e.file.rsplit(".", 1)[0] if attr == "stem" else getattr(e, attr)
            if value is None:
                continue
            for k in (value, value.lower()):
                index.setdefault(k, e)
    dup = {e.name for e in entries if sum(x.name == e.name for x in entries) > 1}
    if dup:
        raise ManifestError(f"{path}: duplicate dataset name(s) {', '.join(sorted(dup))}")
    return Manifest(entries=entries, path=path, version=int(data.get("version", 1)), _index=index)


@lru_cache(maxsize=4)
def _load_cached(path: str, mtime: float) -> Manifest:
    return parse_manifest(Path(path).read_text(encoding="utf-8"), path)


def load_manifest(path: str | os.PathLike | None = None) -> Manifest:
    """The packaged manifest, or the TOML file at ``path``."""
    p = Path(path) if path is not None else default_manifest_path()
    try:
        return _load_cached(str(p), p.stat().st_mtime)
    except OSError as exc:
        raise ManifestError(f"cannot read dataset manifest {p}: {exc.strerror or exc}") from None


# ---- checksums ---------------------------------------------------------------

def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def git_blob_file(path: str | os.PathLike) -> str:
    """Git's blob id of a file: sha1 over ``b"blob <size>\\0"`` followed by the bytes."""
    size = os.path.getsize(path)
    h = hashlib.sha1(b"blob %d\0" % size)
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


_HASHERS = {"sha256": sha256_file, "git_blob": git_blob_file}


@dataclass(frozen=True)
class Verification:
    entry: DatasetEntry
    path: str
    algorithm: str
    expected: str
    actual: str

    @property
    def ok(self) -> bool:
        return self.actual == self.expected


def verify_file(entry: DatasetEntry, path: str | os.PathLike) -> Verification:
    """Hash ``path`` with the entry's checksum algorithm and compare."""
    algo, expected = entry.checksum
    return Verification(entry, os.fspath(path), algo, expected, _HASHERS[algo](path))
