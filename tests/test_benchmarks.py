"""The benchmark scripts' own code paths that no measurement run exercises in CI."""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _module(name: str):
    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    return importlib.import_module(name)


def test_scaling_plot_and_markdown_write_from_records(tmp_path):
    scaling = _module("scaling")
    records = [{"dim": d, "poses": n, "edges": 2 * n, "command": c, "wall": 0.01 * n ** 1.1, "rss": 1e5 * n,
                "status": "ok", "phases": "parse 0.01", "inprocess": 0.01 * n}
               for d in (2, 3) for n in (100, 1000, 10000) for c in ("solve", "fim")]
    out = tmp_path / "scaling.png"
    scaling.plot(records, str(out))
    assert out.stat().st_size > 1000
    table = scaling.markdown(records, "")
    assert table.count("\n| 3 | 10,000 |") == 2
