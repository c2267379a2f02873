"""What produced a result: package versions, the machine, and the ``run.json`` record.

One schema for every ``run.json`` posecrb writes (``tables --out``, ``experiment ... --out``),
built by ``run_record`` and documented in docs/design.md#run-record.
"""
from __future__ import annotations

import json
import os
import platform
import shlex
import sys
import time
from collections.abc import Mapping, Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from .._version import __version__
from .outputs import write_text

_DISTRIBUTIONS = ("numpy", "scipy", "pandas", "scikit-sparse", "numba", "click", "rich", "matplotlib",
                  "dask", "distributed")

RUN_RECORD_SCHEMA = 1   # bumped when a key of the run record changes meaning


def versions() -> dict[str, str]:
    """posecrb, Python and every installed dependency that can change a number or a timing."""
    out = {"posecrb": __version__, "python": sys.version.split()[0]}
    for dist in _DISTRIBUTIONS:
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            pass
    return out


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform()}


def dataset_entry(path: str | os.PathLike | None, sha256: str | None, status: str | None = None) -> dict:
    """One entry of a run record's ``datasets``: the file read and its sha256 (and the row's status)."""
    entry: dict[str, Any] = {"path": None if path is None else os.fspath(path), "sha256": sha256}
    if status is not None:
        entry["status"] = status
    return entry


def run_record(experiment: str, *, settings: Mapping[str, Any], seeds: Any,
               datasets: Mapping[str, Mapping[str, Any]] | None = None,
               results: Mapping[str, Any] | None = None, elapsed_seconds: float | None = None,
               argv: Sequence[str] | None = None) -> dict:
    """The ``run.json`` record (docs/design.md#run-record): enough to reproduce and diff a run.

    ``experiment``: what ran (``"tables"``, ``"crlb"``, ``"thesis"``, ``"octagon"``, ``"sparsify"``);
    ``settings``: every option that can change a number; ``seeds``: how to rebuild every random
    stream; ``datasets``: name -> ``dataset_entry`` (path, sha256[, status]); ``results``: summary
    numbers and the files written next to the record. ``argv`` defaults to ``sys.argv``.
    """
    args = list(sys.argv if argv is None else argv)
    return {
        "schema": RUN_RECORD_SCHEMA,
        "experiment": experiment,
        "command": shlex.join(["posecrb", *args[1:]]),
        "argv": args,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "elapsed_seconds": elapsed_seconds,
        "versions": {**versions(), "platform": platform.platform()},
        "machine": machine(),
        "settings": dict(settings),
        "seeds": seeds,
        "datasets": {name: dict(entry) for name, entry in (datasets or {}).items()},
        "results": dict(results or {}),
    }


def write_run_record(directory: str | os.PathLike, record: Mapping[str, Any]) -> Path:
    """``directory/run.json``, written atomically; values JSON does not know are written as text."""
    return write_text(Path(directory) / "run.json", json.dumps(record, indent=2, default=str) + "\n")
