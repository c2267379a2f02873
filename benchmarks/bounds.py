"""Parse and bounds timings per shared dataset, next to bare CHOLMOD factorizations.

Prints, for every dataset found: parse time, lb / ub / ub_lambda times as posecrb
reports them (median of REPEAT after a warm-up), and the time of calling
scikit-sparse's ``cholesky`` directly on the same two Laplacians (each with its
own analysis), which is the floor the lb computation is measured against.
Targets: parsing ais2klinik <= 0.25 s; lb <= 1.3x the bare factorizations.
Usage: python benchmarks/bounds.py [--repeat K] [NAME ...]
"""
from __future__ import annotations

from _common import dataset_args, median_time
from sksparse.cholmod import cholesky

from posecrb import load
from posecrb.models.paper.bounds import compute_bounds, weighted_laplacians


def main() -> None:
    args, files = dataset_args(__doc__.splitlines()[0], repeat=7)
    print(f"{'dataset':28s} {'n':>6s} {'m':>6s} {'parse':>8s} {'lb':>8s} {'bare':>8s} {'lb/bare':>7s} "
          f"{'ub':>8s} {'ub_lam':>8s}")
    for f in files:
        t_parse = median_time(lambda: load(f), args.repeat)
        g = load(f)
        b = compute_bounds(g, repeat=args.repeat)
        lap = weighted_laplacians(g)
        bare = median_time(lambda: (cholesky(lap.l_tau).logdet(), cholesky(lap.l_w).logdet()), args.repeat)
        t = b.times
        print(f"{g.name:28s} {g.n:6d} {g.m:6d} {t_parse:8.4f} {t['lb']:8.5f} {bare:8.5f} "
              f"{t['lb'] / bare:7.2f} {t['ub']:8.5f} {t['ub_lambda']:8.5f}")


if __name__ == "__main__":
    main()
