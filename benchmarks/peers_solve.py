"""posecrb solve vs SE-Sync C++, whole process vs whole process, on the SE-Sync g2o files.

For every g2o file of the data directory (the 16 of SE-Sync's suite, or the NAMEs given), runs
SE-Sync's example executable ($SESYNC_BIN, see benchmarks/_peers.py) and `posecrb solve FILE
--format json` alternately run by run: one untimed warm-up of each, then K rounds (order flipped
every round), and prints per dataset the median wall times, their ratio, the peak RSS of each
process, both objectives (SE-Sync prints 6 significant digits) and whether they agree within that
print plus 2e-6 relative, SE-Sync's status and posecrb's certificate, and posecrb's own
in-process time (parse + solve, from its JSON) so that the fixed start-up cost shows.

By default posecrb reads 3D quaternions as SE-Sync does (--sesync-compat: same data, same
objective); --no-sesync-compat times posecrb's default normalised reading instead. Both programs
use every core (both link the system BLAS; --threads T caps every OpenMP / BLAS pool of both at
T). Without $SESYNC_BIN the SE-Sync columns are skipped with a message and posecrb runs alone.

The import floor is measured in the same run: the median whole-process time of `python -c
"import numpy, scipy.sparse, sksparse.cholmod"` (what `solve` cannot avoid loading), 5 runs.

Goals: the sum over the 16 files <= 0.8 x SE-Sync's sum; every file where SE-Sync needs
>= 0.5 s no slower than SE-Sync; the others within SE-Sync + the import floor + 0.1 s.

Usage: python benchmarks/peers_solve.py [--pairs K] [--data-dir DIR] [--posecrb CMD]
                                        [--threads T] [--no-sesync-compat] [NAME ...]
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys

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
    suite_files,
)
from _peers import objectives_agree, parse_sesync, run_sesync, sesync_binary, sesync_build_info


def posecrb_json(stdout: str) -> dict:
    try:
        return json.loads(stdout)
    except json.JSONDecodeError:
        return {}


def goal(t_sesync: float, t_ours: float, floor: float) -> str:
    if not (math.isfinite(t_sesync) and math.isfinite(t_ours)):
        return "-"
    if t_sesync >= 0.5:
        return "met" if t_ours <= t_sesync else "MISSED"
    return "met" if t_ours <= t_sesync + floor + 0.1 else "MISSED"


IMPORT_FLOOR = "import numpy, scipy.sparse, sksparse.cholmod"


def import_floor(env: dict, runs: int = 5) -> float:
    """Median whole-process time of the imports `solve` needs (one warm-up first)."""
    argv = [sys.executable, "-c", IMPORT_FLOOR]
    run_process(argv, env=env)
    return statistics.median(run_process(argv, env=env).wall for _ in range(runs))


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], with_data_dir=True, threads=0)
    ap.add_argument("names", nargs="*")
    ap.add_argument("--pairs", type=int, default=3, help="timed rounds per dataset (median) [default: 3]")
    ap.add_argument("--sesync-compat", action=argparse.BooleanOptionalAction, default=True,
                    help="posecrb reads 3D quaternions as SE-Sync does [default: on]")
    ap.add_argument("--timeout", type=float, default=900.0, help="kill a run after this many seconds")
    args = ap.parse_args(argv)

    files = suite_files(data_dir(args.data_dir), args.names)
    if not files:
        print("skipped: no data directory with g2o files (--data-dir or $POSECRB_DATA)")
        return 0
    binary, why = sesync_binary()
    env = child_env(args.threads or None)
    floor = import_floor(env)
    cmd = posecrb_command(args.posecrb)
    extra = ["--sesync-compat"] if args.sesync_compat else []
    print_header("posecrb solve vs SE-Sync C++, whole process", args.threads or None, [
        f"posecrb = {' '.join(cmd)} solve FILE --format json {' '.join(extra)}".rstrip(),
        f"SE-Sync = {binary} FILE; built: {sesync_build_info(binary)}" if binary else f"SE-Sync skipped: {why}",
        f"median of {args.pairs} alternating pairs after one warm-up each; ratio = posecrb / SE-Sync",
        f"import floor (python -c '{IMPORT_FLOOR}'): {floor:.3f} s, median of 5",
    ])
    hdr = (f"{'dataset':24s} {'dim':>3s} {'poses':>6s} {'edges':>6s} {'SE-Sync s':>9s} {'posecrb s':>9s} "
           f"{'ratio':>6s} {'in-proc':>7s} {'RSS SES':>8s} {'RSS pcrb':>8s} {'F SE-Sync':>12s} "
           f"{'F posecrb':>16s} {'rel diff':>9s} {'agree':>5s} {'SES status':>14s} {'cert':>4s} {'goal':>6s}")
    print(hdr)
    print("-" * len(hdr))
    tot_s = tot_p = 0.0
    n_ok = n_agree = n_goal = n_rows = 0
    all_cert = True
    for path in files:
        if not path.is_file():
            print(f"{path.stem:24s} missing: {path}")
            continue
        programs = {"posecrb": lambda p=path: run_process([*cmd, "solve", str(p), "--format", "json", *extra],
                                                         env=env, timeout=args.timeout)}
        if binary:
            programs["SE-Sync"] = lambda p=path: run_sesync(binary, p, env, timeout=args.timeout)
        runs = alternate(programs, args.pairs)
        pr = median_run(runs["posecrb"])
        t_p = median_wall(runs["posecrb"])
        js = posecrb_json(pr.stdout)
        f_p = float(js.get("objective", float("nan")))
        cert = bool(js.get("certified", False))
        all_cert &= cert
        times = js.get("times", {})
        inproc = (times.get("parse") or 0.0) + (times.get("total") or 0.0) if times else float("nan")
        dim = js.get("dim", "?")
        poses, edges = js.get("poses", -1), js.get("edges", -1)
        if binary:
            sr = median_run(runs["SE-Sync"])
            t_s = median_wall(runs["SE-Sync"])
            out = parse_sesync(sr.stdout)
            f_s = out.objective
            agree = objectives_agree(f_p, f_s)
            rel = (f_p - f_s) / abs(f_s) if f_s else float("nan")
            status = out.status if sr.ok else sr.status
            g = goal(t_s, t_p, floor)
            tot_s += t_s
            tot_p += t_p
            n_agree += agree
            n_goal += g == "met"
            s_cols = (f"{t_s:9.3f} {t_p:9.3f} {t_p / t_s:6.2f} {inproc:7.3f} {fmt_bytes(sr.max_rss):>8s} "
                      f"{fmt_bytes(pr.max_rss):>8s} {f_s:12.6g} {f_p:16.10g} {rel:9.1e} "
                      f"{'yes' if agree else 'NO':>5s} {status:>14s} {'yes' if cert else 'NO':>4s} {g:>6s}")
        else:
            tot_p += t_p
            s_cols = (f"{'-':>9s} {t_p:9.3f} {'-':>6s} {inproc:7.3f} {'-':>8s} {fmt_bytes(pr.max_rss):>8s} "
                      f"{'-':>12s} {f_p:16.10g} {'-':>9s} {'-':>5s} {'-':>14s} {'yes' if cert else 'NO':>4s} {'-':>6s}")
        n_rows += 1
        n_ok += pr.returncode in (0, 1) and bool(js)
        print(f"{path.stem:24s} {dim!s:>3s} {poses:6d} {edges:6d} {s_cols}", flush=True)
    print("-" * len(hdr))
    if binary and n_rows:
        print(f"sum of medians: SE-Sync {tot_s:.2f} s, posecrb {tot_p:.2f} s, ratio {tot_p / tot_s:.2f} "
              f"(goal <= 0.80); per-dataset goal met on {n_goal}/{n_rows}; objectives agree on {n_agree}/{n_rows}; "
              f"posecrb certified on all: {all_cert}")
    else:
        print(f"sum of posecrb medians: {tot_p:.2f} s over {n_rows} files; certified on all: {all_cert}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
