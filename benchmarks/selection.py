"""Measurement selection timings (posecrb.selection.select): greedy, certificate, engines, the fim objective.

Prints, for intel, city10000 and sphere2500 at 10%, 20% and 50% of the loop closures: the tree
objective's greedy time (median of REPEAT after a warm-up), its value, the certified ratio from
the submodular bound alone and with the relaxation bound (--certify) and that run's time;
then, at 20%, the greedy engines side by side (incremental/lazy x path/CHOLMOD), exact initial
gains (solves with the factor on small blocks, selected inversion otherwise) against random
projections, and the fim objective on sphere2500
(greedy, with and without the certified solve of the full graph that fixes the estimate).
Targets: tree greedy on city10000 at 20% <= 2 s; fim greedy on sphere2500 at 20% <= 30 s.
Timings on a shared machine are provisional.
Usage: python benchmarks/selection.py [--repeat K] [--fim-repeat K] [--skip-engines] [NAME ...]
"""
from __future__ import annotations

import argparse
import logging
import time

import numpy as np
from _common import median_time

from posecrb import load
from posecrb.core.timing import timed
from posecrb.datasets import search as datasets
from posecrb.selection import select_edges, split_edges, tree_objective
from posecrb.solver.estimate import get_estimate

TREE_DATASETS = ("intel", "city10000", "sphere2500")
BUDGETS = ("10%", "20%", "50%")


def main() -> None:
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=list(TREE_DATASETS))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--fim-repeat", type=int, default=1)
    ap.add_argument("--skip-engines", action="store_true")
    args = ap.parse_args()
    graphs = {n: load(datasets.resolve(n)) for n in args.names}

    print("tree objective, greedy (incremental, engine auto); ratio = certified ratio")
    print(f"{'dataset':12s} {'budget':>6s} {'K':>6s} {'greedy [s]':>10s} {'value':>12s} {'ratio(sub)':>10s} "
          f"{'certify [s]':>11s} {'ratio(FW)':>9s}")
    for name, g in graphs.items():
        for b in BUDGETS:
            t = median_time(lambda: select_edges(g, b), args.repeat)
            r = select_edges(g, b)
            t0 = time.perf_counter()
            c = select_edges(g, b, certify=True)
            tc = time.perf_counter() - t0
            print(f"{name:12s} {b:>6s} {r.budget:6d} {t:10.3f} {r.value:12.6g} {r.certified_ratio:10.4f} "
                  f"{tc:11.2f} {c.certified_ratio:9.4f}")
            if name == "city10000" and b == "20%":
                print(f"    target: city10000 tree greedy at 20% <= 2 s: {t:.3f} s")

    if not args.skip_engines:
        print("\ngreedy engines at 20% (same selection; median of REPEAT) and the first gains of every candidate")
        print(f"{'dataset':12s} {'incr/path':>10s} {'incr/cholmod':>12s} {'lazy/path':>10s} {'lazy/cholmod':>12s} "
              f"{'gains [s]':>10s} {'JL-64 [s]':>9s} {'JL rel.err':>10s}")
        for name, g in graphs.items():
            # the lazy greedy with CHOLMOD solves needs ~100 whole-factor solves per step on city10000
            # (minutes): one run there
            ts = [timed(lambda: select_edges(g, "20%", strategy=s, engine=e),
                        1 if (s, e) == ("lazy", "cholmod") and g.m > 5000 else args.repeat)[1]
                  for s, e in (("incremental", "path"), ("incremental", "cholmod"), ("lazy", "path"),
                               ("lazy", "cholmod"))]
            obj = tree_objective(g)
            split = split_edges(g)
            x = np.zeros(g.m)
            x[split.fixed] = 1.0
            st = obj.evaluate(x)
            t_sel = median_time(lambda: obj.gains(st, split.candidates), args.repeat)
            t_jl = median_time(lambda: obj.gains_projected(st, split.candidates, 64, np.random.default_rng(0)),
                               args.repeat)
            exact = obj.gains(st, split.candidates)
            est = obj.gains_projected(st, split.candidates, 64, np.random.default_rng(0))
            err = float(np.median(np.abs(est - exact) / exact))
            print(f"{name:12s} {ts[0]:10.3f} {ts[1]:12.3f} {ts[2]:10.3f} {ts[3]:12.3f} {t_sel:10.4f} "
                  f"{t_jl:9.4f} {err:10.3f}")

    if "sphere2500" in graphs:
        g = graphs["sphere2500"]
        t0 = time.perf_counter()
        ref = get_estimate(g, "solve")
        t_solve = time.perf_counter() - t0
        print(f"\nfim objective (frame-consistent FIM at the certified optimum), sphere2500; solve {t_solve:.2f} s")
        print(f"{'budget':>6s} {'K':>5s} {'greedy [s]':>10s} {'+ solve [s]':>11s} {'value':>12s} {'ratio(sub)':>10s}")
        for b in BUDGETS:
            r, t = timed(lambda: select_edges(g, b, objective="fim", reference=ref), args.fim_repeat,
                         warmup=args.fim_repeat > 1)
            print(f"{b:>6s} {r.budget:5d} {t:10.2f} {t + t_solve:11.2f} {r.value:12.6g} {r.certified_ratio:10.4f}")
            if b == "20%":
                print(f"    target: fim greedy on sphere2500 at 20% <= 30 s: {t + t_solve:.2f} s (with the solve)")


if __name__ == "__main__":
    main()
