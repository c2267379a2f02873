"""One BLAS thread against all, where posecrb chooses (posecrb/linalg/threads.py).

On a noisy grid (benchmarks/grids.py; default the 2D grid of 30,276 poses), alternating the two
settings run by run, each in a fresh process:

  solve    posecrb.solver.solve(load(FILE)) in-process: "1" as the library runs it (every BLAS at
           one thread, except CHOLMOD's in the M_red factorizations of 3D graphs >= 10,000
           poses and 2D >= 50,000), "all" with CHOLMOD's BLAS on every core throughout (numpy's/scipy's still at
           one thread): wall and CPU seconds, Hessian-vector products and the objective
  selinv   the selected inversion (posecrb.linalg.selinv.SelectedInverse) of the FIM at the
           file's vertices (after a warm-up call that compiles the kernels; with
           ``--absolute-terms`` it also sums the log-det's accuracy bound, as ``fim`` does):
           numpy's/scipy's OpenBLAS at "1" thread throughout, on "all" cores in every wide
           supernode, or as the "library" runs it (the supernodes of at least 10^9 flops on the
           cores no other process keeps busy, the rest at one thread)
  logdet   the FIM log-det (posecrb.models.paper.fim: analysis + factorization) with CHOLMOD's
           BLAS at 1 thread or at every core (SymbolicCholesky's ``threaded``, which the library
           sets only for the block matrices of 3D graphs >= 10,000 poses and 2D >= 50,000)

  greedy   posecrb.selection.select_edges(load(FILE), --budget) with the tree objective (the
           incremental greedy; after a warm-up selection of 10 edges that compiles the kernels):
           "1" with every step fused in one compiled call on one thread, "library" as posecrb runs
           it (each step on two threads of its own when two cores are free and the factor splits,
           posecrb.selection.greedy): wall and CPU seconds, the select stage, the refreshes and
           the value (the same bit for bit)

  openmp   the solver's M_red factorization as the library runs it (median of 3 per process):
           "team" with CHOLMOD's own OpenMP team (its compile-time size, 4 threads in Debian's
           SuiteSparse 5), "library" with it off as in every factorization of the library
           (posecrb.linalg.threads.cholmod_openmp_serial); also the process's voluntary context
           switches

  load     the solver's M_red factorization (median of 3 per process), next to ``--hogs K``
           processes that never sleep (started for the whole run): "1" thread, "all" threads,
           and "library", the library's choice (posecrb.linalg.threads.load_aware_threads: the
           threads of CHOLMOD's BLAS, fewer when other processes keep cores busy); e.g.
           ``--what load --dim 3 --poses 20000 --hogs 1`` and the same with ``--hogs 0``

Usage: python benchmarks/threads.py [--dim 2] [--poses 30000] [--rounds 2]
       [--what solve,selinv,logdet,greedy,openmp,load] [--hogs K] [--absolute-terms] [--budget K|P%]
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
elif what == "greedy":
    import posecrb.selection.greedy as sel
    from posecrb.selection.select import select_edges
    if threads == "1":
        sel._two_threads_allowed = lambda k: False
    select_edges(g, 10)
    t, c = time.perf_counter(), time.process_time()
    r = select_edges(g, os.environ["BENCH_BUDGET"])
    out = {"wall": time.perf_counter() - t, "cpu": time.process_time() - c, "value": r.value,
           "select": r.times["select"], "refreshes": r.stats["refreshes"], "steps": r.budget}
    # the factor the greedy updates (the full graph's pattern) and where its tree splits
    import numpy as np
    from posecrb.selection import tree_objective
    pathchol, kernels = sel._compiled()
    obj = tree_objective(g)
    pf = pathchol.PathFactor(obj.evaluate(np.ones(g.m)).data[0])
    top, mid = kernels.subtree_split(pf.indptr, pf.indices, pf.parent, sel.SPLIT_SHARE)
    out["factor"] = {"blocks": len(obj.blocks), "entries": int(pf.indptr[-1]), "columns": pf.n,
                     "trunk": pf.n - top if top >= 0 else None,
                     "trunk_entries": int(pf.indptr[-1] - pf.indptr[top]) if top >= 0 else None}
elif what in ("openmp", "load"):
    # the solver's M_red factorization, three times: "openmp" toggles CHOLMOD's own OpenMP team,
    # "load" the threads of its BLAS
    import contextlib, resource, statistics
    from posecrb.linalg import cholesky
    from posecrb.solver.problem import Problem
    p = Problem.from_graph(g)
    p._full_parts()
    sym = p._full_symbolic
    if what == "openmp" and threads == "team":
        cholesky.cholmod_openmp_serial = contextlib.nullcontext
    if what == "load":
        sym.threaded = threads != "1"
        if threads == "all":
            cholesky.load_aware_threads = contextlib.nullcontext
    M = p.full_matrix(None, 1e-3)
    walls = []
    c = time.process_time()
    switches = resource.getrusage(resource.RUSAGE_SELF).ru_nvcsw
    for _ in range(3):
        t = time.perf_counter()
        sym.factor(M)
        walls.append(time.perf_counter() - t)
    out = {"wall": statistics.median(walls), "cpu": (time.process_time() - c) / 3, "threaded": sym.threaded,
           "switches": (resource.getrusage(resource.RUSAGE_SELF).ru_nvcsw - switches) / 3}
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
        terms = os.environ.get("BENCH_ABSOLUTE_TERMS") == "1"
        f = fim_symbolic(fim).factor(fim.matrix)
        selinv.SelectedInverse(f, absolute_terms=terms)
        # "1": every supernode at one thread; "all": every wide supernode on every core;
        # "library": the largest ones on the cores no other process keeps busy
        if threads == "1":
            th.python_blas_usable_threads = lambda: 1
        elif threads == "all":
            selinv._THREADED_FLOPS = 0.0
            th.python_blas_usable_threads = lambda: os.cpu_count() or 1
        t, c = time.perf_counter(), time.process_time()
        sel = selinv.SelectedInverse(f, absolute_terms=terms)
        out = {"wall": time.perf_counter() - t, "cpu": time.process_time() - c,
               "terms": sel.absolute_terms}
        # flops of the wide supernodes (w columns, s rows below): the inversion's dtrsm, dpotri,
        # dsymm, dgemm; the accuracy bound's dsyrk, dlauum, dtrmm; and those of the threaded ones
        import numpy as np
        bounds = selinv.supernode_bounds(sel.indptr, sel.indices)
        w = np.diff(bounds).astype(float)
        s_ = (sel.indptr[bounds[:-1] + 1] - sel.indptr[bounds[:-1]]).astype(float) - w
        wide = w >= selinv._WIDE
        base = selinv._supernode_flops(w, s_)
        extra = s_**2 * w + s_ * w**2 + w**3 / 3
        big = wide & (base >= selinv._THREADED_FLOPS)
        out["gflop"] = {"inversion": float(base[wide].sum()) / 1e9, "bound": float(extra[wide].sum()) / 1e9,
                        "inversion_threaded": float(base[big].sum()) / 1e9}
print(json.dumps(out))
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dim", type=int, default=2, choices=(2, 3))
    ap.add_argument("--poses", type=int, default=30000)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--what", default="solve,selinv,logdet")
    ap.add_argument("--hogs", type=int, default=0, help="busy processes next to the measured ones (--what load)")
    ap.add_argument("--absolute-terms", action="store_true",
                    help="--what selinv: also sum the log-det's accuracy bound (as fim and bounds do)")
    ap.add_argument("--budget", default="2000", help="--what greedy: edges to select (K or P%%)")
    ap.add_argument("--cache-dir", default=None)
    args = ap.parse_args(argv)
    path = grid_file(args.dim, args.poses, directory=args.cache_dir)
    print_header(f"one BLAS thread against all (benchmarks/threads.py), {path.name}, {args.hogs} busy processes")
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.hogs)]
    try:
        _measure(args, path)
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    return 0


def _measure(args: argparse.Namespace, path: Path) -> None:
    for what in args.what.split(","):
        settings = (("1", "all", "library") if what in ("load", "selinv") else ("1", "library") if what == "greedy"
                    else ("team", "library") if what == "openmp" else ("1", "all"))
        runs: dict[str, list[dict]] = {s: [] for s in settings}
        for k in range(args.rounds):
            for threads in (settings if k % 2 == 0 else settings[::-1]):
                env = child_env(threads=None)
                env["BENCH_ABSOLUTE_TERMS"] = "1" if args.absolute_terms else "0"
                env["BENCH_BUDGET"] = args.budget
                load = os.getloadavg()[0]
                r = subprocess.run([sys.executable, "-c", CHILD, what, str(path), threads], env=env,
                                   capture_output=True, text=True, check=False)
                if r.returncode:
                    print(f"{what} {threads}: failed: {r.stderr.strip()[-300:]}")
                    continue
                d = json.loads(r.stdout.strip().splitlines()[-1])
                d["load"] = load
                runs[threads].append(d)
                extra = (f", {d['hvp']} HVPs, objective {d['objective']:.10g}" if what == "solve" else
                         f", absolute terms {d['terms']:.10g}" if d.get("terms") is not None else
                         f", {d['steps']} steps, select {d['select']:.2f} s, {d['refreshes']} refreshes, "
                         f"value {d['value']!r}" if what == "greedy" else
                         f", {d['switches']:.0f} voluntary context switches per factorization, CHOLMOD's BLAS "
                         + ("threaded" if d["threaded"] else "at one thread") if what == "openmp" else "")
                if what == "greedy" and k == 0 and threads == settings[0]:
                    f = d["factor"]
                    print(f"  factor: {f['blocks']} Laplacian block(s), {f['entries']:,} entries in {f['columns']:,} "
                          f"columns; trunk above the two subtrees: "
                          + (f"{f['trunk']:,} columns, {f['trunk_entries']:,} entries" if f["trunk"] else "none"))
                if what == "selinv" and k == 0 and threads == settings[0]:
                    g = d["gflop"]
                    print(f"  wide supernodes: {g['inversion']:.1f} Gflop of inversion "
                          f"({g['inversion_threaded']:.1f} in the threaded ones), {g['bound']:.1f} Gflop more "
                          "for the accuracy bound")
                print(f"{what:7s} threads {threads:>7s}: wall {d['wall']:7.2f} s, CPU {d['cpu']:7.2f} s{extra} "
                      f"(load average {load:.1f} at the start, {time.strftime('%H:%M:%S')})", flush=True)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
