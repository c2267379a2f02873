"""Start-up cost of the posecrb command line, whole process, and what its imports spend.

Prints the median whole-process wall time (and peak RSS) of, alternating run by run after one
warm-up of each (benchmarks/_common.py), every program run by this interpreter directly (no
pyenv/virtualenv shim in front):
  python -c pass                                     the interpreter alone
  python -c "import numpy"                           the floor of anything that reads a file (info)
  python -c "import numpy, scipy.sparse, sksparse.cholmod"
                                                     the floor of solve: what it genuinely needs
  ... deferred                                       the same after the CLI's deferral of numpy modules
                                                     it never uses (numpy.f2py, numpy.testing, ...), which
                                                     scipy's array-API layer would otherwise import
  posecrb --help
  posecrb --version
  posecrb info FILE                                  a small file (default CSAIL, else the smallest g2o)
  posecrb solve SMALL3D --format json                default tinyGrid3D
  posecrb solve FILE --format json                   default CSAIL
For the solve runs also the in-process work (the JSON's times.total: parse + solve) and what
is left, the start-up. Then ``python -X importtime -m posecrb solve FILE --format json`` once:
the total, the largest imports made directly by posecrb modules (cumulative time, with the
posecrb module that imports them), and the self time summed per top-level package.
Targets: `posecrb --help` <= 0.25 s, `posecrb info` on a small file <= 0.35 s; solve as close as
possible to its floor.

Usage: python benchmarks/startup.py [--repeat K] [--file FILE] [--file3d FILE] [--top N] [--posecrb CMD]
                                    [--threads T] [--no-importtime]
"""
from __future__ import annotations

import json
import subprocess
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from _common import (
    alternate,
    child_env,
    data_dir,
    fmt_bytes,
    median_run,
    median_wall,
    posecrb_command,
    print_header,
    process_parser,
    run_process,
)


@dataclass
class ImportRecord:
    name: str
    self_us: int
    cumulative_us: int
    depth: int
    parent: str | None = None


def parse_importtime(stderr: str) -> list[ImportRecord]:
    """Records of ``-X importtime`` with each module's importer (its enclosing, shallower line).

    The report is post-order: a module's own line comes after the lines of everything it
    imported, which are indented one level deeper."""
    records: list[ImportRecord] = []
    pending: dict[int, list[ImportRecord]] = defaultdict(list)
    for line in stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        self_s, cum_s, name = line[len("import time:"):].split("|", 2)
        try:
            self_us, cum_us = int(self_s), int(cum_s)
        except ValueError:
            continue  # the header line
        stripped = name.lstrip()
        depth = (len(name) - len(stripped) - 1) // 2
        rec = ImportRecord(stripped.rstrip(), self_us, cum_us, depth)
        for child in pending.pop(depth + 1, []):
            child.parent = rec.name
        pending[depth].append(rec)
        records.append(rec)
    return records


def importtime_report(cmd_python: str, env: dict, args: list[str], top: int) -> list[str]:
    """``python -X importtime ARGS`` once (e.g. ``-m posecrb solve FILE``): where the imports go."""
    proc = subprocess.run([cmd_python, "-X", "importtime", *args], env=env,
                          capture_output=True, text=True, check=False)
    recs = parse_importtime(proc.stderr)
    if not recs:
        return [f"importtime: no report ({proc.stderr.strip()[:200]})"]
    total = sum(r.cumulative_us for r in recs if r.depth == 0)
    ours = [r for r in recs if r.name.split(".")[0] == "posecrb"]
    direct = [r for r in recs if r.parent and r.parent.split(".")[0] == "posecrb"
              and r.name.split(".")[0] != "posecrb"]
    out = [(f"python -X importtime {' '.join(args)}: {total / 1e6:.3f} s of imports in total "
            f"({len(recs)} modules, one run)"), "",
           "largest imports made by posecrb modules (cumulative; a module already imported costs 0 later):",
           f"  {'seconds':>8s}  {'module':34s} imported by"]
    for r in sorted(direct, key=lambda r: -r.cumulative_us)[:top]:
        out.append(f"  {r.cumulative_us / 1e6:8.3f}  {r.name:34s} {r.parent}")
    per_pkg: dict[str, int] = defaultdict(int)
    for r in recs:
        per_pkg[r.name.split(".")[0]] += r.self_us
    out += ["", "self time per top-level package:", f"  {'seconds':>8s}  package"]
    for pkg, us in sorted(per_pkg.items(), key=lambda kv: -kv[1])[:top]:
        out.append(f"  {us / 1e6:8.3f}  {pkg}")
    out += ["", "posecrb modules (cumulative includes what they import first):",
            f"  {'cumul. s':>8s}  {'self s':>7s}  module"]
    for r in sorted(ours, key=lambda r: -r.cumulative_us)[:top]:
        out.append(f"  {r.cumulative_us / 1e6:8.3f}  {r.self_us / 1e6:7.3f}  {r.name}")
    return out


def _default_file(directory, name: str, smallest: bool) -> str | None:
    """``name``.g2o in the data directory, else (``smallest``) its smallest g2o file."""
    if directory is None:
        return None
    if (directory / f"{name}.g2o").is_file():
        return str(directory / f"{name}.g2o")
    files = sorted(directory.glob("*.g2o"), key=lambda p: p.stat().st_size) if smallest else []
    return str(files[0]) if files else None


def _in_process_total(run) -> float | None:
    """times.total of a ``solve --format json`` run (parse + solve, measured inside the process)."""
    try:
        return float(json.loads(run.stdout)["times"]["total"])
    except (ValueError, KeyError, TypeError):
        return None


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], with_data_dir=True, repeat=7)
    ap.add_argument("--file", default=None, help="file for `posecrb info` and `solve` [default: CSAIL.g2o in the "
                                                 "data dir, else its smallest g2o]")
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--file3d", default=None, help="small 3D file for `solve` [default: tinyGrid3D.g2o]")
    ap.add_argument("--no-importtime", action="store_true", help="skip the -X importtime report")
    args = ap.parse_args(argv)

    env = child_env(args.threads)
    cmd = posecrb_command(args.posecrb)
    d = data_dir(args.data_dir)
    small = args.file or _default_file(d, "CSAIL", smallest=True)
    small3d = args.file3d or _default_file(d, "tinyGrid3D", smallest=False)
    py = sys.executable
    floor = "numpy, scipy.sparse, sksparse.cholmod"
    programs = {
        "python -c pass": [py, "-c", "pass"],
        "python -c 'import numpy'": [py, "-c", "import numpy"],
        f"python -c 'import {floor}'": [py, "-c", f"import {floor}"],
        f"python -c 'import {floor}' deferred": [
            py, "-c",
            f"from posecrb.cli.lazy_numpy import defer_unused_imports; defer_unused_imports(); import {floor}"],
        "posecrb --help": [*cmd, "--help"],
        "posecrb --version": [*cmd, "--version"],
    }
    solves = []
    if small:
        programs[f"posecrb info {Path(small).name}"] = [*cmd, "info", small]
    for f in (small3d, small):
        if f:
            key = f"posecrb solve {Path(f).name} --format json"
            programs[key] = [*cmd, "solve", f, "--format", "json"]
            solves.append(key)
    print_header("posecrb start-up, whole process", args.threads,
                 [f"posecrb = {' '.join(cmd)} (the interpreter itself, no shim)",
                  f"median of {args.repeat} alternating rounds after one warm-up each"])
    runs = alternate({k: (lambda a=a: run_process(a, env=env)) for k, a in programs.items()}, args.repeat)
    width = max(len(k) for k in programs)
    print(f"{'command':{width}s} {'median s':>9s} {'min s':>7s} {'max s':>7s} {'peak RSS':>9s}  status")
    for name, rs in runs.items():
        med = median_run(rs)
        bad = [r.status for r in rs if not r.ok]
        print(f"{name:{width}s} {median_wall(rs):9.3f} {min(r.wall for r in rs):7.3f} "
              f"{max(r.wall for r in rs):7.3f} {fmt_bytes(med.max_rss):>9s}  {bad[0] if bad else 'ok'}")
    print("targets: posecrb --help <= 0.25 s; posecrb info (small file) <= 0.35 s; solve near its floor\n")
    floor_wall = median_wall(runs[f"python -c 'import {floor}'"])
    if solves:
        print("solve: whole process = in-process work (times.total, median) + start-up and exit")
        print(f"{'command':{width}s} {'whole s':>8s} {'work s':>7s} {'rest s':>7s} {'floor s':>8s} {'over floor':>10s}")
        for name in solves:
            rs = runs[name]
            works = sorted(w for w in (_in_process_total(r) for r in rs) if w is not None)
            work = works[(len(works) - 1) // 2] if works else float("nan")
            whole = median_wall(rs)
            print(f"{name:{width}s} {whole:8.3f} {work:7.3f} {whole - work:7.3f} {floor_wall:8.3f} "
                  f"{whole - work - floor_wall:10.3f}")
        print()
    if not args.no_importtime:
        target = ["-m", "posecrb", "solve", small, "--format", "json"] if small else ["-m", "posecrb", "--help"]
        for line in importtime_report(py, env, target, args.top):
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
