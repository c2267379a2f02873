"""posecrb's measurement selection against MAC (Doherty et al. 2022), side by side on the same problem.

MAC is not a dependency: set POSECRB_MAC_PYTHON to a Python interpreter that can ``import mac``
(a virtual environment with MAC installed from its public repository, outside this checkout; see
benchmarks/_peers.py); without it the MAC columns are skipped with a message and posecrb runs
alone. Both sides get the same odometry chain as fixed edges and the same loop closures as
candidates, weighted by the Langevin concentration kappa (MAC's weights), and the same budget K
(--budget, default 20% of the candidates, rounded down as MAC does).

Speed (always printed), on intel and city10000 unless NAMEs are given:

* fiedler relax against MAC, in-process, as MAC is run (its g2o example builds ``MAC`` and calls
  ``solve`` inside one process): each side runs in its own worker process that loads the problem,
  makes one untimed call (page cache, numba's cache, first imports), then times --reps calls;
  workers of the two sides alternate (order flipped every round) for --rounds rounds and the
  figure is the median of all timed calls (wall, and CPU time of the process: with one thread per
  pool, the cost without the other processes' share of the cores). MAC's call = ``MAC(...)`` + ``NaiveGreedy.subset`` +
  ``MAC.solve`` (20 Frank-Wolfe iterations, nearest rounding: its example's protocol) with
  ``fiedler_method="tracemin_cholesky"``; posecrb's = ``select_edges(graph, budget,
  objective="fiedler", method="relax", fiedler_weight="kappa")``, the odometry split included.
  lambda_2 of both selections by one evaluator (posecrb's ``FiedlerObjective``, the Rayleigh
  quotient of a converged Lanczos vector) and by MAC's ``evaluate_objective``; the upper bound
  each reports.
* the same whole process against whole process: ``posecrb select NAME --budget B --objective
  fiedler --method relax --format json`` (which reads the g2o file; its lambda_2 uses the rotation
  weight, 2 kappa in 2D, so it is twice the kappa one) against a MAC process that imports MAC,
  loads the problem from an npz file written here (MAC's side does not read the g2o file) and
  solves; one untimed run each, then --rounds alternating runs, median wall.
* the tree objective's relax against its own greedy (and greedy --certify, which also returns a
  relaxation bound), in-process (alternating workers as above) and whole process (``posecrb select
  NAME --budget B [--method relax | --certify]``): median times, values and upper bounds.

Goals (printed met / MISSED): posecrb fiedler relax at most MAC's time with lambda_2 at least
MAC's (one evaluator, within 1e-9 relative); tree relax at most tree greedy's time with a value at
least greedy's.

--quality adds, per dataset and budget (--budgets, default 10%,20%,50%), the former comparison of
what the selections are worth for SLAM: MAC, posecrb fiedler-relax and tree greedy under the tree
bound (eq. 75), the FIM log-det at the full graph's certified optimum and the ATE of the pruned
graph's certified optimum.

Every OpenMP/BLAS/numba pool of both programs is capped at --threads threads (default 1; 0 keeps
the libraries' defaults).
Usage: POSECRB_MAC_PYTHON=/path/to/python python benchmarks/mac_compare.py [--budget 20%] [--rounds K]
           [--reps R] [--threads T] [--quality [--budgets 10%,20%,50%]] [NAME ...]
"""
from __future__ import annotations

import json
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np
from _common import (
    alternate,
    child_env,
    median_wall,
    posecrb_command,
    print_header,
    process_parser,
    run_process,
)
from _peers import mac_build_info, mac_python

from posecrb import load
from posecrb.datasets import search as datasets

SPEED_DATASETS = ("intel", "city10000")
QUALITY_DATASETS = ("intel", "city10000", "ais2klinik", "kitti_02", "kitti_05", "sphere2500")

# posecrb's in-process worker: one untimed call, then REPS timed calls of select_edges.
OURS_WORKER = r"""
import json, logging, sys, time
logging.getLogger("posecrb").setLevel(logging.ERROR)
from posecrb import load
from posecrb.datasets import search
from posecrb.selection import select_edges
name, budget, objective, method, certify, reps = sys.argv[1:7]
g = load(search.resolve(name))
kw = dict(objective=objective, method=method, certify=certify == "1")
if objective == "fiedler":
    kw["fiedler_weight"] = "kappa"
select_edges(g, budget, **kw)
times, cpu = [], []
for _ in range(int(reps)):
    t0, c0 = time.perf_counter(), time.process_time()
    r = select_edges(g, budget, **kw)
    times.append(time.perf_counter() - t0)
    cpu.append(time.process_time() - c0)
print(json.dumps({"times": times, "cpu": cpu, "value": r.value, "upper": r.upper_bound,
                  "selected": r.selected_edges.tolist()}))
"""

# MAC's in-process worker (runs in MAC's interpreter): the problem from an npz file, one untimed
# call, then REPS timed calls of MAC(...) + NaiveGreedy.subset + MAC.solve, as its g2o example.
MAC_WORKER = r"""
import contextlib, io, json, sys, time
from timeit import default_timer as timer
import numpy as np
from mac.solvers import MAC, NaiveGreedy
from mac.utils.graphs import Edge
d = np.load(sys.argv[1])
reps = int(sys.argv[2])
n, k = int(d["n"]), int(d["k"])
fixed = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["fi"], d["fj"], d["fw"])]
cand = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["ci"], d["cj"], d["cw"])]

def run():
    t0, c0 = timer(), time.process_time()
    mac = MAC(fixed, cand, n, fiedler_method="tracemin_cholesky")
    with contextlib.redirect_stdout(io.StringIO()):
        w_init = NaiveGreedy(cand).subset(k)
    t1 = timer()
    result, unrounded, upper = mac.solve(k, w_init, max_iters=20, rounding="nearest", use_cache=True)
    t2 = timer()
    return mac, result, upper, t2 - t0, t2 - t1, time.process_time() - c0

run()
times, solve_times, cpu = [], [], []
for _ in range(reps):
    mac, result, upper, t, ts, c = run()
    times.append(t)
    solve_times.append(ts)
    cpu.append(c)
ours = np.asarray(d["posecrb"][0], dtype=float)
print(json.dumps({"times": times, "solve_times": solve_times, "cpu": cpu, "selected": np.flatnonzero(result).tolist(),
                  "upper": float(upper), "l2": float(mac.evaluate_objective(result)),
                  "l2_posecrb": float(mac.evaluate_objective(ours))}))
"""

# MAC as a whole process: import, load the npz problem, build, solve, print lambda_2.
MAC_WHOLE = r"""
import contextlib, io, sys
import numpy as np
from mac.solvers import MAC, NaiveGreedy
from mac.utils.graphs import Edge
d = np.load(sys.argv[1])
n, k = int(d["n"]), int(d["k"])
fixed = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["fi"], d["fj"], d["fw"])]
cand = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["ci"], d["cj"], d["cw"])]
mac = MAC(fixed, cand, n, fiedler_method="tracemin_cholesky")
with contextlib.redirect_stdout(io.StringIO()):
    w_init = NaiveGreedy(cand).subset(k)
result, unrounded, upper = mac.solve(k, w_init, max_iters=20, rounding="nearest", use_cache=True)
print(float(mac.evaluate_objective(result)), float(upper))
"""


def _json_line(stdout: str) -> dict:
    lines = [ln for ln in stdout.splitlines() if ln.startswith("{")]
    return json.loads(lines[-1]) if lines else {}


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def _goal(ok: bool) -> str:
    return "met" if ok else "MISSED"


def write_problem(g, split, ks: list[int], ours: list[np.ndarray], path: Path) -> None:
    """The problem as MAC takes it: fixed and candidate edges (internal indices) with kappa, the
    budgets ``ks`` (``k``: the first) and posecrb's selection at each (edge indices -> 0/1 rows)."""
    cand = split.candidates
    sel = np.zeros((len(ks), cand.size))
    for row, selected in enumerate(ours):
        sel[row, np.searchsorted(cand, selected)] = 1.0
    np.savez(path, n=g.n, k=ks[0], ks=np.array(ks), fi=g.src[split.fixed], fj=g.dst[split.fixed],
             fw=g.kappa[split.fixed], ci=g.src[cand], cj=g.dst[cand], cw=g.kappa[cand], posecrb=sel)


def in_process(programs: dict, rounds: int) -> dict[str, list[dict]]:
    """Alternate the worker processes (no extra warm-up: each worker makes its own untimed call)."""
    runs = alternate(programs, rounds, warmup=False)
    out: dict[str, list[dict]] = {}
    for name, rs in runs.items():
        bad = [r for r in rs if not r.ok]
        if bad:
            raise RuntimeError(f"{name} worker failed ({bad[0].status}): {bad[0].stderr[-2000:]}")
        out[name] = [_json_line(r.stdout) for r in rs]
    return out


def speed(names: list[str], budget: str, args, mac_py: str | None) -> None:
    from posecrb.selection import FiedlerObjective, parse_budget, select_edges, split_edges

    env = child_env(args.threads or None)
    py = sys.executable
    cmd = posecrb_command(args.posecrb)
    tally = []
    print(f"fiedler relax against MAC at {budget} of the loop closures; in-process: median of {args.rounds} "
          f"alternating worker processes x {args.reps} timed calls; whole process: median of {args.rounds} "
          "alternating runs after one untimed run each")
    print(f"{'dataset':10s} {'K':>5s} | {'MAC [s]':>8s} {'(solve)':>8s} {'ours [s]':>8s} {'ratio':>6s} | "
          f"{'MAC cpu':>8s} {'ours cpu':>8s} | {'MAC proc':>8s} {'ours proc':>9s} {'ratio':>6s} | "
          f"{'λ2 MAC':>12s} {'λ2 ours':>12s} {'(MAC eval)':>12s} {'(ours by MAC)':>13s} | {'ub MAC':>10s} "
          f"{'ub ours':>10s} | goal")
    for name in names:
        g = load(datasets.resolve(name))
        split = split_edges(g)
        k = parse_budget(budget, split.candidates.size)
        ours = select_edges(g, budget, objective="fiedler", method="relax", fiedler_weight="kappa", split=split)
        lam = FiedlerObjective(g, g.kappa, 0)
        with tempfile.TemporaryDirectory() as tmp:
            prob = Path(tmp) / "problem.npz"
            write_problem(g, split, [k], [ours.selected_edges], prob)
            programs = {"posecrb": lambda: run_process([py, "-c", OURS_WORKER, name, budget, "fiedler", "relax", "0",
                                                        str(args.reps)], env=env)}
            whole = {"posecrb": lambda: run_process([*cmd, "select", name, "--budget", budget, "--objective",
                                                     "fiedler", "--method", "relax", "--format", "json"], env=env)}
            if mac_py:
                programs["MAC"] = lambda: run_process([mac_py, "-c", MAC_WORKER, str(prob), str(args.reps)], env=env)
                whole["MAC"] = lambda: run_process([mac_py, "-c", MAC_WHOLE, str(prob)], env=env)
            inproc = in_process(programs, args.rounds)
            procs = alternate(whole, args.rounds)
        t_ours = _median([t for w in inproc["posecrb"] for t in w["times"]])
        c_ours = _median([t for w in inproc["posecrb"] for t in w["cpu"]])
        p_ours = median_wall(procs["posecrb"])
        if not mac_py:
            print(f"{name:10s} {k:5d} | {'-':>8s} {'-':>8s} {t_ours:8.3f} {'-':>6s} | {'-':>8s} {c_ours:8.3f} | "
                  f"{'-':>8s} {p_ours:9.3f} {'-':>6s} | {'-':>12s} {ours.value:12.8g} {'-':>12s} {'-':>13s} | "
                  f"{'-':>10s} {ours.upper_bound:10.6g} | -")
            continue
        m = inproc["MAC"][-1]
        t_mac = _median([t for w in inproc["MAC"] for t in w["times"]])
        t_mac_solve = _median([t for w in inproc["MAC"] for t in w["solve_times"]])
        c_mac = _median([t for w in inproc["MAC"] for t in w["cpu"]])
        p_mac = median_wall(procs["MAC"])
        x = np.zeros(g.m)
        x[np.union1d(split.fixed, split.candidates[m["selected"]])] = 1.0
        l2_mac = lam.value(x)
        ok = t_ours <= t_mac and ours.value >= l2_mac * (1 - 1e-9)
        tally.append(ok)
        print(f"{name:10s} {k:5d} | {t_mac:8.3f} {t_mac_solve:8.3f} {t_ours:8.3f} {t_ours / t_mac:6.2f} | "
              f"{c_mac:8.3f} {c_ours:8.3f} | {p_mac:8.3f} {p_ours:9.3f} {p_ours / p_mac:6.2f} | "
              f"{l2_mac:12.8g} {ours.value:12.8g} "
              f"{m['l2']:12.8g} {m['l2_posecrb']:13.8g} | {m['upper']:10.6g} {ours.upper_bound:10.6g} | "
              f"{_goal(ok)}", flush=True)
    if tally:
        print(f"goal, fiedler relax at most MAC's in-process time with λ2 at least MAC's: "
              f"{sum(tally)}/{len(tally)} met")

    print(f"\ntree relax against its own greedy at {budget} (and greedy --certify: the same two outputs, value and "
          "a relaxation bound); in-process and whole process as above")
    print(f"{'dataset':10s} {'K':>5s} | {'greedy':>8s} {'certify':>8s} {'relax':>8s} {'ratio':>6s} | "
          f"{'cpu greedy':>10s} {'certify':>8s} {'relax':>8s} | {'greedy proc':>11s} {'certify proc':>12s} "
          f"{'relax proc':>10s} | {'value greedy':>14s} {'value relax':>14s} | {'ub greedy':>12s} "
          f"{'ub certify':>12s} {'ub relax':>12s} | goal")
    tally = []
    for name in names:
        g = load(datasets.resolve(name))
        k = parse_budget(budget, split_edges(g).candidates.size)
        programs = {label: (lambda method=method, certify=certify: run_process(
            [py, "-c", OURS_WORKER, name, budget, "tree", method, certify, str(args.reps)], env=env))
            for label, method, certify in (("greedy", "greedy", "0"), ("certify", "greedy", "1"),
                                           ("relax", "relax", "0"))}
        whole = {label: (lambda extra=extra: run_process([*cmd, "select", name, "--budget", budget, *extra,
                                                          "--format", "json"], env=env))
                 for label, extra in (("greedy", []), ("certify", ["--certify"]), ("relax", ["--method", "relax"]))}
        inproc = in_process(programs, args.rounds)
        procs = alternate(whole, args.rounds)
        t = {label: _median([x for w in ws for x in w["times"]]) for label, ws in inproc.items()}
        c = {label: _median([x for w in ws for x in w["cpu"]]) for label, ws in inproc.items()}
        p = {label: median_wall(rs) for label, rs in procs.items()}
        last = {label: ws[-1] for label, ws in inproc.items()}
        ok = t["relax"] <= t["greedy"] and last["relax"]["value"] >= last["greedy"]["value"]
        tally.append(ok)
        print(f"{name:10s} {k:5d} | {t['greedy']:8.3f} {t['certify']:8.3f} {t['relax']:8.3f} "
              f"{t['relax'] / t['greedy']:6.2f} | {c['greedy']:10.3f} {c['certify']:8.3f} {c['relax']:8.3f} | "
              f"{p['greedy']:11.3f} {p['certify']:12.3f} {p['relax']:10.3f} | "
              f"{last['greedy']['value']:14.10g} {last['relax']['value']:14.10g} | {last['greedy']['upper']:12.8g} "
              f"{last['certify']['upper']:12.8g} {last['relax']['upper']:12.8g} | {_goal(ok)}", flush=True)
    print(f"goal, tree relax at most tree greedy's in-process time with a value at least greedy's: "
          f"{sum(tally)}/{len(tally)} met")


# ---- --quality: what the selections are worth for SLAM ------------------------------------------------

QUALITY_DRIVER = r"""
import contextlib, io, json, sys
import numpy as np
from mac.solvers import MAC, NaiveGreedy
from mac.utils.graphs import Edge
d = np.load(sys.argv[1])
n = int(d["n"])
fixed = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["fi"], d["fj"], d["fw"])]
cand = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["ci"], d["cj"], d["cw"])]
mac = MAC(fixed, cand, n, fiedler_method="tracemin_cholesky")
out = []
for k, ours in zip(d["ks"], d["posecrb"]):
    with contextlib.redirect_stdout(io.StringIO()):
        w_init = NaiveGreedy(cand).subset(int(k))
    result, unrounded, upper = mac.solve(int(k), w_init, max_iters=20, rounding="nearest", use_cache=True)
    out.append({"selected": np.flatnonzero(result).tolist(), "upper": float(upper),
                "l2": float(mac.evaluate_objective(result)),
                "l2_posecrb": float(mac.evaluate_objective(np.asarray(ours, dtype=float)))})
print(json.dumps(out))
"""


def quality(names: list[str], budgets: list[str], mac_py: str, env: dict) -> None:
    from posecrb.experiments.sparsify import _evaluate, trajectory_error
    from posecrb.selection import FiedlerObjective, parse_budget, select_edges, split_edges
    from posecrb.solver import solve
    from posecrb.solver.estimate import Estimate

    def slam(graph, context, keep_idx):
        keep = np.zeros(graph.m, dtype=bool)
        keep[keep_idx] = True
        ev = _evaluate(context, keep)
        sol = solve(ev.pop("pruned"), anchor=0)
        ref = context["reference"]
        return ev, trajectory_error(sol.rot, sol.trans, ref.rot, ref.trans).ate_trans

    print(f"\nquality: {'dataset':11s} {'budget':>6s} {'K':>5s} | {'λ2 MAC*':>12s} {'λ2 ours':>12s} | "
          f"{'tree MAC':>10s} {'tree ours':>10s} {'tree greedy':>11s} | {'FIM MAC':>10s} {'FIM ours':>10s} "
          f"{'FIM greedy':>10s} | {'ATE MAC':>8s} {'ATE ours':>8s} {'ATE greedy':>10s}")
    for name in names:
        g = load(datasets.resolve(name))
        split = split_edges(g)
        cand = split.candidates
        full = solve(g, anchor=0)
        ref = Estimate(full.rot, full.trans, "solve", bool(full.certified), float(full.objective), None)
        context = {"graph": g, "reference": ref, "anchor": 0}
        ks = [parse_budget(b, cand.size) for b in budgets]
        ours = [select_edges(g, b, objective="fiedler", method="relax", fiedler_weight="kappa", split=split)
                for b in budgets]
        with tempfile.TemporaryDirectory() as tmp:
            prob = Path(tmp) / "problem.npz"
            write_problem(g, split, ks, [r.selected_edges for r in ours], prob)
            run = run_process([mac_py, "-c", QUALITY_DRIVER, str(prob)], env=env)
            if not run.ok:
                raise RuntimeError(f"MAC failed ({run.status}): {run.stderr[-2000:]}")
            mac_out = json.loads(run.stdout.splitlines()[-1])
        lam = FiedlerObjective(g, g.kappa, 0)
        for b, k, r, m in zip(budgets, ks, ours, mac_out):
            mac_keep = np.union1d(split.fixed, cand[m["selected"]])
            x = np.zeros(g.m)
            x[mac_keep] = 1.0
            greedy = select_edges(g, b, split=split)
            ev_mac, ate_mac = slam(g, context, mac_keep)
            ev_ours, ate_ours = slam(g, context, r.kept_edges)
            ev_gr, ate_gr = slam(g, context, greedy.kept_edges)
            print(f"quality: {name:11s} {b:>6s} {k:5d} | {lam.value(x):12.8g} {r.value:12.8g} | "
                  f"{ev_mac['tree']:10.6g} {ev_ours['tree']:10.6g} {ev_gr['tree']:11.6g} | "
                  f"{ev_mac['fim_logdet']:10.6g} {ev_ours['fim_logdet']:10.6g} {ev_gr['fim_logdet']:10.6g} | "
                  f"{ate_mac:8.3g} {ate_ours:8.3g} {ate_gr:10.3g}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = process_parser(__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--budget", default="20%", help="K or P%% of the candidates [default: 20%%]")
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds (median) [default: 5]")
    ap.add_argument("--reps", type=int, default=3, help="timed calls per in-process worker [default: 3]")
    ap.add_argument("--quality", action="store_true", help="also the SLAM quality table (slow: certified solves)")
    ap.add_argument("--budgets", default="10%,20%,50%", help="budgets of --quality [default: 10%%,20%%,50%%]")
    args = ap.parse_args(argv)
    mac_py, why = mac_python()
    names = args.names or list(SPEED_DATASETS)
    missing = [n for n in names if not _resolvable(n)]
    if missing:
        print(f"skipped: dataset(s) not found: {', '.join(missing)} (set $POSECRB_DATA)")
        return 0
    print_header("posecrb selection vs MAC", args.threads or None, [
        f"MAC = {mac_build_info(mac_py)}" if mac_py else f"MAC skipped: {why}",
        "command: " + " ".join(["python", "benchmarks/mac_compare.py", *(argv if argv is not None else sys.argv[1:])]),
    ])
    speed(names, args.budget, args, mac_py)
    if args.quality:
        if not mac_py:
            print(f"\nquality table skipped: {why}")
        else:
            quality(args.names or list(QUALITY_DATASETS), [b for b in args.budgets.split(",") if b], mac_py,
                    child_env(args.threads or None))
    return 0


def _resolvable(name: str) -> bool:
    try:
        datasets.resolve(name)
    except Exception:
        return False
    return True


if __name__ == "__main__":
    sys.exit(main())
