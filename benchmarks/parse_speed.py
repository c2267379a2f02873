"""Reading speed: posecrb.load against converting the same numbers alone, and where the time goes.

For each file (paths or dataset names; default: the 2D grid of 10^5 poses of the suite), prints
the median over --repeat runs after a warm-up, as CPU seconds of this process (the machine is
shared: wall times follow the load) and MB/s:

* ``numbers``: ``np.fromstring`` of the file's numeric fields alone (tags and comment lines removed
  beforehand, untimed): the price of the decimal-to-double conversion by strtod;
* ``load``: ``posecrb.load`` (read, SHA-256, tokenise, convert, decode, check, build the graph);
* ``read``, ``scan``, ``numbers``, ``decode`` and ``graph``: the stages of ``load``;

then ``load`` once in a fresh process after a first load of a small grid (CPU seconds from its
resource usage), where the first touch of every page is paid.
Usage: python benchmarks/parse_speed.py [--repeat K] [FILE_OR_NAME ...]
"""
from __future__ import annotations

import argparse
import logging
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from suite import inputs

import posecrb
from posecrb.core.inputs import read_input
from posecrb.io import FORMATS, reader, text

_NOT_NUMBERS = re.compile(rb"^[ \t]*#.*$|^[ \t]*[A-Za-z][^ \t\n]*", re.M)    # comment lines, tags


def cpu(fn, repeat: int) -> float:
    """Median CPU seconds of ``fn()`` over ``repeat`` runs after one untimed run."""
    fn()
    runs = []
    for _ in range(repeat):
        t = time.process_time()
        fn()
        runs.append(time.process_time() - t)
    return statistics.median(runs)


def stages(path: Path, repeat: int) -> dict[str, float]:
    """Median CPU seconds of each stage of ``load``."""
    inp = read_input(path)
    tokens = text.scan_bytes(inp.data)
    spent = {"numbers": 0.0}
    numeric = tokens.numeric

    def timed_numeric(*args):
        t = time.process_time()
        out = numeric(*args)
        spent["numbers"] += time.process_time() - t
        return out

    timed = text.Tokens(tokens.groups, timed_numeric)
    rows = []
    for _ in range(repeat):
        spent["numbers"] = 0.0
        t = time.process_time()
        reader.parse(timed, FORMATS, str(path), inp.sha256)
        rows.append((spent["numbers"], time.process_time() - t - spent["numbers"]))
    return {"read": cpu(lambda: read_input(path), repeat), "scan": cpu(lambda: text.scan_bytes(inp.data), repeat),
            "numbers": statistics.median(r[0] for r in rows), "decode": statistics.median(r[1] for r in rows)}


def cold(path: Path) -> float:
    """CPU seconds of ``load`` in a fresh process, after the imports and a first load of a small grid."""
    code = ("import resource, sys, posecrb; posecrb.load(sys.argv[2]); r = resource.getrusage(resource.RUSAGE_SELF); "
            "posecrb.load(sys.argv[1]); s = resource.getrusage(resource.RUSAGE_SELF); "
            "print(s.ru_utime - r.ru_utime + s.ru_stime - r.ru_stime)")
    small = inputs.grid_file(2, 64)
    out = subprocess.run([sys.executable, "-c", code, str(path), str(small)], capture_output=True, text=True,
                         check=True, env=inputs.posecrb_env(), cwd=small.parent)   # not a checkout: -c imports from cwd
    return float(out.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", help="files, dataset names or grid names such as grid2d-100000")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    names = args.files or ["grid2d-100000"]
    paths = [Path(n) if Path(n).is_file() else inputs.path(n) for n in names]
    print(f"# {platform.machine()} {platform.system()}, {os.cpu_count()} cores, load average "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}, numpy {np.__version__}, "
          f"max RSS so far {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024} MB; "
          f"CPU s, median of {args.repeat} after a warm-up")
    print(f"{'file':36s} {'MB':>7s} {'numbers':>8s} {'load':>7s} {'MB/s':>6s} {'ratio':>5s} {'read':>6s} "
          f"{'scan':>6s} {'convert':>7s} {'decode':>6s} {'cold':>6s}")
    for path in paths:
        data = path.read_bytes()
        mb = len(data) / 1e6
        blob = _NOT_NUMBERS.sub(b"", data)
        numbers = cpu(lambda: np.fromstring(blob, dtype=np.float64, sep=" "), args.repeat)
        load = cpu(lambda: posecrb.load(path), args.repeat)
        parts = stages(path, args.repeat)
        print(f"{path.name[:36]:36s} {mb:7.2f} {numbers:8.3f} {load:7.3f} {mb / load:6.0f} {load / numbers:5.2f} "
              f"{parts['read']:6.3f} {parts['scan']:6.3f} {parts['numbers']:7.3f} {parts['decode']:6.3f} "
              f"{cold(path):6.3f}")


if __name__ == "__main__":
    main()
