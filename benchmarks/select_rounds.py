"""The round greedy against the exact greedy: value, certified ratio and time, side by side.

For each graph (intel and city10000 from the data directory, the scaling benchmark's full-lattice 2D
grids of 10,000, 30,276 and 100,489 poses and its 3D grid of 21,952, benchmarks/grids.py) and each
strategy (``incremental``: the exact greedy; ``rounds``: posecrb.selection.rounds), one fresh process
reads the file and runs ``select_edges(strategy=...)`` at --budget (the tree objective, 20% by
default). Printed per graph and strategy: poses, candidates, K, the strategy ``auto`` takes, the
value, the upper bound, the certified ratio and (rounds) its difference to the exact greedy's, the
selection stage (the result's ``times``), and the whole process's wall and CPU time (its own
rusage). Then the exponents of the round greedy's whole-process wall and CPU time in the number of
candidates over the 2D grids (least squares, benchmarks/_common.fit_exponent). The exact greedy takes
minutes on the largest grids: --exact-up-to N runs it only up to N poses (0: never).

Usage: python benchmarks/select_rounds.py [--budget B] [--exact-up-to N] [--no-grids] [--data-dir DIR]
       [--threads T] [NAME ...]
"""
from __future__ import annotations

import json
import sys

from _common import child_env, data_dir, fit_exponent, print_header, process_parser, run_process, suite_files
from grids import grid_file

from posecrb.selection.greedy import pick_strategy

DEFAULT = ("intel", "city10000")
GRIDS = ((2, 10_000), (2, 30_276), (2, 100_489), (3, 21_952))

# The timed program: read the file and select, nothing else; its own CPU time at the end.
CHILD = r"""
import json, resource, sys
from posecrb import load
from posecrb.selection import select_edges
graph = load(sys.argv[1])
res = select_edges(graph, sys.argv[2], strategy=sys.argv[3]).to_dict()
use = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"poses": graph.n, "candidates": res["candidates"], "k": res["budget"], "value": res["value"],
                  "upper_bound": res["upper_bound"], "ratio": res["certified_ratio"],
                  "select": res["times"]["select"], "strategy": res["stats"].get("strategy"),
                  "cpu": use.ru_utime + use.ru_stime}))
"""


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], with_data_dir=True)
    ap.add_argument("--budget", default="20%", help="the selection's budget [default: 20%%]")
    ap.add_argument("--exact-up-to", type=int, default=40_000,
                    help="run the exact greedy only on graphs of at most this many poses [default: 40000]")
    ap.add_argument("--no-grids", action="store_true", help="only the named datasets, no grid")
    ap.add_argument("names", nargs="*", help=f"datasets [default: {' '.join(DEFAULT)}]")
    args = ap.parse_args(argv)
    graphs = [(path, 0) for path in suite_files(data_dir(args.data_dir), args.names or DEFAULT)]
    if not args.no_grids:
        graphs += [(grid_file(dim, poses), poses) for dim, poses in GRIDS]
    env = child_env(args.threads)
    print_header("the round greedy against the exact greedy, whole process (benchmarks/select_rounds.py)",
                 args.threads)
    print(f"tree objective, greedy at --budget {args.budget}; one run per graph and strategy")
    print()
    print("| graph | poses | candidates | K | auto | strategy | value | upper bound | certified ratio | "
          "ratio - exact's | select s | wall s | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    scaling: list[tuple[int, float, float]] = []
    for path, poses in graphs:
        exact_ratio = None
        for strategy in ("incremental", "rounds"):
            if strategy == "incremental" and poses > args.exact_up_to:
                continue
            run = run_process([sys.executable, "-c", CHILD, str(path), args.budget, strategy], env=env)
            if not run.ok:
                print(f"| {path.stem} | failed ({strategy}): {(run.stderr.strip().splitlines() or [run.status])[-1]} "
                      "||||||||||||", flush=True)
                break
            out = json.loads(run.stdout.strip().splitlines()[-1])
            auto = pick_strategy("auto", "auto", out["k"], out["poses"])
            delta = "" if exact_ratio is None or strategy != "rounds" else f"{out['ratio'] - exact_ratio:+.4f}"
            if strategy == "incremental":
                exact_ratio = out["ratio"]
            print(f"| {path.stem} | {out['poses']} | {out['candidates']} | {out['k']} | {auto} | {strategy} | "
                  f"{out['value']:.2f} | {out['upper_bound']:.2f} | {out['ratio']:.4f} | {delta} | "
                  f"{out['select']:.2f} | {run.wall:.2f} | {out['cpu']:.2f} |", flush=True)
            if strategy == "rounds" and path.stem.startswith("grid2d"):
                scaling.append((out["candidates"], run.wall, out["cpu"]))
    if len(scaling) >= 2:
        cand, wall, cpu = zip(*scaling)
        print(f"\nround greedy on the 2D grids: whole-process time ~ candidates^{fit_exponent(cand, wall):.2f} (wall), "
              f"^{fit_exponent(cand, cpu):.2f} (CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
