"""Where `posecrb solve FILE` spends its time: cProfile over the whole command, imports included.

Runs, in a fresh interpreter per dataset, ``posecrb.cli.main(["solve", FILE, "--format", "json"])``
under cProfile with the profiler started BEFORE posecrb is imported, and prints the cumulative
time of the stages (imports, parsing, problem set-up, chordal initialisation, trust region with
its Hessian-vector products and preconditioner solves, verification, rounding, output), the
CHOLMOD work inside them, and the functions with the largest own time. scikit-sparse's compiled
calls are invisible to cProfile: CHOLMOD's solves count in the own time of their callers
(Q_product, schur_solve, translations). cProfile's per-call
overhead inflates Python-heavy stages; the wall time of the same command unprofiled is printed
next to it, and the phase times posecrb reports itself.

--cpu times with the process's CPU time instead of the wall clock (time.process_time): on a
machine shared with other jobs their share of the cores then does not count (only meaningful with
one thread, the default).

Usage: python benchmarks/profile_solve.py [--top N] [--sesync-compat] [--threads T] [--cpu] NAME|FILE ...
"""
from __future__ import annotations

import argparse
import json
import pstats
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import child_env, data_dir, posecrb_command, print_header, run_process

DRIVER = """
import cProfile, sys, time
prof = cProfile.Profile(time.process_time) if sys.argv[2] == "cpu" else cProfile.Profile()
prof.enable()
from posecrb.cli import main
code = main(sys.argv[3:])
prof.disable()
prof.dump_stats(sys.argv[1])
"""

# (label, module path suffix, function name); cumulative time of the outermost call.
STAGES = [
    ("imports (all, incl. lazy)", "<frozen importlib._bootstrap>", "_find_and_load"),
    ("parse: io.load", "posecrb/io/reader.py", "load"),
    ("solve total", "posecrb/solver/solve.py", "_solve"),
    ("  Problem.from_graph", "posecrb/solver/problem.py", "from_graph"),
    ("  chordal_rotations", "posecrb/solver/chordal.py", "chordal_rotations"),
    ("  trust_region (all levels)", "posecrb/solver/trust_region.py", "trust_region"),
    ("    tCG", "posecrb/solver/trust_region.py", "_tcg"),
    ("    hvp", "posecrb/solver/staircase.py", "hvp"),
    ("      Q_product", "posecrb/solver/problem.py", "Q_product"),
    ("    precondition", "posecrb/solver/staircase.py", "precondition"),
    ("      schur_solve", "posecrb/solver/problem.py", "schur_solve"),
    ("    prepare (adaptive preconditioner refactor)", "posecrb/solver/staircase.py", "prepare"),
    ("    evaluate (f, gradient, Lambda)", "posecrb/solver/staircase.py", "evaluate"),
    ("    retract", "posecrb/solver/stiefel.py", "retract"),
    ("  nearest_rotations (chordal, rounding)", "posecrb/solver/stiefel.py", "nearest_rotations"),
    ("  verify", "posecrb/solver/staircase.py", "verify"),
    ("    Lanczos (_largest_inverse_eig)", "posecrb/solver/staircase.py", "_largest_inverse_eig"),
    ("  escape", "posecrb/solver/staircase.py", "escape"),
    ("  round_rotations", "posecrb/solver/rounding.py", "round_rotations"),
    ("  recover_translations", "posecrb/solver/rounding.py", "recover_translations"),
    ("factor_full (all: precond, prepare, verify)", "posecrb/solver/problem.py", "factor_full"),
    ("  _full_parts (pattern + symbolic, once)", "posecrb/solver/problem.py", "_full_parts"),
    ("CHOLMOD analyses (linalg.SymbolicCholesky)", "posecrb/linalg/cholesky.py", "__init__"),
    ("CHOLMOD factorizations + log-det checks", "posecrb/linalg/cholesky.py", "factor_logdet"),
    ("sparse mat-vec (csr _matmul_vector/_multivector)", "scipy/sparse/_compressed.py", "_matmul_multivector"),
    ("threadpoolctl controller", "threadpoolctl.py", "__init__"),
    ("rendering (report.print_rows)", "posecrb/report/render.py", "print_rows"),
]


def stage_times(stats: pstats.Stats) -> list[tuple[str, float, int]]:
    out = []
    for label, path, func in STAGES:
        ct, calls = 0.0, 0
        for (fname, _, fn), (_cc, nc, _tt, ctime, _callers) in stats.stats.items():  # type: ignore[attr-defined]
            if fn == func and fname.replace("\\", "/").endswith(path) if path != "~" else fn == func:
                ct += ctime
                calls += nc
        out.append((label, ct, calls))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=["intel", "sphere2500", "cubicle"])
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--sesync-compat", action="store_true")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--cpu", action="store_true", help="profile CPU time (time.process_time), not wall time")
    args = ap.parse_args(argv)
    d = data_dir(args.data_dir)
    env = child_env(args.threads)
    print_header("profile of `posecrb solve` (cProfile, whole command incl. imports)", args.threads)
    for name in args.names:
        path = Path(name) if Path(name).is_file() else (d / f"{name}.g2o" if d else Path(name))
        if not path.is_file():
            print(f"{name}: missing ({path})")
            continue
        cli = ["solve", str(path), "--format", "json"] + (["--sesync-compat"] if args.sesync_compat else [])
        plain = run_process([*posecrb_command(), *cli], env=env)
        js = json.loads(plain.stdout) if plain.ok else {}
        with tempfile.TemporaryDirectory() as tmp:
            prof = Path(tmp) / "solve.prof"
            clock = "cpu" if args.cpu else "wall"
            proc = subprocess.run([sys.executable, "-c", DRIVER, str(prof), clock, *cli], env=env,
                                  capture_output=True, text=True, check=False)
            if not prof.exists():
                print(f"{name}: profiling failed: {proc.stderr.strip()[-300:]}")
                continue
            stats = pstats.Stats(str(prof))
        total = stats.total_tt  # type: ignore[attr-defined]
        t = js.get("times", {})
        print(f"== {path.stem}: {js.get('poses')} poses, {js.get('edges')} edges, rank {js.get('rank')}, "
              f"{js.get('iterations')} TR iterations, {js.get('hessian_vector_products')} HVPs; "
              f"unprofiled whole process {plain.wall:.3f} s; posecrb's own phases: "
              + ", ".join(f"{k} {v:.3f}" for k, v in t.items() if isinstance(v, (int, float))))
        print(f"   profiled total {total:.3f} s ({'CPU' if args.cpu else 'wall'} time)")
        print(f"   {'stage':48s} {'cum s':>8s} {'share':>6s} {'calls':>7s}")
        for label, ct, calls in stage_times(stats):
            if calls:
                print(f"   {label:48s} {ct:8.3f} {ct / total:6.1%} {calls:7d}")
        print("   largest own time (tottime):")
        rows = sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[:args.top]  # type: ignore[attr-defined]
        for (fname, line, fn), (_cc, nc, tt, _ct, _) in rows:
            short = "/".join(Path(fname).parts[-2:]) if fname != "~" else ""
            print(f"   {tt:8.3f} s {nc:7d} calls  {fn} {short}:{line}")
        print(flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
