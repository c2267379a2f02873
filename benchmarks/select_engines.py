"""The log-det greedy's two update engines as whole processes: where numba's start-up is worth it.

``select_edges(..., engine=...)`` with ``path`` (posecrb.linalg.pathchol's compiled kernels: numba's
import and first call, 0.7-0.9 s in a fresh process, then cheap path solves) and ``cholmod``
(whole-factor CHOLMOD solves and updates, numpy for the rest: nothing to load, each step a solve
with the whole factor), each in a fresh interpreter that imports posecrb, reads the file and selects
(the tree objective's greedy at --budget, 20% of the loop closures by default), alternating after
one warm-up of each (benchmarks/_common.py). Printed per dataset (the sizes from one more, untimed
process): the blocks' rows, candidates, K, the entries of M^{-1} U that
``posecrb.selection.greedy.pick_engine`` counts (its limit CHOLMOD_ENGINE_ENTRIES), the engine
``auto`` takes, the median whole-process wall time of each engine, whether the two chose the same
edges, and whether numba was loaded.

Usage: python benchmarks/select_engines.py [--repeat K] [--budget B] [--data-dir DIR] [--threads T] [NAME ...]
"""
from __future__ import annotations

import json
import sys

from _common import alternate, child_env, data_dir, median_run, print_header, process_parser, run_process, suite_files

from posecrb.selection.greedy import CHOLMOD_ENGINE_ENTRIES

DEFAULT = ("CSAIL", "MIT", "intel", "kitti_05", "kitti_00", "manhattan", "city10000", "smallGrid3D",
           "parking-garage", "sphere2500", "torus3D")

# The timed program: read the file and select, nothing else.
CHILD = r"""
import json, sys
from posecrb import load
from posecrb.selection import select_edges
res = select_edges(load(sys.argv[1]), sys.argv[2], engine=sys.argv[3])
print(json.dumps({"selected": res.selected_edges.tolist(), "numba": "numba" in sys.modules}))
"""
# Untimed, once per dataset: the sizes pick_engine sees and its choice.
SIZES = r"""
import json, sys
from posecrb import load
from posecrb.selection import split_edges, tree_objective
from posecrb.selection.budget import parse_budget
from posecrb.selection.greedy import pick_engine
graph = load(sys.argv[1])
obj = tree_objective(graph)
cand = int(split_edges(graph).candidates.size)
k = parse_budget(sys.argv[2], cand)
print(json.dumps({"rows": [b.size for b in obj.blocks], "candidates": cand, "k": k,
                  "entries": sum(b.size * b.U.shape[2] for b in obj.blocks) * (cand + k),
                  "auto": pick_engine("auto", obj, cand, k)}))
"""


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], with_data_dir=True, repeat=5)
    ap.add_argument("--budget", default="20%", help="the selection's budget [default: 20%%]")
    ap.add_argument("names", nargs="*", help=f"datasets [default: {' '.join(DEFAULT)}]")
    args = ap.parse_args(argv)
    files = suite_files(data_dir(args.data_dir), args.names or DEFAULT)
    if not files:
        ap.error("no data directory: give --data-dir or set POSECRB_DATA")
    env = child_env(args.threads)
    print_header("the log-det greedy's update engines, whole process (benchmarks/select_engines.py)", args.threads)
    print(f"tree objective, greedy at --budget {args.budget}; median of {args.repeat} alternating runs per engine")
    print()
    print("| dataset | block rows | candidates | K | entries | auto | path s | cholmod s | same edges | "
          "numba (path, cholmod) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in files:
        def engine(name: str, p=path):
            return lambda: run_process([sys.executable, "-c", CHILD, str(p), args.budget, name], env=env)

        runs = alternate({"path": engine("path"), "cholmod": engine("cholmod")}, args.repeat)
        med = {name: median_run(r) for name, r in runs.items()}
        if not all(r.ok for r in med.values()):
            bad = next(r for r in med.values() if not r.ok)
            print(f"| {path.stem} | failed: {(bad.stderr.strip().splitlines() or [bad.status])[-1]} |||||||||")
            continue
        out = {name: json.loads(r.stdout.strip().splitlines()[-1]) for name, r in med.items()}
        p, c = out["path"], out["cholmod"]
        sz = run_process([sys.executable, "-c", SIZES, str(path), args.budget], env=env)
        if not sz.ok:
            print(f"| {path.stem} | failed: {(sz.stderr.strip().splitlines() or [sz.status])[-1]} |||||||||")
            continue
        z = json.loads(sz.stdout.strip().splitlines()[-1])
        print(f"| {path.stem} | {' + '.join(map(str, z['rows']))} | {z['candidates']} | {z['k']} | "
              f"{z['entries'] / 1e6:.1f}M | {z['auto']} | {med['path'].wall:.3f} | {med['cholmod'].wall:.3f} | "
              f"{'yes' if p['selected'] == c['selected'] else 'NO'} | {p['numba']}, {c['numba']} |", flush=True)
    print(f"\nauto: cholmod up to {CHOLMOD_ENGINE_ENTRIES / 1e6:.0f}M entries (CHOLMOD_ENGINE_ENTRIES)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
