"""The performance page's tables from the suite's result files: one command, no pasting.

Reads asv's results of the in-process suite (``.bench/asv/results``: the newest run, or the one of
``--commit``) and the harness's files of the whole-process comparisons (``.bench/hyperfine/*.json``:
hyperfine's exports and the checks), and writes into ``--out`` (default ``.bench/report``) one
markdown file per table, and the scaling figure:

  provenance.md  date, commit and machine of the figures, once
  goals.md       every speed goal: what it asks, what was measured, met or not
  sesync.md      posecrb solve against SE-Sync C++, file by file, and the sums
  gtsam.md       every pose's covariance against GTSAM's Marginals
  mac.md         the algebraic connectivity's selection against MAC
  inprocess.md   the library's calls per dataset (asv)
  scaling.md     time and peak memory against poses on the grids, and the fitted exponents;
  scaling.png    the same as a log-log figure
  orderings.md   fim's time with each fill-reducing ordering
  threads.md     posecrb's thread policy against one thread, and the start-up and timeline tables
  baseline.md    this checkout against an earlier one (POSECRB_BASELINE), side by side: bounds and solve,
                 select on the grids, parsing; with the cost goals

A table whose results are absent says so in one line. The same text goes to stdout.

``--page FILE`` also writes the performance page: benchmarks/performance.md.in with each
``<!-- table: NAME -->`` line replaced by that table, and the scaling figure beside it in
``figures/scaling.png`` (``make bench-report`` writes docs/performance.md).
Usage: python benchmarks/report.py [--asv DIR] [--hyperfine DIR] [--commit HASH] [--out DIR] [--page FILE]
"""
from __future__ import annotations

import argparse
import ast
import datetime
import itertools
import json
import math
import os
import statistics
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TABLES = ("provenance", "goals", "sesync", "gtsam", "mac", "inprocess", "scaling", "orderings", "threads",
          "baseline")
# asv benchmarks of the scaling table and figure: label -> (time benchmark, peak-memory benchmark, extra params)
SCALING = {
    "solve": ("bench_solve.Solve.time_solve", "bench_solve.Solve.peakmem_solve", ()),
    "bounds, graph only": ("bench_bounds.BoundsGraphOnly.time_bounds", "bench_bounds.BoundsGraphOnly.peakmem_bounds",
                           ()),
    "bounds at the vertices": ("bench_bounds.BoundsAtVertices.time_bounds",
                               "bench_bounds.BoundsAtVertices.peakmem_bounds", ()),
    "fim": ("bench_models.Fim.time_fim", "bench_models.Fim.peakmem_fim", ()),
    "crlb": ("bench_models.Crlb.time_crlb", "bench_models.Crlb.peakmem_crlb", ()),
    "select (tree greedy, 20%)": ("bench_select.Select.time_select", None, ("tree-greedy",)),
}
INPROCESS = {"load": "bench_load.Load.time_load", "solve": "bench_solve.Solve.time_solve",
             "bounds": "bench_bounds.BoundsGraphOnly.time_bounds",
             "bounds at vertices": "bench_bounds.BoundsAtVertices.time_bounds", "fim": "bench_models.Fim.time_fim",
             "crlb": "bench_models.Crlb.time_crlb",
             "crlb per pose (sed)": "bench_models.CrlbPerPose.time_crlb_per_pose"}


# ---- reading the result files -------------------------------------------------------------------

class AsvRun:
    """One asv result file: ``value(benchmark, *params)`` (None when skipped, failed or absent)."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.data: dict = json.loads(path.read_text()) if path else {}
        machine = path.parent / "machine.json" if path else None
        self.machine: dict = json.loads(machine.read_text()) if machine and machine.is_file() else {}
        self.values: dict[str, dict[tuple, float | None]] = {}
        self.started: list[float] = []
        self.ended: list[float] = []
        columns = self.data.get("result_columns", [])
        for name, row in self.data.get("results", {}).items():
            fields = dict(zip(columns, row))
            if isinstance(fields.get("started_at"), (int, float)):   # ms since the epoch; duration in s
                self.started.append(fields["started_at"])
                self.ended.append(fields["started_at"] + 1000 * float(fields.get("duration") or 0))
            results = fields.get("result") or []
            params = [[ast.literal_eval(p) for p in values] for values in (fields.get("params") or [])]
            combos = list(itertools.product(*params)) if params else [()]
            self.values[name] = {combo: _number(v) for combo, v in zip(combos, results)}

    def __bool__(self) -> bool:
        return bool(self.values)

    def value(self, benchmark: str, *params: str) -> float | None:
        return self.values.get(benchmark, {}).get(tuple(params))

    def params(self, benchmark: str) -> list[tuple]:
        return list(self.values.get(benchmark, {}))


def _number(value) -> float | None:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def find_asv(results: Path, commit: str | None) -> AsvRun:
    """The newest result file under ``results`` (of ``commit`` when given)."""
    files = [p for p in results.glob("*/*.json") if p.name != "machine.json"] if results.is_dir() else []
    if commit:
        files = [p for p in files if p.name.startswith(commit[:8])]
    if not files:
        return AsvRun(None)
    return AsvRun(max(files, key=lambda p: json.loads(p.read_text()).get("date", 0)))


def read_groups(directory: Path) -> dict[str, dict]:
    """The harness's files: group name -> its content."""
    groups = {}
    for path in sorted(directory.glob("*.json")) if directory.is_dir() else []:
        data = json.loads(path.read_text())
        if isinstance(data, dict) and "comparisons" in data:
            groups[data.get("group", path.stem)] = data
    return groups


def timing(comparison: dict, label: str) -> dict | None:
    """hyperfine's result of one command of a comparison (None when it failed or is absent)."""
    for result in comparison.get("hyperfine", {}).get("results", []):
        if result.get("command") == label:
            return result
    return None


def median(comparison: dict, label: str) -> float | None:
    result = timing(comparison, label)
    return None if result is None else float(result["median"])


# ---- formatting ---------------------------------------------------------------------------------

def seconds(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.3f}" if value < 10 else f"{value:.2f}" if value < 100 else f"{value:.1f}"


def memory(value: float | None) -> str:
    if not value:
        return "-"
    return f"{value / 2**30:.2f} GiB" if value >= 2**30 else f"{value / 2**20:.0f} MiB"


def memories(comparison: dict, *labels: str) -> str:
    """The check runs' peak resident sets of ``labels``, "a / b"."""
    return " / ".join(memory(comparison["peak_rss"].get(label)) for label in labels)


def ratio(a: float | None, b: float | None) -> str:
    return f"{a / b:.2f}" if a is not None and b else "-"


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def absent(what: str, command: str) -> str:
    return f"No results: {what} ({command})."


def fit_exponent(sizes: list[float], values: list[float]) -> float:
    """Least-squares slope of log(value) against log(size): value ~ size^slope (nan below 2 points)."""
    points = [(math.log(s), math.log(v)) for s, v in zip(sizes, values) if s > 0 and v and v > 0]
    if len(points) < 2:
        return math.nan
    mx = statistics.fmean(p[0] for p in points)
    my = statistics.fmean(p[1] for p in points)
    sxx = sum((p[0] - mx) ** 2 for p in points)
    return sum((p[0] - mx) * (p[1] - my) for p in points) / sxx if sxx > 0 else math.nan


def grid_poses(name: str) -> tuple[int, int] | None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from suite.inputs import grid_spec

    return grid_spec(name)


# ---- the tables ---------------------------------------------------------------------------------

def provenance(run: AsvRun, groups: dict[str, dict]) -> str:
    """When, at which commit and on what each part of the run was measured: the machine and the
    versions once (per part where they differ), then a row per part."""
    lines, rows = [], []
    if run:
        start, end = (datetime.datetime.fromtimestamp(t / 1000, datetime.UTC)
                      for t in (min(run.started, default=0), max(run.ended, default=0)))
        m = run.machine
        lines.append(f"* Machine: {m.get('machine', '?')}, {m.get('cpu') or '?'}, {m.get('num_cpu') or '?'} cores; "
                     f"interpreter {run.data.get('python', '?')}.")
        rows.append(["in-process suite (asv)", f"{start:%Y-%m-%d %H:%M}-{end:%H:%M}",
                     run.data.get("commit_hash", "?")[:7], "asv's samples", ""])
    versions = {name: ", ".join(f"{k} {v}" for k, v in g.get("environment", {}).get("versions", {}).items())
                for name, g in groups.items()}
    if len(set(versions.values())) == 1:
        env = next(iter(groups.values()))["environment"]
        tool = "hyperfine " + env["hyperfine"].split()[-1] if env.get("hyperfine") else "hyperfine"
        lines.append(f"* Whole process: {tool} on {env.get('cpu', '?')}, {env.get('cores', '?')} cores; "
                     f"{next(iter(versions.values()))}.")
    for name, group in groups.items():
        env = group.get("environment", {})
        warmup = "no warm-up" if env.get("warmup") == 0 else f"{env.get('warmup')} warm-up"
        own = f"; {versions[name]}" if len(set(versions.values())) > 1 else ""
        rows.append([f"`{name}`", env.get("date", "?")[:16].replace("T", " "), env.get("commit", "?")[:7],
                     f"median of {env.get('runs')}, {warmup}{own}",
                     " ".join(f"{x:.2f}" for x in env.get("load_average", []))])
    commits = sorted({c[:7] for c in [run.data.get("commit_hash", "") if run else "",
                                       *(g.get("environment", {}).get("commit", "") for g in groups.values())] if c})
    if len(commits) > 1:
        lines.append(library_identity(commits))
    if not rows:
        return absent("neither suite has run", "make bench")
    header = ["part", "UTC", "commit", "runs", "load average at the end (1, 5, 15 min)"]
    return "\n".join(lines) + "\n\n" + table(header, rows)


def library_identity(commits: list[str]) -> str:
    """Whether the measured library (``posecrb/``) is the same at every commit of the run's parts:
    a run can span commits that change only the benchmarks or the documentation."""
    import subprocess

    changed = [c for c in commits[1:] if subprocess.run(
        ["git", "-C", str(REPO), "diff", "--quiet", commits[0], c, "--", "posecrb"], check=False).returncode != 0]
    names = ", ".join(commits)
    if not changed:
        return f"* The library (`posecrb/`) is the same at commits {names}: they differ only outside it."
    return f"* **The library (`posecrb/`) differs between commits {names}**: the parts measured different code."


def _goal(ok: bool | None) -> str:
    return "-" if ok is None else ("yes" if ok else "**no**")


def flop_limit_goal(run: AsvRun) -> list[str]:
    """The FIM log-det's cost goal (bench_models.FimFlopLimit): its time at most 1.6x the flop limit, on
    the largest grid the run measured; "-" when the benchmark did not run."""
    bench = "bench_models.FimFlopLimit.track_"
    measured = [p[0] for p in run.params(bench + "limit_ratio") if run.value(bench + "limit_ratio", *p) is not None]
    name = max(measured, key=lambda n: (grid_poses(n) or (0, 0))[1], default="grid3d-20000")
    goal = (f"FIM log-det of the 3D grid of {(grid_poses(name) or (0, 0))[1]:,} poses at most 1.6x the flop limit "
            "(median of 3)")
    if name not in measured:
        return [goal, "-", "-"]
    time, gflop, rate, times_limit = (run.value(bench + what, name) or math.nan
                                      for what in ("seconds", "gflop", "dgemm_rate", "limit_ratio"))
    return [goal, f"{seconds(time)} s against {gflop:.4g} Gflop / {rate:.1f} GF/s = {seconds(gflop / rate)} s: "
                  f"**{times_limit:.2f}x**", _goal(times_limit <= 1.6)]


def goals(run: AsvRun, groups: dict[str, dict]) -> str:
    rows: list[list[str]] = []
    by_label = {name: {c["label"]: c for c in g["comparisons"]} for name, g in groups.items()}
    startup = by_label.get("startup", {}).get("startup")
    if startup:
        helps, info = median(startup, "posecrb --help"), median(startup, "posecrb info")
        rows.append(["`posecrb --help` at most 0.25 s", f"{seconds(helps)} s",
                     _goal(helps is not None and helps <= 0.25)])
        rows.append([f"`posecrb info` of a small file ({Path(startup['checks'].get('file', '?')).stem}) at most 0.35 s",
                     f"{seconds(info)} s", _goal(info is not None and info <= 0.35)])
    for label, comparison in by_label.get("goals", {}).items():
        kind, name = label.split(" ", 1)
        checks = comparison.get("checks", {})
        wall = median(comparison, kind.split("-")[0])
        poses = checks.get("poses") or (grid_poses(name) or (0, 0))[1]
        if kind == "solve":
            certified = bool(checks.get("certified"))
            rows.append([f"`solve` of the {name[4:6].upper()} grid of {poses:,} poses at most 15 s, certified",
                         f"{seconds(wall)} s, {memory(comparison['peak_rss'].get('solve'))}, "
                         f"{'certified' if certified else 'NOT certified'}",
                         _goal(wall is not None and wall <= 15 and certified)])
        elif kind == "bounds-vertices":
            # the work of the stages: each median time times its runs (the default protocol repeats
            # the short stages; a record without runs counts each stage once)
            runs = checks.get("runs") or {}
            stages = sum(v * runs.get(k, 1) for k, v in (checks.get("times") or {}).items()
                         if isinstance(v, (int, float)) and k != "total")
            allowed = 1.5 * stages + 1.5
            rows.append([f"`bounds --estimate vertices` of the 3D grid of {poses:,} poses: wall at most 1.5x "
                         "the work of its stages (time x runs) + 1.5 s",
                         f"{seconds(wall)} s against stages of {seconds(stages)} s (allowed {seconds(allowed)} s), "
                         f"{memory(comparison['peak_rss'].get('bounds'))}",
                         _goal(wall is not None and wall <= allowed)])
    rows.append(flop_limit_goal(run))
    sesync = groups.get("sesync")
    if sesync:
        floor = median(startup, "import floor") if startup else None
        verdicts = [sesync_goal(c, floor) for c in sesync["comparisons"]]
        total_s, total_p = (sum(median(c, p) or 0.0 for c in sesync["comparisons"] if "hyperfine" in c)
                            for p in ("SE-Sync", "posecrb"))
        met = sum(v == "met" for v in verdicts)
        rows.append(["every SE-Sync file at most SE-Sync C++'s time where it needs 0.5 s or more, else at most "
                     "SE-Sync + the import floor + 0.1 s; the sum at most 0.8x",
                     f"{met} of {len(verdicts)} files; sum {seconds(total_p)} s against {seconds(total_s)} s, "
                     f"**{ratio(total_p, total_s)}x**",
                     _goal(met == len(verdicts) and bool(total_s) and total_p <= 0.8 * total_s)])
    mac = groups.get("mac")
    if mac:
        parts, oks = [], []
        for c in mac["comparisons"]:
            ours, theirs = median(c, "posecrb"), median(c, "MAC")
            l2 = c.get("checks", {}).get("lambda2", {})
            ok = ours is not None and theirs is not None and ours <= theirs and \
                (l2.get("posecrb") or 0) >= (l2.get("MAC") or math.inf) * (1 - 1e-9)
            oks.append(ok)
            parts.append(f"{c['label']} {seconds(ours)} s against {seconds(theirs)} s ({ratio(ours, theirs)}x)")
        rows.append(["`select --objective fiedler --method relax` at most MAC's time (whole process), with lambda_2 "
                     "at least MAC's", "; ".join(parts), _goal(bool(oks) and all(oks))])
    relax = [(name, run.value("bench_select.Select.time_select", name, "tree-relax"),
              run.value("bench_select.Select.time_select", name, "tree-greedy")) for name in ("intel", "city10000")]
    relax = [r for r in relax if r[1] is not None and r[2] is not None]
    if relax:
        rows.append(["the tree objective's `relax` at most its own `greedy`'s time (in-process)",
                     "; ".join(f"{n} {seconds(a)} s against {seconds(b)} s ({a / b:.2f}x)" for n, a, b in relax),
                     _goal(all(a <= b for _, a, b in relax))])
    timelines = list(by_label.get("timeline", {}).values())
    if timelines:
        # The goal is the long chain's (its prefixes are many and each cheap); the other files'
        # ratios are in the threads table, where the timeline's cost per prefix shows.
        ratios = [(c["label"], median(c, "timeline"), median(c, "bounds")) for c in timelines
                  if "hyperfine" in c and c["label"].startswith("chain")]
        if ratios:
            rows.append(["`timeline --estimate none` of the 2D chain at most 3x one `bounds --estimate none`",
                         "; ".join(f"{n} {ratio(a, b)}x" for n, a, b in ratios),
                         _goal(all(a is not None and b and a <= 3 * b for _, a, b in ratios))])
    verifies = [c for c in by_label.get("verify", {}).values() if "hyperfine" in c]
    if verifies:
        sums = [(c["label"], median(c, "verify"), (median(c, "solve") or 0.0) + (median(c, "crlb") or 0.0))
                for c in verifies]
        rows.append(["`verify` at most one `solve` plus one `crlb` of the same graph (whole process)",
                     "; ".join(f"{n} {seconds(a)} s against {seconds(b)} s" for n, a, b in sums),
                     _goal(all(a is not None and a <= b for _, a, b in sums))])
        stages = [(c["label"], c["checks"].get("certificate"), c["checks"].get("solve_certificate")) for c in verifies]
        rows.append(["`verify --no-solve`: the certificate at the estimate at most twice `solve`'s own certificate "
                     "check", "; ".join(f"{n} {seconds(a)} s against {seconds(b)} s" for n, a, b in stages),
                     _goal(all(a is not None and b is not None and a <= 2 * b for _, a, b in stages))])
    return table(["goal", "measured", "met"], rows)


def sesync_goal(comparison: dict, floor: float | None) -> str:
    theirs, ours = median(comparison, "SE-Sync"), median(comparison, "posecrb")
    if theirs is None or ours is None:
        return "failed"
    if theirs >= 0.5:
        return "met" if ours <= theirs else "missed"
    return "met" if floor is not None and ours <= theirs + floor + 0.1 else "missed"


def agreement(agree: bool | None, theirs: float | None, ours: float | None, certified: bool | None) -> str:
    """The "agree" cell: yes, or no with the side whose objective is lower. Where posecrb's certified
    optimum is the lower one, SE-Sync stopped above the optimum (its own stopping rule, not a
    different problem)."""
    if agree:
        return "yes"
    if theirs is None or ours is None or not (math.isfinite(theirs) and math.isfinite(ours)):
        return "**no**"
    if ours < theirs:
        return "**no**: posecrb lower" + (" (certified)" if certified else "")
    return "**no**: SE-Sync lower"


def sesync(groups: dict[str, dict]) -> str:
    group = groups.get("sesync")
    if not group:
        return absent("posecrb solve against SE-Sync C++", "SESYNC_BIN=... python benchmarks/peers/sesync_solve.py")
    startup = next((c for c in groups.get("startup", {}).get("comparisons", []) if c["label"] == "startup"), None)
    floor = median(startup, "import floor") if startup else None
    rows = []
    totals = [0.0, 0.0]
    for c in group["comparisons"]:
        checks = c.get("checks", {})
        if "hyperfine" not in c:
            rows.append([c["label"], "failed: " + "; ".join(f"{k}: {v}" for k, v in c.get("failed", {}).items())]
                        + [""] * 9)
            continue
        theirs, ours = median(c, "SE-Sync"), median(c, "posecrb")
        totals[0] += theirs or 0.0
        totals[1] += ours or 0.0
        s, p = checks.get("sesync", {}), checks.get("posecrb", {})
        rows.append([c["label"], str(checks.get("dim", "")), f"{checks.get('poses', 0):,}", seconds(theirs),
                     seconds(ours), ratio(ours, theirs), memories(c, "SE-Sync", "posecrb"),
                     f"{s.get('objective', math.nan):.6g} / {p.get('objective', math.nan):.10g}",
                     agreement(checks.get("agree"), s.get("objective"), p.get("objective"), p.get("certified")),
                     f"{s.get('status', '?')} / {'certified' if p.get('certified') else 'NOT certified'}",
                     sesync_goal(c, floor)])
    rows.append(["**sum**", "", "", seconds(totals[0]), seconds(totals[1]), f"**{ratio(totals[1], totals[0])}**",
                 "", "", "", "", ""])
    return table(["file", "d", "poses", "SE-Sync s", "posecrb s", "ratio", "peak RSS (SE-Sync / posecrb)",
                  "F (SE-Sync / posecrb)", "agree", "status (SE-Sync / posecrb)", "goal"], rows)


def gtsam(groups: dict[str, dict]) -> str:
    group = groups.get("gtsam")
    if not group:
        return absent("every pose's covariance against GTSAM", "python benchmarks/peers/gtsam_marginals.py")
    rows = []
    for c in group["comparisons"]:
        if "hyperfine" not in c:
            rows.append([c["label"], "failed", "", "", "", ""])
            continue
        ours, theirs = median(c, "posecrb"), median(c, "GTSAM")
        rows.append([c["label"], f"{c['checks'].get('poses', 0):,}", seconds(ours), seconds(theirs),
                     ratio(ours, theirs), memories(c, "posecrb", "GTSAM"),
                     f"{c['checks'].get('largest_relative_difference', math.nan):.1e}"])
    return table(["file", "poses", "posecrb s", "GTSAM s", "ratio", "peak RSS (posecrb / GTSAM)",
                  "largest relative difference"], rows)


def mac(groups: dict[str, dict]) -> str:
    group = groups.get("mac")
    if not group:
        return absent("the algebraic connectivity's selection against MAC",
                      "POSECRB_MAC_PYTHON=... python benchmarks/peers/mac_select.py")
    rows = []
    for c in group["comparisons"]:
        if "hyperfine" not in c:
            rows.append([c["label"], "failed"] + [""] * 7)
            continue
        ch = c["checks"]
        ours, theirs = median(c, "posecrb"), median(c, "MAC")
        l2, ub, inproc = ch.get("lambda2", {}), ch.get("upper_bound", {}), ch.get("in_process", {})
        rows.append([c["label"], str(ch.get("budget")), seconds(ours), seconds(theirs), ratio(ours, theirs),
                     f"{seconds(inproc.get('posecrb'))} / {seconds(inproc.get('MAC'))}",
                     f"{l2.get('posecrb', math.nan):.8g} / {l2.get('MAC', math.nan):.8g}",
                     f"{ub.get('posecrb') or math.nan:.6g} / {ub.get('MAC') or math.nan:.6g}"])
    return table(["file", "K", "posecrb s", "MAC s", "ratio", "in-process s (posecrb / MAC)",
                  "lambda_2 (posecrb / MAC, MAC's evaluator)", "upper bound (posecrb / MAC)"], rows)


def inprocess(run: AsvRun) -> str:
    if not run:
        return absent("the in-process suite", "make bench")
    names = list(dict.fromkeys(p[0] for bench in INPROCESS.values() for p in run.params(bench)
                               if grid_poses(p[0]) is None))
    rows = [[name] + [seconds(run.value(bench, name)) for bench in INPROCESS.values()] for name in names]
    return table(["dataset"] + [f"{label} s" for label in INPROCESS], rows)


def scaling_records(run: AsvRun) -> list[dict]:
    records = []
    for label, (time_bench, mem_bench, extra) in SCALING.items():
        for params in run.params(time_bench):
            spec = grid_poses(params[0])
            if spec is None or tuple(params[1:]) != extra:
                continue
            records.append({"command": label, "dim": spec[0], "poses": spec[1],
                            "time": run.value(time_bench, *params),
                            "memory": run.value(mem_bench, *params) if mem_bench else None})
    return records


def scaling(run: AsvRun, out: Path | None) -> str:
    records = scaling_records(run)
    if not records:
        return absent("the grids of the in-process suite", "make bench")
    rows = [[str(r["dim"]), f"{r['poses']:,}", r["command"], seconds(r["time"]), memory(r["memory"])]
            for r in sorted(records, key=lambda r: (r["dim"], list(SCALING).index(r["command"]), r["poses"]))]
    fits = []
    for (dim, command), group in itertools.groupby(sorted(records, key=lambda r: (r["dim"], list(SCALING).index(
            r["command"]))), key=lambda r: (r["dim"], r["command"])):
        group = list(group)
        sizes = [r["poses"] for r in group]
        a = fit_exponent(sizes, [r["time"] for r in group])
        b = fit_exponent(sizes, [r["memory"] for r in group])
        fits.append([str(dim), command, str(len(group))] + ["-" if math.isnan(x) else f"{x:.2f}" for x in (a, b)])
    text = table(["d", "poses", "call", "time s", "peak memory"], rows) + "\n\nFitted exponents (time ~ poses^a, " \
        "peak memory ~ poses^b, least squares on log-log):\n\n" + table(["d", "call", "grids", "a", "b"], fits)
    if out is not None:
        plot(records, out / "scaling.png")
        text += "\n\n![Time and peak memory against poses](scaling.png)"
    return text


def plot(records: list[dict], path: Path) -> None:
    """Time and peak memory against poses, log-log: 2D and 3D side by side, one line per call, one
    legend below the panels in a font that stays readable at page width."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dims = sorted({r["dim"] for r in records})
    fig, axes = plt.subplots(2, len(dims), figsize=(5.5 * len(dims), 8), squeeze=False)
    for col, dim in enumerate(dims):
        for label in SCALING:
            points = sorted((r["poses"], r["time"], r["memory"]) for r in records
                            if r["dim"] == dim and r["command"] == label and r["time"])
            if not points:
                continue
            xs = [p[0] for p in points]
            color = f"C{list(SCALING).index(label)}"   # one colour per call in every panel
            axes[0][col].loglog(xs, [p[1] for p in points], "o-", label=label, color=color)
            mem = [(x, p[2] / 2**30) for x, p in zip(xs, points) if p[2]]
            if mem:
                axes[1][col].loglog(*zip(*mem), "o-", label=label, color=color)
        axes[0][col].set_title(f"{dim}D grids: time of one call", fontsize=13)
        axes[1][col].set_title(f"{dim}D grids: peak memory of the process", fontsize=13)
        axes[0][col].set_ylabel("seconds", fontsize=12)
        axes[1][col].set_ylabel("GiB", fontsize=12)
        for ax in (axes[0][col], axes[1][col]):
            ax.set_xlabel("poses", fontsize=12)
            ax.tick_params(labelsize=11)
            ax.grid(True, which="both", alpha=0.3)
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=13, frameon=False)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def orderings(run: AsvRun) -> str:
    bench = "bench_models.Orderings.time_fim"
    params = run.params(bench)
    if not params:
        return absent("fim with each ordering", "make bench")
    names = list(dict.fromkeys(p[0] for p in params))
    kinds = list(dict.fromkeys(p[1] for p in params))
    rows = []
    for name in names:
        times = {k: run.value(bench, name, k) for k in kinds}
        known = {k: t for k, t in times.items() if t is not None}
        rows.append([name] + [seconds(times[k]) for k in kinds] + [min(known, key=known.get) if known else "-"])
    return table(["input"] + [f"{k} s" for k in kinds] + ["fastest"], rows)


def threads(groups: dict[str, dict]) -> str:
    parts = []
    group = groups.get("threads")
    if group:
        rows = []
        for c in group["comparisons"]:
            policy, one = timing(c, "posecrb's policy"), timing(c, "one thread")
            if policy is None or one is None:
                rows.append([c["label"], "failed", "", "", ""])
                continue
            rows.append([c["label"], seconds(policy["median"]), seconds(one["median"]),
                         ratio(policy["median"], one["median"]),
                         f"{seconds(policy['user'] + policy['system'])} / {seconds(one['user'] + one['system'])}"])
        parts.append(table(["command", "posecrb's policy s", "one thread s", "ratio",
                            "CPU s, user + system (policy / one thread)"], rows))
    else:
        parts.append(absent("posecrb's thread policy against one thread", "python benchmarks/commands.py"))
    startup = next((c for c in groups.get("startup", {}).get("comparisons", []) if "hyperfine" in c), None)
    if startup:
        rows = [[f"`{r['command']}`", seconds(r["median"]), memory(startup["peak_rss"].get(r["command"]))]
                for r in startup["hyperfine"]["results"]]
        parts.append(table(["program", "median s", "peak RSS"], rows))
    timeline = [c for c in groups.get("timeline", {}).get("comparisons", []) if "hyperfine" in c]
    if timeline:
        rows = [[c["label"], seconds(median(c, "timeline")), seconds(median(c, "bounds")),
                 ratio(median(c, "timeline"), median(c, "bounds"))] for c in timeline]
        parts.append(table(["file", "timeline s", "bounds s", "ratio"], rows))
    return "\n\n".join(parts)


def _exponent(points: list[tuple[float, float]]) -> float | None:
    """The least-squares slope of log(time) against log(size)."""
    if len(points) < 2:
        return None
    xs, ys = [math.log(x) for x, _ in points], [math.log(y) for _, y in points]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    return None if sxx == 0 else sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx


def baseline(groups: dict[str, dict]) -> str:
    group = groups.get("baseline")
    if not group:
        return absent("this checkout against an earlier one", "POSECRB_BASELINE=DIR python benchmarks/commands.py "
                      "--groups baseline --alternate")
    comps = [c for c in group["comparisons"] if "hyperfine" in c]
    commit = group.get("environment", {}).get("baseline_commit") or "the baseline"
    rows, goal_rows = [], []
    bounds_ok, select_points, ratios_ok = [], [], []
    for c in comps:
        kind, name = c["label"].split(" ", 1)
        if kind == "bounds":
            now, before, solve = median(c, "bounds"), median(c, "bounds before"), median(c, "solve")
            allowed = None if solve is None else max(solve + 0.3, 1.3 * solve)
            ok = now is not None and allowed is not None and now <= allowed
            bounds_ok.append(ok)
            rows.append([f"`bounds` {name}", seconds(before), seconds(now), ratio(now, before),
                         f"solve {seconds(solve)} s, allowed {seconds(allowed)} s: {_goal(ok)}"])
        elif kind == "select":
            now, before = median(c, "select"), median(c, "select before")
            ch = c.get("checks", {})
            ok = ch.get("ratio") is not None and ch.get("ratio_before") is not None and \
                ch["ratio"] >= ch["ratio_before"] - 0.01
            ratios_ok.append(ok)
            if name.startswith("grid2d") and now is not None and ch.get("candidates"):
                select_points.append((float(ch["candidates"]), now, name))
            rows.append([f"`select --budget 20%` {name}", seconds(before), seconds(now), ratio(now, before),
                         f"certified ratio {ch.get('ratio_before', 0):.4f} -> {ch.get('ratio', 0):.4f} "
                         f"({ch.get('method')}): {_goal(ok)}"])
        elif kind == "parse":
            ch = c.get("checks", {})
            p_now, p_before = ch.get("parse"), ch.get("parse_before")
            ok = p_now is not None and p_before is not None and p_before >= 4 * p_now
            runs = f", median of {ch['parse_runs']}" if ch.get("parse_runs") else ""
            rows.append([f"parse {name} (in-process{runs})", seconds(p_before), seconds(p_now), ratio(p_now, p_before),
                         _goal(ok)])
            rows.append([f"`info` {name}", seconds(median(c, "info before")), seconds(median(c, "info")),
                         ratio(median(c, "info"), median(c, "info before")), ""])
            goal_rows.append(["parsing the 2D grid at least 4x faster", f"{seconds(p_before)} s -> {seconds(p_now)} s",
                              _goal(ok)])
    if bounds_ok:
        goal_rows.append(["`bounds` at most the larger of `solve` + 0.3 s and 1.3x `solve`",
                          f"{sum(bounds_ok)} of {len(bounds_ok)} files", _goal(all(bounds_ok))])
    if select_points:
        exponent = _exponent([(x, y) for x, y, _ in select_points])
        largest = max(select_points)
        goal_rows.append(["`select --budget 20%` on the 2D grids: exponent in the candidates at most 1.2",
                          "n/a" if exponent is None else f"{exponent:.2f}",
                          _goal(exponent is not None and exponent <= 1.2)])
        goal_rows.append([f"`select --budget 20%` of {largest[2]} at most 15 s", f"{seconds(largest[1])} s",
                          _goal(largest[1] <= 15)])
    if ratios_ok:
        goal_rows.append(["certified ratio at least the earlier greedy's minus 0.01",
                          f"{sum(ratios_ok)} of {len(ratios_ok)} graphs", _goal(all(ratios_ok))])
    return "\n\n".join([f"Against {commit}, side by side (alternating rounds), whole process:",
                         table(["run", "before s", "after s", "after/before", "check"], rows),
                         table(["goal", "measured", "met"], goal_rows)])


TEMPLATE = REPO / "benchmarks" / "performance.md.in"
_TABLE_LINE = "<!-- table: {} -->"


def _replace(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file renamed into place."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def page(tables: dict[str, str], template: str) -> str:
    """The performance page: the template with each table's marker line replaced by the table
    (the scaling figure referred to in the page's ``figures/`` folder). A marker of an unknown
    table, or a table without its marker, is an error: the page would lose or invent a table."""
    lines = template.splitlines()
    markers = {line for line in lines if line.startswith("<!-- table: ")}
    expected = {_TABLE_LINE.format(name) for name in tables}
    if markers != expected:
        raise ValueError(f"{TEMPLATE.name}: markers {sorted(markers ^ expected)} do not match the tables")
    by_marker = {_TABLE_LINE.format(name): text.replace("](scaling.png)", "](figures/scaling.png)")
                 for name, text in tables.items()}
    return "\n".join(by_marker.get(line, line) for line in lines) + "\n"


def build(run: AsvRun, groups: dict[str, dict], out: Path | None) -> dict[str, str]:
    """Every table's markdown, by name (``out``: where the figure goes; None draws no figure)."""
    return {"provenance": provenance(run, groups), "goals": goals(run, groups), "sesync": sesync(groups),
            "gtsam": gtsam(groups), "mac": mac(groups), "inprocess": inprocess(run), "scaling": scaling(run, out),
            "orderings": orderings(run), "threads": threads(groups), "baseline": baseline(groups)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--asv", default=str(REPO / ".bench" / "asv" / "results"), help="asv's results directory")
    ap.add_argument("--hyperfine", default=str(REPO / ".bench" / "hyperfine"), help="the harness's result files")
    ap.add_argument("--commit", default=None, help="the asv run of this commit [default: the newest]")
    ap.add_argument("--out", default=str(REPO / ".bench" / "report"), help="directory of the tables")
    ap.add_argument("--page", default=None, help="also write the performance page here (its figure into "
                                                 "figures/ beside it)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    run, groups = find_asv(Path(args.asv), args.commit), read_groups(Path(args.hyperfine))
    if args.page and not (run and groups):
        # A page of "No results" lines would replace the figures of the last run.
        print(f"report: no {'in-process' if not run else 'whole-process'} results to write the page from "
              f"({args.asv if not run else args.hyperfine}): run make bench first", file=sys.stderr)
        return 1
    tables = build(run, groups, out)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in tables.items():
        _replace(out / f"{name}.md", (text + "\n").encode())
        print(f"<!-- {name}.md -->\n{text}\n")
    if args.page:
        target = Path(args.page)
        _replace(target, page(tables, TEMPLATE.read_text()).encode())
        figure = out / "scaling.png"
        if figure.is_file():
            (target.parent / "figures").mkdir(exist_ok=True)
            _replace(target.parent / "figures" / "scaling.png", figure.read_bytes())
        print(f"wrote {target}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
