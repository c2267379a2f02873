"""Run the whole benchmark suite, or all of it once on small inputs (--quick), then the report.

1. The in-process suite (asv, benchmarks/asv.conf.json) in this interpreter's environment: the
   full run files its results under the checkout's commit (``.bench/asv/results``); ``--quick``
   runs every benchmark once and keeps nothing (asv's ``--quick``), so that a broken benchmark
   fails.
2. The whole-process comparisons (hyperfine): benchmarks/commands.py and every script of
   benchmarks/peers/, each skipping what is absent (hyperfine, a peer) with its reason.
3. benchmarks/report.py on what the two wrote.

Exit status 1 when a step fails. ``make bench`` and ``make bench-quick`` run this; the test suite
runs ``--quick`` (tests/benchmarks/test_benchmarks.py), so CI fails on a broken benchmark.
--bench REGEX runs only the asv benchmarks it matches (and the report).
Usage: python benchmarks/run.py [--quick] [--out DIR] [--bench REGEX]
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
REPO = BENCHMARKS.parent
SCRIPTS = ("commands.py", "peers/sesync_solve.py", "peers/gtsam_marginals.py", "peers/mac_select.py")


def step(title: str, argv: list[str], env: dict[str, str]) -> bool:
    print(f"bench: {title}: {' '.join(argv)}", file=sys.stderr, flush=True)
    start = time.perf_counter()
    ok = subprocess.run(argv, env=env, cwd=REPO, check=False).returncode == 0
    print(f"bench: {title}: {'ok' if ok else 'FAILED'} ({time.perf_counter() - start:.0f} s)", file=sys.stderr)
    return ok


def asv_argv(quick: bool, bench: str | None, config: Path = BENCHMARKS / "asv.conf.json") -> list[str]:
    """``asv run`` in this interpreter's environment: every benchmark once (``quick``), or filed under
    the checkout's commit."""
    argv = [sys.executable, "-m", "asv", "--config", str(config), "run", "--show-stderr",
            "--environment", f"existing:{sys.executable}"]
    if quick:
        argv.append("--quick")
    else:
        commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=True).stdout.strip()
        argv += ["--set-commit-hash", commit]
    return argv + (["--bench", bench] if bench else [])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="every benchmark once, on small inputs")
    ap.add_argument("--out", default=None, help="directory of the whole-process results and the report "
                                                "[default: .bench, --quick: .bench/quick]")
    ap.add_argument("--bench", default=None, help="only the asv benchmarks matching this regular expression "
                                                  "(no whole-process comparison)")
    args = ap.parse_args(argv)
    out = Path(args.out or REPO / ".bench" / ("quick" if args.quick else ""))
    if importlib.util.find_spec("asv") is None:
        print("bench: asv is not installed in this interpreter (the dev extra: pip install -e '.[dev]')",
              file=sys.stderr)
        return 1
    # asv drops PYTHONPATH; ASV_PYTHONPATH puts this checkout first for the benchmarks it runs.
    env = {**os.environ, "POSECRB_BENCH": "quick" if args.quick else "full", "ASV_PYTHONPATH": str(REPO)}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), *[p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]])
    asv = [sys.executable, "-m", "asv", "--config", str(BENCHMARKS / "asv.conf.json")]
    subprocess.run([*asv, "machine", "--yes"], env=env, cwd=REPO, check=False, stdout=subprocess.DEVNULL)
    ok = step("in-process suite (asv)", asv_argv(args.quick, args.bench), env)
    hyperfine_out = out / "hyperfine"
    for script in SCRIPTS if args.bench is None else ():
        ok &= step(script, [sys.executable, str(BENCHMARKS / script), "--out", str(hyperfine_out),
                            *(["--quick"] if args.quick else [])], env)
    results = REPO / ".bench" / "asv" / "results"
    ok &= step("report", [sys.executable, str(BENCHMARKS / "report.py"), "--asv", str(results), "--hyperfine",
                          str(hyperfine_out), "--out", str(out / "report")], env)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
