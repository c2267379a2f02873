"""One BLAS thread against all, where posecrb chooses (posecrb/linalg/threads.py).

On a noisy grid (benchmarks/grids.py; default the 2D grid of 30,276 poses), alternating the two
settings run by run, each in a fresh process:

  solve    posecrb.solver.solve(load(FILE)) in-process: "1" as the library runs it (every BLAS at
           one thread, except CHOLMOD's in the M_red factorizations of 3D graphs >= 10,000
           poses), "all" with CHOLMOD's BLAS on every core throughout (numpy's/scipy's still at
           one thread): wall and CPU seconds, Hessian-vector products and the objective
  selinv   the selected inversion (posecrb.linalg.selinv.SelectedInverse) of the FIM at the
           file's vertices, with numpy's/scipy's OpenBLAS at 1 thread or at every core (after a
           warm-up call that compiles the kernels)
  logdet   the FIM log-det (posecrb.models.paper.fim: analysis + factorization) with CHOLMOD's
           BLAS at 1 thread or at every core (SymbolicCholesky's ``threaded``, which the library
           sets only for the block matrices of 3D graphs >= 10,000 poses)

Usage: python benchmarks/threads.py [--dim 2] [--poses 30000] [--rounds 2] [--what solve,selinv,logdet]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _common import child_env, print_header
from grids import grid_file

CHILD = r"""
import json, os, sys, time
what, path, threads = sys.argv[1], sys.argv[2], sys.argv[3]
from posecrb.io import load
g = load(path)
out = {}
if what == "solve":
    import contextlib
    import posecrb.solver.solve
    ps = sys.modules["posecrb.solver.solve"]   # the package exports a function of the same name
    from posecrb.linalg import threads as th
    if threads == "all":
        @contextlib.contextmanager
        def python_blas_only(n):
            with th.python_blas().limit(limits=1):
                yield
        ps.solver_threads = python_blas_only
    solve = ps.solve
    t, c = time.perf_counter(), time.process_time()
    r = solve(g)
    out = {"wall": time.perf_counter() - t, "cpu": time.process_time() - c, "objective": r.objective,
           "hvp": r.hessian_vector_products, "certified": r.certified}
else:
    from posecrb.models.paper.fim import paper_fim, fim_symbolic
    fim = paper_fim(g, g.vertex_rot, g.vertex_trans, 0, "eq59", variant="consistent")
    if what == "logdet":
        t, c = time.perf_counter(), time.process_time()
        sym = fim_symbolic(fim)
        sym.threaded = threads == "all"
        f = sym.factor(fim.matrix)
        out = {"wall": time.perf_counter() - t, "cpu": time.process_time() - c}
    else:
        import scipy.linalg.blas
        from posecrb.linalg import selinv, threads as th
        f = fim_symbolic(fim).factor(fim.matrix)
        selinv.SelectedInverse(f)
        # the library limits it to one thread; lift that for the "all" setting
        if threads == "all":
            import contextlib

            class NoLimit:
                def limit(self, limits):
                    return contextlib.nullcontext()

            th.python_blas = NoLimit
        t, c = time.perf_counter(), time.process_time()
        selinv.SelectedInverse(f)
        out = {"wall": time.perf_counter() - t, "cpu": time.process_time() - c}
print(json.dumps(out))
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dim", type=int, default=2, choices=(2, 3))
    ap.add_argument("--poses", type=int, default=30000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--what", default="solve,selinv,logdet")
    ap.add_argument("--cache-dir", default=None)
    args = ap.parse_args(argv)
    path = grid_file(args.dim, args.poses, directory=args.cache_dir)
    print_header(f"one BLAS thread against all (benchmarks/threads.py), {path.name}")
    for what in args.what.split(","):
        runs: dict[str, list[dict]] = {"1": [], "all": []}
        for k in range(args.rounds):
            for threads in (("1", "all") if k % 2 == 0 else ("all", "1")):
                env = child_env(threads=None)
                load = os.getloadavg()[0]
                r = subprocess.run([sys.executable, "-c", CHILD, what, str(path), threads], env=env,
                                   capture_output=True, text=True, check=False)
                if r.returncode:
                    print(f"{what} {threads}: failed: {r.stderr.strip()[-300:]}")
                    continue
                d = json.loads(r.stdout.strip().splitlines()[-1])
                d["load"] = load
                runs[threads].append(d)
                extra = (f", {d['hvp']} HVPs, objective {d['objective']:.10g}" if what == "solve" else "")
                print(f"{what:7s} threads {threads:>3s}: wall {d['wall']:7.2f} s, CPU {d['cpu']:7.2f} s{extra} "
                      f"(load average {load:.1f} at the start, {time.strftime('%H:%M:%S')})", flush=True)
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
