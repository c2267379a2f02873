"""Dataset status and verification against the manifest: found / missing / checksum mismatch for every
manifest entry (list_datasets), and a check of every dataset file on the search path (verify_files).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from ..io import load
from .manifest import DatasetEntry, Manifest, Verification, load_manifest, verify_file
from .search import dataset_files, locate

STATUS_FOUND = "found"


STATUS_MISSING = "missing"


STATUS_MISMATCH = "checksum mismatch"


@dataclass(frozen=True)
class DatasetStatus:
    """One manifest entry and what the search path holds for it."""
    entry: DatasetEntry
    path: Path | None
    status: str                            # found | missing | checksum mismatch
    verification: Verification | None = None

    def row(self) -> dict:
        e = self.entry
        return {
            "name": e.name, "dim": e.dim, "poses": e.poses, "edges": e.edges,
            "table": e.table_label, "paper_name": e.paper_name, "table_number": e.table,
            "paper_order": e.paper_order, "status": self.status,
            "path": str(self.path) if self.path else None, "format": e.format, "file": e.file,
            "checksum": f"{self.verification.algorithm}:{self.verification.expected}" if self.verification
            else "{}:{}".format(*e.checksum),
            "url": e.url,
        }


def dataset_status(entry: DatasetEntry, data_dir: str | os.PathLike | None = None,
                   check: bool = True) -> DatasetStatus:
    """Locate ``entry``; with ``check`` hash the file (sha256 or git blob) against the manifest."""
    path = locate(entry, data_dir)
    if path is None:
        return DatasetStatus(entry, None, STATUS_MISSING)
    if not check:
        return DatasetStatus(entry, path, STATUS_FOUND)
    v = verify_file(entry, path)
    return DatasetStatus(entry, path, STATUS_FOUND if v.ok else STATUS_MISMATCH, v)


def list_datasets(data_dir: str | os.PathLike | None = None, check: bool = True,
                  manifest: Manifest | None = None) -> list[DatasetStatus]:
    """Every manifest entry in manifest order (the paper's Table I, Table II, then the rest)."""
    return [dataset_status(e, data_dir, check) for e in (manifest or load_manifest())]


@dataclass(frozen=True)
class FileCheck:
    """``verify`` result for one file on the search path."""
    path: Path
    entry: DatasetEntry | None
    status: str                     # ok | checksum mismatch | count mismatch | unknown
    algorithm: str | None = None
    expected: str | None = None
    actual: str | None = None
    poses: int | None = None        # parsed counts (only with parse=True)
    edges: int | None = None

    @property
    def failed(self) -> bool:
        return self.status in (STATUS_MISMATCH, "count mismatch")

    def row(self) -> dict:
        return {"name": self.entry.name if self.entry else None, "file": self.path.name,
                "status": self.status, "algorithm": self.algorithm, "expected": self.expected,
                "actual": self.actual, "poses": self.poses, "edges": self.edges, "path": str(self.path)}


def _match_entry(manifest: Manifest, path: Path) -> DatasetEntry | None:
    exact = [e for e in manifest if e.file == path.name]
    if exact:
        return exact[0]
    folded = [e for e in manifest if e.file.lower() == path.name.lower()]
    return folded[0] if folded else None


def verify_files(data_dir: str | os.PathLike | None = None, parse: bool = False,
                 manifest: Manifest | None = None, files: list[Path] | None = None) -> list[FileCheck]:
    """Check every dataset file on the search path (or the given ``files``) against the manifest.

    Files are matched to entries by file name. Files the manifest does not know are
    reported as ``unknown`` (not a failure). ``parse=True`` also loads each matching
    file and compares its pose/edge counts.
    """
    manifest = manifest or load_manifest()
    out: list[FileCheck] = []
    for f in (dataset_files(data_dir) if files is None else [Path(p) for p in files]):
        entry = _match_entry(manifest, f)
        if entry is None:
            out.append(FileCheck(f, None, "unknown"))
            continue
        v = verify_file(entry, f)
        status = "ok" if v.ok else STATUS_MISMATCH
        poses = edges = None
        if parse:

            g = load(f)
            poses, edges = g.n, g.m
            if status == "ok" and (poses, edges) != (entry.poses, entry.edges):
                status = "count mismatch"
        out.append(FileCheck(f, entry, status, v.algorithm, v.expected, v.actual, poses, edges))
    return out
