"""An experiment's ``--out`` directory: its rows as CSV and JSON, extra tables, and ``run.json``.

Every file is written atomically (``posecrb.core.outputs``) into a folder swapped in whole
(``posecrb.core.folders``); the run record follows the one schema
of ``posecrb.core.provenance.run_record`` (docs/design.md#run-record).
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.outputs import make_output_dir, write_text
from ..core.provenance import write_run_record
from .render import to_csv, to_json


def write_experiment_outputs(out_dir: str | os.PathLike, rows: Sequence[dict[str, Any]], record: Mapping[str, Any],
                             extra: Mapping[str, Sequence[dict[str, Any]]] | None = None) -> list[Path]:
    """``rows.csv``, ``rows.json``, ``<name>.csv`` for every ``extra`` table, then ``run.json``.

    ``record`` comes from ``run_record``; the names of the files written are added to its
    ``results["files"]``. ``out_dir`` is the folder being written by
    ``posecrb.core.folders.output_folder`` (which swaps it in whole, with the figure drawn into it,
    and says what it wrote). Returns the paths written."""
    d = make_output_dir(out_dir)
    written = [write_text(d / "rows.csv", to_csv(list(rows))),
               write_text(d / "rows.json", to_json(list(rows), single=False) + "\n")]
    for name, data in (extra or {}).items():
        written.append(write_text(d / f"{name}.csv", to_csv(list(data))))
    rec = {**record, "results": {**record.get("results", {}), "files": [p.name for p in written] + ["run.json"]}}
    written.append(write_run_record(d, rec))
    return written
