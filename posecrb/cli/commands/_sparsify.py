"""`posecrb experiment sparsify FILE`: selection methods vs budget, and the pruned graphs' solutions."""
from __future__ import annotations

import logging
import time

import click

from ...core.choices import EXECUTORS, FIXED_RULES
from ...core.errors import UsageError
from ...core.folders import output_folder
from ...core.provenance import dataset_entry, run_record
from ...core.status import Status, log_status
from ...experiments.sparsify import (
    DEFAULT_BUDGETS,
    DEFAULT_METHODS,
    QUICK_BUDGETS,
    sparsify_experiment,
)
from ...report.outputs import write_experiment_outputs
from ...report.render import print_rows
from ..options import (
    SEED_RANGE,
    PlainInt,
    anchor_option,
    data_dir_option,
    executor_settings,
    format_option,
    load_dataset,
    plot_target,
)
from ..paths import FIGURE_EXTENSIONS, Command, DatasetArg, InputFile, OutputDir, OutputFile
from ..progress import progress

log = logging.getLogger("posecrb")

COLUMNS = ["budget_spec", "budget", "method", "value", "upper_bound", "certified_ratio", "time_select", "tree",
           "fiedler", "fim_logdet", "crlb_trace", "certified", "ate_trans", "ate_rot_deg", "rpe_trans",
           "rpe_rot_deg"]
HEADERS = {"budget_spec": "budget", "budget": "K", "upper_bound": "upper bound", "certified_ratio": "cert. ratio",
           "time_select": "time (s)", "tree": "tree lb (75)", "fiedler": "λ2", "fim_logdet": "FIM logdet",
           "crlb_trace": "tr CRLB", "certified": "cert.", "ate_trans": "ATE t", "ate_rot_deg": "ATE R [°]",
           "rpe_trans": "RPE t", "rpe_rot_deg": "RPE R [°]"}


# Budgets x methods: every pair is a selection and a certified solve of the pruned graph.
MAX_TASKS = 10000


@click.command("sparsify", cls=Command,
               short_help="Selection methods vs budget: bounds, certificates, ATE of the pruned graphs.")
@click.argument("file", type=DatasetArg())
@click.option("--budgets", default=None, metavar="LIST",
              help="Budgets, each K or P% of the loop closures (default 10%,20%,...,100%; --quick: 20%,50%).")
@click.option("--methods", default=None, metavar="LIST",
              help="[objective-]method list (default greedy,relax,fiedler-relax,random,naive).")
@click.option("--objective", default="tree", show_default=True, metavar="tree|fim|fiedler",
              help="Objective of the methods named without one.")
@click.option("--fixed", default="odometry", show_default=True, type=InputFile(FIXED_RULES),
              metavar="odometry|FILE", help="Fixed edges: the odometry chain, or a file of pose-id pairs 'i j'.")
@click.option("--certify", is_flag=True, help="Relaxation bound for greedy, random and naive too.")
@click.option("--max-iter", type=PlainInt(1, 100000), default=None, help="Relaxation iterations.")
@click.option("--seed", type=SEED_RANGE, default=0, show_default=True,
              help="Seed of random selections and Madow rounding.")
@click.option("--jobs", type=PlainInt(1, 1024), default=1, show_default=True,
              help="Worker processes (local pool, or LocalCluster size for --executor dask).")
@click.option("--executor", type=click.Choice(EXECUTORS), default="local", show_default=True,
              help="local: serial (--jobs 1) or a process pool; dask: dask.distributed.")
@click.option("--scheduler", metavar="ADDRESS", default=None, help="Dask scheduler address.")
@click.option("--plot", "plot_path", type=OutputFile(FIGURE_EXTENSIONS), default=None,
              help="Write the figure (PNG, SVG or PDF, by the extension).")
@click.option("--out", "out_dir", type=OutputDir(("rows.csv", "rows.json", "run.json", "sparsify.png")), default=None,
              help="Directory for rows.csv, rows.json, run.json and sparsify.png; created if missing (its parent "
                   "must exist).")
@click.option("--quick", is_flag=True, help="Small settings for CI (budgets 20%,50%).")
@anchor_option
@data_dir_option
@format_option()
def sparsify_cmd(file, budgets, methods, objective, fixed, certify, max_iter, seed, jobs, executor, scheduler,
                 plot_path, out_dir, quick, anchor, data_dir, fmt):
    """Per budget and method: the selection's objective value, upper bound and certified ratio,
    its tree bound, lambda_2, FIM log-det and CRLB trace (at the full graph's optimum), and the
    pruned graph's certified optimum (ATE/RPE against the full graph's optimum, aligned)."""

    ex = executor_settings(executor, jobs, scheduler)
    budgets = budgets or ",".join(QUICK_BUDGETS if quick else DEFAULT_BUDGETS)
    methods = methods or ",".join(DEFAULT_METHODS)
    n_tasks = len([b for b in budgets.split(",") if b.strip()]) * len([m for m in methods.split(",") if m.strip()])
    if n_tasks > MAX_TASKS:
        raise UsageError(f"--budgets x --methods gives {n_tasks} selections (each with a certified solve); "
                         f"at most {MAX_TASKS}")
    graph, _ = load_dataset(file, data_dir)
    t0 = time.perf_counter()
    with progress(n_tasks, f"{graph.name}: selections") as cb:
        res = sparsify_experiment(graph, budgets.split(","), methods, objective=objective, fixed=fixed, seed=seed,
                                  certify=certify, max_iter=max_iter, anchor=graph.anchor_index(anchor),
                                  progress=cb, **ex)
    elapsed = time.perf_counter() - t0
    bad = [f"{r['method']}@{r['budget_spec']}" for r in res.rows if not r["certified"]]
    if bad:
        log.warning("pruned graph(s) whose optimum is NOT certified: %s", ", ".join(bad))
    ref = res.reference
    for where, row in [("full graph", ref), ("fixed edges only", ref["fixed_only"]),
                       *((f"{r['method']}@{r['budget_spec']}", r) for r in res.rows)]:
        if row.get("crlb_trace_status"):
            log_status(log, f"tr CRLB ({where})", Status.from_json(row["crlb_trace_status"]))
    crlb_ref = "n/a" if ref["crlb_trace"] is None else f"{ref['crlb_trace']:.4g}"
    print_rows(res.rows, fmt, COLUMNS if fmt in ("table", "markdown") else None, headers=HEADERS,
               single_json=False,
               title=f"{res.dataset}: {res.candidates} loop closures, {res.fixed} fixed edges, objective "
                     f"{res.objective}; full graph: tree {ref['tree']:.6g}, λ2 {ref['fiedler']:.4g}, "
                     f"FIM logdet {ref['fim_logdet']:.6g}, tr CRLB {crlb_ref} ({elapsed:.1f} s)")
    with output_folder(out_dir) as folder:     # --out DIR swapped in whole
        target = plot_target(plot_path, folder, "sparsify")
        if target:
            from ...report.plots import plot_sparsify  # noqa: PLC0415 -- matplotlib, only for --plot

            plot_sparsify(res, target)
        if folder is not None:
            settings = {"file": res.path, "sha256": res.sha256, "dataset": res.dataset, "dim": res.dim,
                        "poses": res.poses, "edges": res.edges, "fixed": res.fixed, "fixed_rule": res.fixed_rule,
                        "candidates": res.candidates, "anchor": res.anchor_id, "objective": res.objective,
                        "budgets": res.budgets, "methods": res.methods, "certify": certify, "max_iter": max_iter,
                        "seed": seed, "quick": quick, "reference": res.reference, **ex}
            record = run_record("sparsify", settings=settings, seeds=res.seeds,
                                datasets={res.dataset: dataset_entry(res.path, res.sha256)},
                                results={"rows": len(res.rows)}, elapsed_seconds=elapsed)
            write_experiment_outputs(folder, res.rows, record)
