"""Scaling on noisy grids: whole-process time and peak memory against the number of poses.

Grids (benchmarks/grids.py: full lattices, noise 0.05, seed 0): 2D 10^4 and 10^5 poses
(10^6 with --huge), 3D 2*10^3 and 2*10^4 (10^5 with --huge). For each grid, runs
  bounds none      posecrb bounds FILE --estimate none --repeat 1      (graph-only bounds)
  bounds vertices  posecrb bounds FILE --estimate vertices --repeat 1  (+ FIM log-det at the vertices)
  fim              posecrb fim FILE --estimate vertices                (FIM build + log-det)
  crlb             posecrb crlb FILE --estimate vertices               (trace by selected inversion)
  solve            posecrb solve FILE                                  (certified optimum)
  SE-Sync          $SESYNC_BIN FILE                                    (when set, benchmarks/_peers.py)
each as one whole process (--repeat K: median of K alternating rounds after a warm-up), and prints
wall time, peak RSS, the in-process phase times each program reports, and per command the fitted
exponent of time (and memory) against poses. `--repeat 1` is passed to bounds so that it computes
once (its own default repeats for its timing columns).

A run is skipped when the fit over the smaller grids (exponent 1.5 from a single point) predicts
more than --budget seconds or --max-mem GB (--no-predict: never); a run exceeding 2x the budget or
the memory cap is killed. From a single point, crlb's memory is extrapolated with the growth of the
nonzeros of a nested-dissection Cholesky factor (n log n in 2D, taken as n^1.1; n^(4/3) in 3D):
the selected inversion works in place on a copy of the factor's values, so its memory follows them.

Goals: 2D 10^5 solve <= 15 s and <= 1.5 GB; 3D 2.2*10^4 solve <= 20 s and FIM log-det <= 3 s;
bounds --estimate none exponent <= 1.2 up to 10^6 2D poses within 24 GB.

Usage: python benchmarks/scaling.py [--dims 2,3] [--huge] [--sizes2 N,N] [--sizes3 N,N]
          [--commands bounds-none,bounds-vertices,fim,crlb,solve,sesync] [--budget S] [--max-mem GB]
          [--repeat K] [--threads T] [--posecrb CMD] [--cache-dir DIR]
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from _common import (
    alternate,
    child_env,
    fit_exponent,
    fmt_bytes,
    median_run,
    median_wall,
    posecrb_command,
    print_header,
    process_parser,
    run_process,
)
from _peers import parse_sesync, run_sesync, sesync_binary, sesync_build_info
from grids import DEFAULT_SIGMA, grid_poses

SIZES = {2: [10_000, 100_000], 3: [2_000, 20_000]}
HUGE = {2: [1_000_000], 3: [100_000]}
COMMANDS = ["bounds-none", "bounds-vertices", "fim", "crlb", "solve", "sesync"]
DEFAULT_EXPONENT = 1.5
# Single-point memory exponents where the default would mislead (module docstring): crlb holds the
# factor (CHOLMOD's copy and its own), whose nonzeros grow as n log n (2D) and n^(4/3) (3D).
MEMORY_EXPONENT = {(2, "crlb"): 1.1, (3, "crlb"): 4 / 3}


def posecrb_args(command: str, path: Path) -> list[str]:
    f = str(path)
    return {
        "bounds-none": ["bounds", f, "--estimate", "none", "--repeat", "1", "--format", "json"],
        "bounds-vertices": ["bounds", f, "--estimate", "vertices", "--repeat", "1", "--format", "json"],
        "fim": ["fim", f, "--estimate", "vertices", "--format", "json"],
        "crlb": ["crlb", f, "--estimate", "vertices", "--format", "json"],
        "solve": ["solve", f, "--format", "json"],
    }[command]


def phases(command: str, stdout: str) -> tuple[str, float]:
    """The in-process times the program reports about itself, and their sum."""
    if command == "sesync":
        out = parse_sesync(stdout)
        return ((f"init {out.init_time:.2f}, total {out.reported_total:.2f} (excl. reading), "
                 f"{'optimum' if out.certified else out.status}"), out.reported_total)
    try:
        js = json.loads(stdout)
    except json.JSONDecodeError:
        return "", float("nan")
    t = js.get("times", {})
    keys = {"bounds-none": ["parse", "laplacians", "lb", "ub", "ub_lambda"],
            "bounds-vertices": ["parse", "lb", "ub", "fim_build", "fim_logdet"],
            "fim": ["parse", "fim_build", "fim_logdet"],
            "crlb": ["parse", "fim_build", "crlb_blocks", "curvature"],
            "solve": ["parse", "init", "optimize", "verify", "round"]}[command]
    vals = {k: t[k] for k in keys if isinstance(t.get(k), (int, float))}
    text = ", ".join(f"{k} {v:.2f}" for k, v in vals.items())
    if command == "solve":
        text += f", {'certified' if js.get('certified') else 'NOT certified'} r={js.get('rank')}"
    return text, sum(vals.values())


def predict(history: list[tuple[int, float]], n: int, single: float = DEFAULT_EXPONENT) -> float:
    """Extrapolate (poses, value) pairs to n poses with their log-log fit (exponent >= 1; from a
    single point, exponent ``single``)."""
    if not history:
        return 0.0
    e = fit_exponent([h[0] for h in history], [h[1] for h in history]) if len(history) > 1 else single
    e = max(1.0, e if math.isfinite(e) else DEFAULT_EXPONENT)
    n0, v0 = history[-1]
    return v0 * (n / n0) ** e


def make_grid(dim: int, poses: int, cache_dir: str | None) -> Path:
    """Generated in a child process, so this process stays small while the others are measured."""
    cmd = [sys.executable, str(Path(__file__).with_name("grids.py")), str(dim), str(poses),
           "--sigma", str(DEFAULT_SIGMA)]
    if cache_dir:
        cmd += ["--cache-dir", cache_dir]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    return Path(out.split("  (")[0].strip())


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], repeat=1)
    ap.add_argument("--dims", default="2,3")
    ap.add_argument("--huge", action="store_true", help="add 10^6 (2D) and 10^5 (3D) poses")
    ap.add_argument("--sizes2", default=None, help="comma-separated 2D pose counts (overrides the defaults)")
    ap.add_argument("--sizes3", default=None, help="comma-separated 3D pose counts (overrides the defaults)")
    ap.add_argument("--commands", default=",".join(COMMANDS))
    ap.add_argument("--budget", type=float, default=300.0, help="seconds; skip runs predicted to take longer")
    ap.add_argument("--max-mem", type=float, default=8.0, help="GB; skip runs predicted to need more, kill above")
    ap.add_argument("--no-predict", action="store_true",
                    help="run every size (still killed above 2x the budget or the memory cap)")
    ap.add_argument("--cache-dir", default=None)
    args = ap.parse_args(argv)

    dims = [int(d) for d in args.dims.split(",")]
    sizes = {d: list(SIZES[d]) + (HUGE[d] if args.huge else []) for d in dims}
    for d, spec in ((2, args.sizes2), (3, args.sizes3)):
        if spec and d in sizes:
            sizes[d] = [int(x) for x in spec.split(",")]
    commands = [c for c in args.commands.split(",") if c]
    unknown = set(commands) - set(COMMANDS)
    if unknown:
        ap.error(f"unknown commands {sorted(unknown)}; choose from {COMMANDS}")
    binary, why = sesync_binary()
    if "sesync" in commands and binary is None:
        commands.remove("sesync")
    env = child_env(args.threads)
    cmd = posecrb_command(args.posecrb)
    max_rss = args.max_mem * 1e9
    print_header("posecrb scaling on noisy grids, whole process", args.threads, [
        f"posecrb = {' '.join(cmd)}; grids: benchmarks/grids.py, sigma {DEFAULT_SIGMA}, seed 0, full lattices",
        (f"SE-Sync = {binary}; built: {sesync_build_info(binary)}" if binary else f"SE-Sync skipped: {why}"),
        (f"{'one run each' if args.repeat == 1 else f'median of {args.repeat} alternating rounds after a warm-up'}; "
         f"budget {args.budget:g} s per run (kill at {2 * args.budget:g} s), memory cap {args.max_mem:g} GB"),
    ])
    hdr = (f"{'dim':>3s} {'poses':>8s} {'edges':>8s} {'command':16s} {'wall s':>8s} {'peak RSS':>9s} "
           f"{'status':8s} phases (s)")
    print(hdr)
    print("-" * 110)
    results: dict[tuple[int, str], list[tuple[int, float, float, float]]] = {}
    for d in dims:
        for n_req in sorted(sizes[d]):
            path = make_grid(d, n_req, args.cache_dir)
            n = grid_poses(d, n_req)
            with open(path, "rb") as fh:
                m = sum(1 for line in fh if line.startswith(b"EDGE"))
            programs, skipped = {}, []
            for c in commands:
                hist = results.get((d, c), [])
                t_pred = predict([(h[0], h[1]) for h in hist], n)
                m_pred = predict([(h[0], h[2]) for h in hist], n, MEMORY_EXPONENT.get((d, c), DEFAULT_EXPONENT))
                if not args.no_predict and (t_pred > args.budget or m_pred > max_rss):
                    skipped.append((c, t_pred, m_pred))
                    continue
                if c == "sesync":
                    programs[c] = lambda p=path: run_sesync(binary, p, env, timeout=2 * args.budget, max_rss=max_rss)
                else:
                    programs[c] = lambda c=c, p=path: run_process([*cmd, *posecrb_args(c, p)], env=env,
                                                                  timeout=2 * args.budget, max_rss=max_rss)
            runs = alternate(programs, args.repeat, warmup=args.repeat > 1) if programs else {}
            for c in commands:
                if c in runs:
                    r = median_run(runs[c])
                    t = median_wall(runs[c])
                    text, inproc = phases(c, r.stdout) if r.ok else (r.stderr.strip()[-120:], float("nan"))
                    if r.ok:
                        results.setdefault((d, c), []).append((n, t, float(r.max_rss), inproc))
                    print(f"{d:3d} {n:8d} {m:8d} {c:16s} {t:8.2f} {fmt_bytes(r.max_rss):>9s} {r.status:8s} {text}",
                          flush=True)
                else:
                    s = next(s for s in skipped if s[0] == c)
                    print(f"{d:3d} {n:8d} {m:8d} {c:16s} {'-':>8s} {'-':>9s} {'skipped':8s} predicted "
                          f"{s[1]:.0f} s, {fmt_bytes(s[2])} (budget {args.budget:g} s, {args.max_mem:g} GB)",
                          flush=True)
    print("-" * 110)
    print("fitted exponents (log-log least squares over the completed grids): wall time ~ poses^a, peak RSS ~ "
          "poses^b;\na_in = the same for the sum of the phase times the program reports (no start-up; for "
          "bounds only the timed phases)")
    print(f"{'dim':>3s} {'command':16s} {'grids':>5s} {'a (wall)':>9s} {'a_in':>6s} {'b (mem)':>8s}")
    for (d, c), hist in sorted(results.items(), key=lambda kv: (kv[0][0], COMMANDS.index(kv[0][1]))):
        ns = [h[0] for h in hist]
        a = fit_exponent(ns, [h[1] for h in hist])
        a_in = fit_exponent(ns, [h[3] for h in hist])
        b = fit_exponent(ns, [h[2] for h in hist])
        print(f"{d:3d} {c:16s} {len(hist):5d} {a:9.2f} {a_in:6.2f} {b:8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
