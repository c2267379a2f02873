"""Scaling on noisy grids: whole-process time and peak memory against the number of poses.

Grids (benchmarks/grids.py: full lattices, noise 0.05, seed 0): 2D 10^3, 10^4, 3*10^4 and 10^5
poses (10^6 with --huge), 3D 10^3, 5*10^3 and 2*10^4 (10^5 with --huge). For each grid, runs
  bounds none      posecrb bounds FILE --estimate none --repeat 1      (graph-only bounds)
  bounds vertices  posecrb bounds FILE --estimate vertices --repeat 1  (+ FIM log-det at the vertices)
  fim              posecrb fim FILE --estimate vertices                (FIM build + log-det)
  crlb             posecrb crlb FILE --estimate vertices               (trace by selected inversion)
  solve            posecrb solve FILE                                  (certified optimum)
  select           posecrb select FILE --budget 20%                    (tree objective, greedy)
  SE-Sync          $SESYNC_BIN FILE                                    (when set, benchmarks/_peers.py)
each as one whole process (--repeat K: median of K alternating rounds after a warm-up), and prints
wall time, peak RSS, the in-process phase times each program reports, and per command the fitted
exponent of time (and memory) against poses. `--repeat 1` is passed to bounds so that it computes
once (its default, auto, computes a stage once only when it takes >= 1 s). Every BLAS pool keeps
all cores unless --threads T caps them.

Flop limit (on unless --no-flops): per grid, CHOLMOD's flop count of the FIM factorization with
the ordering posecrb uses (posecrb.linalg.ordering, auto), through benchmarks/_cholmod.py, and
right before the grid's runs the dgemm rate of all cores of the system BLAS (CHOLMOD's); the FIM
log-det phase of
`fim` and `bounds vertices` is printed as a multiple of flops / rate. --plot FILE draws time and
peak memory against poses (log-log, one line per command, 2D and 3D), --json FILE keeps the
results, --markdown prints the table for docs/performance.md.

A run is skipped when the fit over the smaller grids (exponent 1.5 from a single point) predicts
more than --budget seconds or --max-mem GB (--no-predict: never); a run exceeding 2x the budget or
the memory cap is killed. From a single point, crlb's memory is extrapolated with the growth of the
nonzeros of a nested-dissection Cholesky factor (n log n in 2D, taken as n^1.1; n^(4/3) in 3D):
the selected inversion works in place on a copy of the factor's values, so its memory follows them.

Goals: 2D 10^5 solve <= 15 s and <= 1.5 GB; 3D 2.2*10^4 solve <= 20 s and FIM log-det <= 3 s;
bounds --estimate none exponent <= 1.2 up to 10^6 2D poses within 24 GB.

Usage: python benchmarks/scaling.py [--dims 2,3] [--huge] [--sizes2 N,N] [--sizes3 N,N]
          [--commands bounds-none,bounds-vertices,fim,crlb,solve,select,sesync] [--budget S]
          [--max-mem GB] [--repeat K] [--threads T] [--posecrb CMD] [--cache-dir DIR] [--no-flops]
          [--plot FILE.png|svg] [--json FILE] [--markdown]
"""
from __future__ import annotations

import argparse
import json
import math
import os
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

SIZES = {2: [1_000, 10_000, 30_000, 100_000], 3: [1_000, 5_000, 20_000]}
HUGE = {2: [1_000_000], 3: [100_000]}
COMMANDS = ["bounds-none", "bounds-vertices", "fim", "crlb", "solve", "select", "sesync"]
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
        "select": ["select", f, "--budget", "20%", "--format", "json"],
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
            "bounds-vertices": ["parse", "laplacians", "lb", "ub", "ub_lambda", "fim_build", "fim_logdet",
                                "logdet_accuracy"],
            "fim": ["parse", "fim_build", "fim_logdet", "logdet_accuracy"],
            "crlb": ["parse", "fim_build", "crlb_blocks", "accuracy", "curvature"],
            "solve": ["parse", "init", "optimize", "verify", "round"],
            "select": ["setup", "base", "select", "value"]}[command]
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


def flop_child(path: Path) -> dict:
    """In a child process: CHOLMOD's flop count and nnz(L) of the FIM factorization with the
    ordering posecrb's `auto` uses on this graph (the FIM at the file's vertices, as `fim` and
    `bounds --estimate vertices` factor it)."""
    import _cholmod
    import numpy as np

    from posecrb.io import load
    from posecrb.models.paper.fim import fim_symbolic_choice, paper_fim

    graph = load(path)
    fim = paper_fim(graph, graph.vertex_rot, graph.vertex_trans, 0, "eq59", variant="consistent")
    sym, choice = fim_symbolic_choice(fim, "auto")
    f = _cholmod.Factorization(fim.matrix, perm=np.asarray(sym.permutation))
    return {"flops": f.flops, "lnz": f.lnz, "ordering": str(choice)}


def dgemm_child() -> dict:
    import _cholmod

    return {"dgemm_all": _cholmod.dgemm_rate(), "cores": os.cpu_count()}


def run_child(what: str, path: Path | None, env: dict) -> dict:
    argv = [sys.executable, __file__, "--child", what] + ([str(path)] if path else [])
    r = run_process(argv, env=env)
    if not r.ok:
        return {"error": (r.stderr.strip().splitlines() or [r.status])[-1]}
    return json.loads(r.stdout.strip().splitlines()[-1])


def plot(records: list[dict], path: str) -> None:
    """Time and peak memory against poses, log-log, per dimension and command."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from posecrb.report.figures import save_figure
    from posecrb.report.plots import check_figure_path

    check_figure_path(path)
    dims = sorted({r["dim"] for r in records})
    fig, axes = plt.subplots(2, len(dims), figsize=(6 * len(dims), 8), squeeze=False)
    for col, d in enumerate(dims):
        for c in COMMANDS:
            pts = sorted((r["poses"], r["wall"], r["rss"]) for r in records if r["dim"] == d and r["command"] == c)
            if not pts:
                continue
            ns = [p[0] for p in pts]
            a = fit_exponent(ns, [p[1] for p in pts])
            b = fit_exponent(ns, [p[2] for p in pts])
            label = c if c != "sesync" else "SE-Sync C++ (solve)"
            axes[0][col].loglog(ns, [p[1] for p in pts], "o-", label=f"{label} (a = {a:.2f})")
            axes[1][col].loglog(ns, [p[2] / 2**30 for p in pts], "o-", label=f"{label} (b = {b:.2f})")
        axes[0][col].set_title(f"{d}D grids: wall time, whole process")
        axes[1][col].set_title(f"{d}D grids: peak memory")
        axes[0][col].set_ylabel("seconds")
        axes[1][col].set_ylabel("GiB")
        for ax in (axes[0][col], axes[1][col]):
            ax.set_xlabel("poses")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
    save_figure(fig, path)


def markdown(records: list[dict], limit_note: str) -> str:
    lines = ["| dim | poses | edges | command | wall s | peak RSS | in-process phases (s) | FIM log-det / limit |",
             "|---|---|---|---|---|---|---|---|"]
    for r in records:
        ratio = f"{r['ratio']:.2f} ({r['fim_logdet']:.2f} s / {r['limit']:.2f} s)" if r.get("ratio") else ""
        lines.append(f"| {r['dim']} | {r['poses']:,} | {r['edges']:,} | {r['command']} | {r['wall']:.2f} | "
                     f"{fmt_bytes(r['rss'])} | {r['phases']} | {ratio} |")
    return "\n".join(lines) + ("\n\n" + limit_note if limit_note else "")


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0], repeat=1, threads=0)
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
    ap.add_argument("--no-flops", action="store_true", help="skip the flop counts and the dgemm rate")
    ap.add_argument("--plot", default=None, help="write the log-log figure (PNG or SVG)")
    ap.add_argument("--json", default=None, help="write the results as JSON")
    ap.add_argument("--markdown", action="store_true", help="also print the table as markdown")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args, rest = ap.parse_known_args(argv)
    if args.child:
        print(json.dumps(flop_child(Path(rest[0])) if args.child == "flops" else dgemm_child()))
        return 0
    if rest:
        ap.error(f"unrecognized arguments: {' '.join(rest)}")
    if args.plot:
        from posecrb.report.plots import check_figure_path

        check_figure_path(args.plot)

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
    env = child_env(args.threads or None)
    rate = {} if args.no_flops else run_child("dgemm", None, env)
    cmd = posecrb_command(args.posecrb)
    max_rss = args.max_mem * 1e9
    print_header("posecrb scaling on noisy grids, whole process", args.threads or None, [
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
    records: list[dict] = []
    for d in dims:
        for n_req in sorted(sizes[d]):
            path = make_grid(d, n_req, args.cache_dir)
            n = grid_poses(d, n_req)
            with open(path, "rb") as fh:
                m = sum(1 for line in fh if line.startswith(b"EDGE"))
            programs, skipped = {}, []
            flops = ({} if args.no_flops or not {"fim", "bounds-vertices"} & set(commands)
                     else run_child("flops", path, env))
            if flops:   # the rate right before this grid's runs: the machine's load drifts
                rate = run_child("dgemm", None, env)
            limit = flops["flops"] / (rate["dgemm_all"] * 1e9) if "flops" in flops and "dgemm_all" in rate else None
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
                    rec = {"dim": d, "poses": n, "edges": m, "command": c, "wall": t, "rss": float(r.max_rss),
                           "status": r.status, "phases": text, "inprocess": inproc, "runs": len(runs[c])}
                    if r.ok and c in ("fim", "bounds-vertices") and limit:
                        ld = json.loads(r.stdout).get("times", {}).get("fim_logdet")
                        if isinstance(ld, (int, float)):
                            rec.update(fim_logdet=ld, limit=limit, ratio=ld / limit, flops=flops["flops"],
                                       ordering=flops["ordering"], dgemm=rate["dgemm_all"])
                            text += (f"; FIM log-det {ld / limit:.2f}x the limit ({flops['flops'] / 1e9:.1f} Gflop, "
                                     f"{flops['ordering']})")
                    if r.ok:
                        results.setdefault((d, c), []).append((n, t, float(r.max_rss), inproc))
                        records.append(rec)
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
    note = (f"Limit = CHOLMOD's flops of the FIM factorization / the dgemm rate of all {rate['cores']} cores "
            "(system BLAS, measured right before each grid's runs)." if "dgemm_all" in rate else "")
    if note:
        print(note)
    if args.markdown:
        print()
        print(markdown(records, note))
    if args.json:
        from posecrb.core.outputs import write_text

        write_text(args.json, json.dumps({"records": records, "dgemm": rate, "load_end": os.getloadavg()},
                                         indent=1))
    if args.plot:
        plot(records, args.plot)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
