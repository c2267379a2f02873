"""sed-model (SE(d)^n) FIM and CRLB timings per shared dataset with vertices.

For every dataset with VERTEX lines (or the NAMEs given) prints, median of REPEAT runs (after a
warm-up run), at the file's vertices:
  build     FIM assembly: information conversion (4.3), residuals, Jr^{-1} Ad blocks (4.7), COO (4.6)
  rank      rank/nullity certificate: CHOLMOD analysis + factorization of F on the free poses
  anchored  sed_crlb trace only (selected inversion on the reused factor), excluding build+rank
  quotient  sed_crlb(quotient=True, per_pose=True): every per-pose block of F^+, excluding build+rank
Usage: python benchmarks/sed.py [--repeat K] [NAME ...]
"""
from __future__ import annotations

import statistics

from _common import dataset_args, median_time

from posecrb import load
from posecrb.models.sed.crlb import sed_crlb
from posecrb.models.sed.fim import sed_fim


def main() -> None:
    args, paths = dataset_args(__doc__.splitlines()[0], repeat=3)
    paths = sorted(paths)
    print(f"{'dataset':24s} {'n':>6s} {'nq':>6s} {'null':>4s} {'build':>7s} {'rank':>7s} "
          f"{'anchored':>8s} {'quotient':>8s}  trace(anchored)  trace(quotient)")
    for path in paths:
        g = load(path)
        if not g.has_vertices:
            continue
        r, t = g.vertex_rot, g.vertex_trans
        fim = sed_fim(g, r, t)
        runs = [sed_fim(g, r, t).times for _ in range(args.repeat)]
        t_build = statistics.median(x["fim_build"] for x in runs)
        t_rank = statistics.median(x["fim_rank"] for x in runs)
        a = sed_crlb(g, r, t, fim=fim)
        t_a = median_time(lambda: sed_crlb(g, r, t, fim=fim), args.repeat)
        qres = sed_crlb(g, r, t, fim=fim, quotient=True, per_pose=True)
        t_q = median_time(lambda: sed_crlb(g, r, t, fim=fim, quotient=True, per_pose=True), args.repeat)
        print(f"{g.name:24s} {g.n:6d} {g.n * g.q:6d} {fim.nullity:4d} {t_build:7.3f} {t_rank:7.3f} "
              f"{t_a:8.3f} {t_q:8.3f}  {a.trace_crlb:15.6g}  {qres.trace_crlb:15.6g}", flush=True)


if __name__ == "__main__":
    main()
