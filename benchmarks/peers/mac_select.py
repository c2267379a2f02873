"""posecrb's measurement selection against MAC (Doherty et al. 2022), whole process against whole
process on the same problem (hyperfine).

MAC is not a dependency: $POSECRB_MAC_PYTHON names an interpreter that can ``import mac`` (see
benchmarks/harness.py); skipped without it. Both sides get the same problem: the odometry chain
(every edge between poses consecutive in id order) fixed, every other edge a candidate weighted by
its Langevin concentration kappa (MAC's weights), the budget K = 20% of the candidates rounded down
(--budget). The programs:

  posecrb   posecrb select FILE --budget K --objective fiedler --method relax --fixed PAIRS
            --format json (reads the g2o file; weighs by the rotation weight, 2 kappa in 2D)
  MAC       a MAC process that loads the problem from an npz file (it reads no g2o file), builds
            ``MAC(fixed, candidates, n, fiedler_method="tracemin_cholesky")`` and solves as its g2o
            example does (NaiveGreedy start, 20 Frank-Wolfe iterations, nearest rounding)

The check runs give lambda_2 of both selections by one evaluator (MAC's ``evaluate_objective``,
kappa weights), the upper bound each reports and the in-process time each reports of its own
selection (one run: posecrb's JSON ``times``, MAC's build and solve).
Goal (benchmarks/report.py): posecrb at most MAC's time, with lambda_2 at least MAC's.

Usage: POSECRB_MAC_PYTHON=... python benchmarks/peers/mac_select.py [--quick] [--budget 20%] [--runs K]
       [--warmup K] [--threads T] [--out DIR] [NAME ...]
"""
from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import _peer  # noqa: F401 -- benchmarks/ on sys.path
import harness
import numpy as np
from harness import Command, posecrb_cli
from suite import inputs

_MAC_PROBLEM = r"""
import contextlib, io, json, sys, time
import numpy as np
from mac.solvers import MAC, NaiveGreedy
from mac.utils.graphs import Edge
d = np.load(sys.argv[1])
n, k = int(d["n"]), int(d["k"])
fixed = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["fi"], d["fj"], d["fw"])]
cand = [Edge(int(i), int(j), float(w)) for i, j, w in zip(d["ci"], d["cj"], d["cw"])]
start = time.perf_counter()
mac = MAC(fixed, cand, n, fiedler_method="tracemin_cholesky")
"""
# The timed MAC program: build and solve as MAC's g2o example, print lambda_2 and the bound.
MAC_SOLVE = _MAC_PROBLEM + r"""
with contextlib.redirect_stdout(io.StringIO()):
    w_init = NaiveGreedy(cand).subset(k)
result, unrounded, upper = mac.solve(k, w_init, max_iters=20, rounding="nearest", use_cache=True)
seconds = time.perf_counter() - start
print(json.dumps({"l2": float(mac.evaluate_objective(result)), "upper": float(upper), "seconds": seconds,
                  "selected": np.flatnonzero(result).tolist()}))
"""
# Untimed: MAC's evaluator on posecrb's selection (0/1 per candidate, in the npz's ``ours``).
MAC_EVALUATE = _MAC_PROBLEM + r"""
print(json.dumps({"l2": float(mac.evaluate_objective(np.asarray(d["ours"], dtype=float)))}))
"""


def write_problem(graph, path: Path, pairs: Path, budget: str) -> tuple[np.ndarray, int]:
    """The problem of both sides: the fixed pairs file for posecrb, the npz for MAC. Returns the
    candidate edges (file positions) and K."""
    fixed = np.abs(graph.src - graph.dst) == 1
    candidates = np.flatnonzero(~fixed)
    k = int(candidates.size * float(budget.rstrip("%")) / 100) if budget.endswith("%") else int(budget)
    ids = graph.ids
    pairs.write_text("".join(f"{ids[i]} {ids[j]}\n" for i, j in zip(graph.src[fixed], graph.dst[fixed])))
    np.savez(path, n=graph.n, k=k, fi=graph.src[fixed], fj=graph.dst[fixed], fw=graph.kappa[fixed],
             ci=graph.src[candidates], cj=graph.dst[candidates], cw=graph.kappa[candidates],
             ours=np.zeros(candidates.size))
    return candidates, k


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__.splitlines()[0])
    ap.add_argument("--budget", default="20%", help="K or P%% of the candidates [default: 20%%]")
    ap.add_argument("names", nargs="*", help="datasets or grids [default: intel city10000]")
    args = harness.parse(ap, argv)
    mac, why = harness.mac_python()
    group = harness.start("mac", args, why)
    if group is None or mac is None:
        return 0
    import posecrb

    names = args.names or ([inputs.GRID_2D_SMALL] if args.quick else ["intel", "city10000"])
    with tempfile.TemporaryDirectory(prefix="posecrb-mac-") as tmp:
        for name, file in harness.found("mac", names):
            problem, pairs = Path(tmp) / f"{name}.npz", Path(tmp) / f"{name}-fixed.txt"
            candidates, k = write_problem(posecrb.load(file), problem, pairs, args.budget)
            entry = group.compare(name, [
                Command("posecrb", posecrb_cli("select", str(file), "--budget", str(k), "--objective",
                                               "fiedler", "--method", "relax", "--fixed", str(pairs), "--format",
                                               "json")),
                Command("MAC", (mac, "-c", MAC_SOLVE, str(problem)))])
            if entry is None:
                continue
            ours, theirs = entry["outputs"]["posecrb"].json(), entry["outputs"]["MAC"]
            theirs = harness.CheckRun(theirs.returncode, theirs.stdout.strip().splitlines()[-1], "", None).json()
            chosen = np.zeros(candidates.size)
            chosen[np.searchsorted(candidates, [edge for _, _, edge in ours["selected"]])] = 1.0
            with np.load(problem) as z:
                np.savez(problem, **{**dict(z), "ours": chosen})
            evaluated = harness.check_run(Command("evaluate", (mac, "-c", MAC_EVALUATE, str(problem))))
            l2_ours = evaluated.json().get("l2", math.nan) if evaluated.ok else math.nan
            entry["checks"].update(
                poses=ours.get("poses"), budget=k, candidates=int(candidates.size), posecrb_value=ours.get("value"),
                lambda2={"posecrb": l2_ours, "MAC": theirs.get("l2")},
                upper_bound={"posecrb": ours.get("upper_bound"), "MAC": theirs.get("upper")},
                in_process={"posecrb": sum(v for v in ours.get("times", {}).values() if isinstance(v, float)),
                            "MAC": theirs.get("seconds")})
    group.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
