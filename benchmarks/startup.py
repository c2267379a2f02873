"""Start-up cost of the posecrb command line, whole process, and what its imports spend.

Prints the median whole-process wall time (and peak RSS) of, alternating run by run after one
warm-up of each (benchmarks/_common.py):
  python -c pass                        the interpreter alone (the floor)
  python -c "import numpy"              the floor of anything that reads a file with numpy
  python -c "import numpy, scipy.sparse" the floor of anything that imports scipy.sparse
  posecrb --help
  posecrb --version
  posecrb info FILE                     a small file (default: the smallest g2o in the data dir)
then ``python -X importtime -c "import posecrb.cli"`` once: the total, the largest imports
made directly by posecrb modules (cumulative time, with the posecrb module that imports them),
and the self time summed per top-level package.
Targets: `posecrb --help` <= 0.25 s, `posecrb info` on a small file <= 0.35 s.

Usage: python benchmarks/startup.py [--repeat K] [--file FILE] [--top N] [--posecrb CMD] [--threads T]
"""
from __future__ import annotations

import subprocess
import sys
from collections import defaultdict
from dataclasses import dataclass

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


def importtime_report(cmd_python: str, env: dict, module: str, top: int) -> list[str]:
    proc = subprocess.run([cmd_python, "-X", "importtime", "-c", f"import {module}"], env=env,
                          capture_output=True, text=True, check=False)
    recs = parse_importtime(proc.stderr)
    if not recs:
        return [f"importtime: no report ({proc.stderr.strip()[:200]})"]
    total = next((r.cumulative_us for r in recs if r.name == module), sum(r.self_us for r in recs if r.depth == 0))
    ours = [r for r in recs if r.name.split(".")[0] == "posecrb"]
    direct = [r for r in recs if r.parent and r.parent.split(".")[0] == "posecrb"
              and r.name.split(".")[0] != "posecrb"]
    out = [(f"python -X importtime -c 'import {module}': {total / 1e6:.3f} s in total "
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


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], with_data_dir=True, repeat=7)
    ap.add_argument("--file", default=None, help="file for `posecrb info` [default: smallest g2o in the data dir]")
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args(argv)

    env = child_env(args.threads)
    cmd = posecrb_command(args.posecrb)
    small = args.file
    if small is None:
        d = data_dir(args.data_dir)
        files = sorted(d.glob("*.g2o"), key=lambda p: p.stat().st_size) if d else []
        small = str(files[0]) if files else None
    py = sys.executable
    programs = {
        "python -c pass": [py, "-c", "pass"],
        "python -c 'import numpy'": [py, "-c", "import numpy"],
        "python -c 'import numpy, scipy.sparse'": [py, "-c", "import numpy, scipy.sparse"],
        "posecrb --help": [*cmd, "--help"],
        "posecrb --version": [*cmd, "--version"],
    }
    if small:
        programs[f"posecrb info {small}"] = [*cmd, "info", small]
    print_header("posecrb start-up, whole process", args.threads,
                 [f"posecrb = {' '.join(cmd)}", f"median of {args.repeat} alternating rounds after one warm-up each"])
    runs = alternate({k: (lambda a=a: run_process(a, env=env)) for k, a in programs.items()}, args.repeat)
    width = max(len(k) for k in programs)
    print(f"{'command':{width}s} {'median s':>9s} {'min s':>7s} {'max s':>7s} {'peak RSS':>9s}  status")
    for name, rs in runs.items():
        med = median_run(rs)
        bad = [r.status for r in rs if not r.ok]
        print(f"{name:{width}s} {median_wall(rs):9.3f} {min(r.wall for r in rs):7.3f} "
              f"{max(r.wall for r in rs):7.3f} {fmt_bytes(med.max_rss):>9s}  {bad[0] if bad else 'ok'}")
    print("targets: posecrb --help <= 0.25 s; posecrb info (small file) <= 0.35 s\n")
    for line in importtime_report(py, env, "posecrb.cli", args.top):
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
