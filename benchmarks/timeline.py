"""The information timeline against one `bounds` of the whole graph, whole process, side by side.

For each graph, alternating run by run after one warm-up of each (benchmarks/_common.py):
  posecrb timeline FILE --estimate none      every step, graph only (lb, ub, t_opt_graph)
  posecrb bounds FILE --estimate none --repeat 1
both in their default output (the timeline's summary table; every step is computed all the same);
``--format json``: both print JSON, the timeline every row and loop closure (about 0.1 s more on
city10000)
and the ratio of the medians (target: at most 3), of the wall times and of the CPU times (user +
system of the process): on a loaded machine the wall times also measure the other programs, the
CPU times much less. Each program's stdout is read and
dropped by the benchmark, as the bounds output is. Also printed: the timeline's own in-process wall
time (``times.timeline``), its checkpoints (factorizations from scratch) and the largest drift found
at one, and the load average before and after.

Graphs: city10000 (2D), sphere2500 (3D) and the 2D grid of 10^5 poses of benchmarks/grids.py
(317^2 = 100,489 poses, generated and cached on first use) unless named on the command line.
``--chain N`` runs a noisy 2D chain of N poses instead (benchmarks/grids.py, cached; with any FILE
named): ``--chain 2000000``
is the case where the drift tolerance must follow the rounding of sums of millions of terms
(docs/design.md#timeline); use ``--repeat 1`` there.

Usage: python benchmarks/timeline.py [--repeat K] [--format json|table] [--data-dir DIR] [--posecrb CMD]
                                     [--threads T] [--chain N] [FILE ...]
"""
from __future__ import annotations

import json
import os
import statistics
import sys
from pathlib import Path

from _common import (
    alternate,
    child_env,
    data_dir,
    median_run,
    median_wall,
    posecrb_command,
    print_header,
    process_parser,
    run_process,
)
from grids import chain_file, grid_file

TARGET = 3.0


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], with_data_dir=True, repeat=5)
    ap.add_argument("files", nargs="*", help="g2o files [default: city10000, sphere2500, the 2D 100k grid]")
    ap.add_argument("--format", default="table", choices=("json", "table"),
                    help="output format of both commands: table (their default; the timeline's summary) or "
                         "json (every row and loop closure) [default: table]")
    ap.add_argument("--chain", type=int, action="append", default=[], metavar="N",
                    help="a noisy 2D chain of N poses, instead of the default graphs (repeatable)")
    args = ap.parse_args(argv)
    env = child_env(args.threads)
    cmd = posecrb_command(args.posecrb)
    if args.files or args.chain:
        files = [Path(f) for f in args.files]
    else:
        d = data_dir(args.data_dir)
        files = [p for p in ((d / "city10000.g2o") if d else None, (d / "sphere2500.g2o") if d else None) if p]
        files.append(grid_file(2, 100000))
    files += [chain_file(n) for n in args.chain]
    print_header("posecrb timeline (every step, --estimate none) vs one bounds --estimate none --repeat 1, "
                 "whole process", args.threads,
                 [f"posecrb = {' '.join(cmd)}", f"median of {args.repeat} alternating rounds after one warm-up each"])
    print(f"{'graph':22s} {'timeline s':>10s} {'bounds s':>9s} {'ratio':>6s} {'CPU s':>11s} {'CPU ratio':>9s} "
          f"{'in-process s':>12s} {'checkpoints':>11s} {'max drift':>9s}  load before -> after")
    worst = 0.0
    for f in files:
        if not f.is_file():
            print(f"{f.name:28s} not found")
            continue
        fmt = [] if args.format == "table" else ["--format", "json"]
        progs = {
            "timeline": lambda f=f: run_process([*cmd, "timeline", str(f), "--estimate", "none", *fmt], env=env),
            "bounds": lambda f=f: run_process([*cmd, "bounds", str(f), "--estimate", "none", "--repeat", "1", *fmt],
                                              env=env),
        }
        before = _load()
        runs = alternate(progs, args.repeat)
        after = _load()
        bad = [r.status for rs in runs.values() for r in rs if not r.ok]
        if bad:
            err = next(r.stderr for rs in runs.values() for r in rs if not r.ok)
            print(f"{f.name:28s} failed: {bad[0]}: {err[:300]}")
            continue
        tl, bd = median_wall(runs["timeline"]), median_wall(runs["bounds"])
        tc, bc = (statistics.median(r.cpu for r in runs[k]) for k in ("timeline", "bounds"))
        # the timeline's own figures: from its JSON (one more run when the table was measured)
        out = json.loads(median_run(runs["timeline"]).stdout if fmt else run_process(
            [*cmd, "timeline", str(f), "--estimate", "none", "--format", "json"], env=env).stdout)
        checks = out["checks"]
        cps = max(c["checkpoints"] for c in checks.values())
        drift = max(c["max_drift"] for c in checks.values())
        ratio = tl / bd
        worst = max(worst, ratio)
        print(f"{f.stem:22s} {tl:10.3f} {bd:9.3f} {ratio:6.2f} {tc:5.2f}/{bc:5.2f} {tc / bc:9.2f} "
              f"{out['times']['timeline']:12.3f} {cps:11d} {drift:9.2g}  {before} -> {after}", flush=True)
    print(f"\ntarget: timeline / bounds <= {TARGET:g} (wall); worst wall ratio {worst:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
