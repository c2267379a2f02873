"""In-process ``solve`` of two posecrb checkouts side by side: what a solver change gains, file by file.

Each checkout (a directory holding a ``posecrb`` package, e.g. one made by
``git worktree add /tmp/before COMMIT``) runs in its own interpreter with that directory first
on ``sys.path``: ``load(FILE, quaternions="raw")`` once, then ``solve(graph)`` --repeat times,
timed around the call (the in-process column of benchmarks/peers_solve.py). The two checkouts
alternate round by round (--rounds; which one goes first flips every round), and the table shows
the median over every timed call of each side, the median ``optimize`` and ``verify`` phases,
Hessian-vector products, the certificate's Lanczos solves (counted around
``posecrb.solver.staircase._largest_inverse_eig`` where a checkout has it), the staircase rank,
the objectives' relative difference and the difference of the certificates' lambda_min. Every
BLAS pool runs at one thread (--threads), as in the solver. --init vertices starts from the
files' own rotations.

--before-set / --after-set MODULE.NAME=VALUE (repeatable) set a module constant of that side
before it solves (VALUE a Python literal), e.g. to time a threshold: ``--before DIR --after DIR
--after-set posecrb.solver.problem.SIMPLICIAL_MAX_FLOPS_PER_ENTRY=1e9`` with the same DIR twice.

Usage: python benchmarks/solve_checkouts.py --before DIR [--after DIR (default: this checkout)]
           [--before-set M.N=V] [--after-set M.N=V] [--rounds R] [--repeat K] [--threads T]
           [--init chordal|vertices] [--data-dir DIR] [NAME|FILE ...]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

from _common import REPO, child_env, data_dir, print_header, suite_files

CHILD = """
import ast, importlib, json, sys, time
sys.path.insert(0, sys.argv[1])
options = json.loads(sys.argv[2])
for setting in options["settings"]:
    target, value = setting.split("=", 1)
    module, name = target.rsplit(".", 1)
    mod = importlib.import_module(module)
    if not hasattr(mod, name):
        raise SystemExit(f"{module} has no {name}")
    setattr(mod, name, ast.literal_eval(value))
from posecrb.io import load
from posecrb.solver import solve
import posecrb.solver.staircase as staircase
counting = hasattr(staircase, "_largest_inverse_eig")   # the certificate's Lanczos solves
lanczos = [0]
if counting:
    _eig = staircase._largest_inverse_eig

    def _counted(*a, **k):
        res = _eig(*a, **k)
        lanczos[0] += res[2]
        return res
    staircase._largest_inverse_eig = _counted
out = {}
for path in sys.argv[3:]:
    graph = load(path, quaternions="raw")
    runs = []
    for _ in range(options["repeat"]):
        lanczos[0] = 0
        t0 = time.perf_counter()
        res = solve(graph, init=options["init"])
        runs.append((time.perf_counter() - t0, res.times["optimize"], res.times["verify"]))
    out[path] = {"wall": [w for w, _, _ in runs], "optimize": [o for _, o, _ in runs],
                 "verify": [v for _, _, v in runs], "objective": res.objective, "lambda_min": res.lambda_min,
                 "hvps": res.hessian_vector_products, "lanczos": lanczos[0] if counting else None, "rank": res.rank,
                 "certified": res.certified}
print(json.dumps(out))
"""


def run_side(checkout: Path, files: list[Path], repeat: int, threads: int, settings: list[str],
             init: str = "chordal") -> dict:
    env = child_env(threads)
    env.pop("PYTHONPATH", None)     # the child puts its own checkout first
    options = {"repeat": repeat, "init": init, "settings": settings}
    proc = subprocess.run([sys.executable, "-c", CHILD, str(checkout), json.dumps(options), *map(str, files)],
                          env=env, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"{checkout}: solve failed:\n{proc.stderr}")
    return json.loads(proc.stdout)


def _count(value: int | None) -> str:
    return "n/a" if value is None else str(value)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="dataset names or g2o files [default: the SE-Sync files]")
    ap.add_argument("--before", required=True, type=Path, help="checkout directory of the baseline")
    ap.add_argument("--after", type=Path, default=REPO, help="checkout directory [default: this one]")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3, help="timed solves per file and round")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--init", choices=("chordal", "vertices"), default="chordal",
                    help="the solver's initial rotations (files without VERTEX lines need chordal)")
    ap.add_argument("--data-dir", default=None)
    for side in ("before", "after"):
        ap.add_argument(f"--{side}-set", action="append", default=[], metavar="MODULE.NAME=VALUE",
                        help=f"set a module constant of the {side} side (a Python literal); repeatable")
    args = ap.parse_args(argv)
    for setting in args.before_set + args.after_set:
        if "=" not in setting or "." not in setting.split("=", 1)[0]:
            ap.error(f"{setting!r} is not MODULE.NAME=VALUE")
    for side in (args.before, args.after):
        if not (side / "posecrb" / "__init__.py").is_file():
            ap.error(f"{side} is not a posecrb checkout (no posecrb/__init__.py)")
    named = [n for n in args.names if not n.endswith(".g2o")]
    files = [Path(n) for n in args.names if n.endswith(".g2o")]
    files += suite_files(data_dir(args.data_dir), named) if named or not files else []
    if not files:
        ap.error("no dataset files: name them, or set $POSECRB_DATA / --data-dir")
    print_header("in-process solve, two checkouts alternating", threads=args.threads,
                 extra=[f"before = {args.before.resolve()} {' '.join(args.before_set)}".rstrip(),
                        f"after = {args.after.resolve()} {' '.join(args.after_set)}".rstrip(),
                        f"{args.rounds} alternating rounds x {args.repeat} timed solves per file; median of all; "
                        f"init {args.init}"])
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    for k in range(args.rounds):
        # the order flips every round, so a drift of the machine within a round favours neither side
        for side in (("before", "after") if k % 2 == 0 else ("after", "before")):
            runs[side].append(run_side(getattr(args, side), files, args.repeat, args.threads,
                                       getattr(args, f"{side}_set"), args.init))

    def pooled(side: str, key: str, path: str) -> float:
        return statistics.median(v for r in runs[side] for v in r[path][key])

    print(f"{'dataset':24s} {'before s':>9s} {'after s':>8s} {'ratio':>6s} {'optimize before -> after':>26s} "
          f"{'verify before -> after':>24s} {'HVPs':>10s} {'Lanczos':>10s} {'rank':>7s} {'F rel diff':>10s} "
          f"{'lambda_min diff':>15s}")
    total = {"before": 0.0, "after": 0.0}
    for f in files:
        p = str(f)
        b, a = runs["before"][0][p], runs["after"][0][p]
        wb, wa = pooled("before", "wall", p), pooled("after", "wall", p)
        total["before"] += wb
        total["after"] += wa
        rel = abs(a["objective"] - b["objective"]) / max(abs(b["objective"]), 1e-300)
        print(f"{f.stem:24s} {wb:9.3f} {wa:8.3f} {wa / wb:6.2f} "
              f"{pooled('before', 'optimize', p):12.3f} -> {pooled('after', 'optimize', p):9.3f} "
              f"{pooled('before', 'verify', p):11.3f} -> {pooled('after', 'verify', p):8.3f} "
              f"{b['hvps']:>4d} -> {a['hvps']:<4d} {_count(b['lanczos']):>4s} -> {_count(a['lanczos']):<4s} "
              f"{b['rank']:>2d} -> {a['rank']:<2d} {rel:10.1e} {a['lambda_min'] - b['lambda_min']:+15.1e}"
              + ("" if a["certified"] and b["certified"] else "  (not certified)"))
    print(f"{'sum':24s} {total['before']:9.3f} {total['after']:8.3f} {total['after'] / total['before']:6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
