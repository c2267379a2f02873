"""The selected inversion's two kernel paths on the shared datasets: numpy's block kernels against
the compiled (numba) ones, and which one a command should take.

For each g2o file: the paper FIM at the certified estimate, factored as `posecrb fim` factors it;
its supernodes, the entries of the ``Z_SS`` blocks the inversion gathers, the block kernels'
Python steps (``posecrb.linalg.selinv.inversion_steps``) and their measured time, the
compiled kernels' time once numba is loaded (in-process, median of --repeat after a warm-up), the
path `posecrb` takes, and how far the two paths' inverses and accuracy sums differ. Then numba's
cost in a fresh process: its import and the first call of the compiled kernels on a 2 x 2 matrix
(whole process minus the same process without the inversion, alternating, median). Last, for the
files the block kernels take, the whole `posecrb fim FILE --format json` with the default rule
against the compiled kernels forced (alternating run by run after a warm-up, median of --rounds).

Usage: python benchmarks/selinv_paths.py [--data-dir DIR] [--repeat K] [--rounds K] [NAME ...]
"""
from __future__ import annotations

import sys

import numpy as np
from _common import (
    alternate,
    child_env,
    data_dir,
    median_time,
    median_wall,
    print_header,
    process_parser,
    run_process,
    suite_files,
)

# the compiled kernels forced: no factor is cheap enough for the block kernels
FORCE_COMPILED = ("import sys, runpy; import posecrb.linalg.selinv as s; s._BLOCK_MAX_STEPS = -1.0; "
                  "sys.argv = ['posecrb', *sys.argv[1:]]; runpy.run_module('posecrb', run_name='__main__')")
NUMBA_COLD = ("import numpy as np, scipy.sparse as sp; import posecrb.linalg.selinv as s; "
              "from posecrb.linalg.cholesky import cholesky; s._BLOCK_MAX_STEPS = -1.0; "
              "s.SelectedInverse(cholesky(sp.csc_matrix(np.array([[2.0, 1.0], [1.0, 2.0]]))))")
NO_INVERSION = ("import numpy as np, scipy.sparse as sp; import posecrb.linalg.selinv as s; "
                "from posecrb.linalg.cholesky import cholesky; cholesky(sp.csc_matrix(np.array([[2.0, 1.0], "
                "[1.0, 2.0]])))")


def fim_factor(path):
    from posecrb.io import load
    from posecrb.models.paper.fim import fim_symbolic_choice, paper_fim
    from posecrb.solver.estimate import get_estimate

    graph = load(path)
    est = get_estimate(graph, "solve")
    fim = paper_fim(graph, est.rot, est.trans)
    symbolic, _ = fim_symbolic_choice(fim, "auto")
    return graph, symbolic.factor(fim.matrix, name="paper FIM")


def main() -> None:
    ap = process_parser(__doc__.splitlines()[0], with_data_dir=True, repeat=5)
    ap.add_argument("--rounds", type=int, default=5, help="whole-process rounds (median) [default: 5]")
    ap.add_argument("names", nargs="*")
    args = ap.parse_args()
    import logging

    from posecrb.linalg import selinv

    logging.getLogger("posecrb").setLevel(logging.ERROR)
    files = suite_files(data_dir(args.data_dir), args.names)
    if not files:
        sys.exit("no g2o files: pass --data-dir or set POSECRB_DATA")
    print_header("selected inversion: block kernels against compiled kernels", threads=args.threads)
    print(f"# rule: block kernels where supernodes + Z_SS entries / {selinv._ENTRIES_PER_STEP} "
          f"<= {selinv._BLOCK_MAX_STEPS:.0f} steps")
    print("\n| dataset | FIM rows | supernodes | Z_SS entries | steps | block s | compiled s (numba loaded) "
          "| path | max entry difference / max entry | accuracy sum, relative difference |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    budget = selinv._BLOCK_MAX_STEPS
    block_files = []
    for path in files:
        graph, factor = fim_factor(path)
        sel = selinv.SelectedInverse(factor, absolute_terms=True)   # loads numba when the rule says so
        bounds = selinv.supernode_bounds(sel.indptr, sel.indices)
        width = np.diff(bounds)
        below = sel.indptr[bounds[:-1] + 1] - sel.indptr[bounds[:-1]] - width
        steps = selinv.inversion_steps(sel.indptr, bounds)
        times, results = {}, {}
        for name, value in (("block", np.inf), ("compiled", -1.0)):
            selinv._BLOCK_MAX_STEPS = value
            times[name] = median_time(lambda: selinv.SelectedInverse(factor, absolute_terms=True), args.repeat)
            results[name] = selinv.SelectedInverse(factor, absolute_terms=True)
        selinv._BLOCK_MAX_STEPS = budget
        block, compiled = results["block"], results["compiled"]
        entry_diff = float(np.max(np.abs(block.zval - compiled.zval)) / np.max(np.abs(compiled.zval)))
        sum_diff = abs(block.absolute_terms - compiled.absolute_terms) / compiled.absolute_terms
        chosen = "block" if steps <= budget else "compiled"
        if chosen == "block":
            block_files.append(path)
        print(f"| {graph.name} | {sel.n:,} | {width.size:,} | {int(np.sum(below * (below + 1) // 2)):,} "
              f"| {steps:,.0f} | {times['block']:.3f} | {times['compiled']:.3f} | {chosen} "
              f"| {entry_diff:.1e} | {sum_diff:.1e} |", flush=True)

    env = child_env(args.threads)
    runs = alternate({"with": lambda: run_process([sys.executable, "-c", NUMBA_COLD], env=env),
                      "without": lambda: run_process([sys.executable, "-c", NO_INVERSION], env=env)}, args.rounds)
    cold = median_wall(runs["with"]) - median_wall(runs["without"])
    print(f"\nnumba's import and first call in a fresh process: {cold:.3f} s "
          f"(median {median_wall(runs['with']):.3f} s with a compiled inversion of a 2 x 2 matrix, "
          f"{median_wall(runs['without']):.3f} s without; {args.rounds} alternating rounds)")

    if block_files:
        print("\nwhole process, `posecrb fim FILE --format json`, median of alternating rounds:\n")
        print("| dataset | default rule s | compiled forced s | saved s |")
        print("|---|---|---|---|")
    for path in block_files:
        argv = ["fim", str(path), "--format", "json"]
        runs = alternate({"default": lambda: run_process([sys.executable, "-m", "posecrb", *argv], env=env),
                          "compiled": lambda: run_process([sys.executable, "-c", FORCE_COMPILED, *argv], env=env)},
                         args.rounds)
        if not all(r.ok for rs in runs.values() for r in rs):
            bad = next(r for rs in runs.values() for r in rs if not r.ok)
            sys.exit(f"{path.stem}: {bad.status}: {bad.stderr[-500:]}")
        a, b = median_wall(runs["default"]), median_wall(runs["compiled"])
        print(f"| {path.stem} | {a:.3f} | {b:.3f} | {b - a:.3f} |", flush=True)


if __name__ == "__main__":
    main()
