"""Parser speed: seconds and MB/s per file for posecrb.io.load, against the reference tokeniser.

For every g2o/TORO file in the data directory of at least --min-mb MB (and, unless --no-grid,
the noisy 2D grid of 10^5 poses from benchmarks/grids.py), prints the median over --repeat
runs after a warm-up of:

* ``load``: what every command runs (read, SHA-256, the vectorised tokeniser, decoding and
  checks);
* ``reference``: the same read, hash, decoding and checks with the reference tokeniser
  (posecrb.io.text.split_text, a Python split per line: the reader before the vectorised one,
  and what ``load`` falls back to on input the fast path does not take);

and checks that both give the same graph bit for bit. MB = 10^6 bytes.
Usage: python benchmarks/parse.py [--repeat K] [--min-mb X] [--no-grid] [--data-dir DIR] [NAME ...]
"""
from __future__ import annotations

import argparse
import logging
import os
import platform
from pathlib import Path

import numpy as np
from _common import data_dir, median_time
from grids import grid_file

from posecrb.core.inputs import read_input
from posecrb.datasets import search as datasets
from posecrb.io import FORMATS, load
from posecrb.io.lines import decode_utf8
from posecrb.io.reader import parse
from posecrb.io.text import split_text

ARRAYS = ("ids", "src", "dst", "rot", "trans", "info", "vertex_rot", "vertex_trans", "edge_lines")


def load_reference(path: Path):
    data = read_input(path)
    return parse(split_text(decode_utf8(data.data, data.path)), FORMATS, data.path, data.sha256)


def same_graph(a, b) -> bool:
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        if (x is None) != (y is None):
            return False
        if x is not None and not (x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y)):
            return False
    return a.format == b.format and a.skipped == b.skipped


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="dataset files or names in the data directory")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--min-mb", type=float, default=1.0)
    ap.add_argument("--no-grid", action="store_true")
    ap.add_argument("--data-dir", default=None)
    args = ap.parse_args()
    logging.getLogger("posecrb").setLevel(logging.ERROR)

    files: list[Path] = []
    directory = data_dir(args.data_dir)
    if args.names:
        files = [datasets.resolve(n, directory) for n in args.names]
    elif directory is not None:
        found = sorted(p for p in directory.rglob("*") if p.suffix in (".g2o", ".graph", ".toro") and p.is_file())
        files = [p for p in found if p.stat().st_size >= args.min_mb * 1e6]
    if not args.no_grid:
        files.append(grid_file(2, 10 ** 5))

    print(f"# {platform.machine()} {platform.system()}, {os.cpu_count()} cores, load average "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}; median of {args.repeat} after a warm-up")
    print(f"{'file':38s} {'MB':>6s} {'lines':>8s} {'load s':>8s} {'MB/s':>6s} {'ref s':>8s} {'MB/s':>6s} "
          f"{'speed-up':>8s} same")
    for path in files:
        mb = path.stat().st_size / 1e6
        t_fast = median_time(lambda: load(path), args.repeat)
        t_ref = median_time(lambda: load_reference(path), args.repeat)
        g = load(path)
        same = same_graph(g, load_reference(path))
        lines = read_input(path).data.count(b"\n")
        print(f"{path.name:38s} {mb:6.2f} {lines:8d} {t_fast:8.3f} {mb / t_fast:6.1f} {t_ref:8.3f} "
              f"{mb / t_ref:6.1f} {t_ref / t_fast:7.2f}x {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
