"""`posecrb experiment crlb|thesis|octagon`: the paper's and the thesis's experiments.

Thin shell over ``posecrb.experiments``: options -> library call -> table / file output.
Trials run serially (``--jobs 1``), in a local process pool (``--jobs N``) or on a Dask
cluster (``--executor dask [--scheduler ADDRESS]``); results are bit-identical for a given
``--seed`` whatever the executor.
"""
from __future__ import annotations

import logging
import os
import re
import time
from collections.abc import Callable
from typing import Any

import click

from ...core.choices import EXECUTORS, NOISE_SCALES
from ...core.errors import UsageError
from ...core.folders import output_folder
from ...core.provenance import dataset_entry, run_record
from ...core.resources import check_memory
from ...experiments.crlb_sweep import MAX_LEVELS, check_levels, crlb_sweep, parse_levels
from ...experiments.octagon import octagon_experiment
from ...experiments.thesis import DEFAULT_M, QUICK_M, thesis_experiment
from ...report.outputs import write_experiment_outputs
from ...report.render import print_rows
from ..options import (
    SEED_RANGE,
    FiniteFloat,
    PlainInt,
    anchor_option,
    data_dir_option,
    executor_settings,
    fim_variant_option,
    format_option,
    load_dataset,
    plot_target,
)
from ..paths import FIGURE_EXTENSIONS, DatasetArg, Group, OutputDir, OutputFile
from ..progress import progress
from ._sparsify import sparsify_cmd

log = logging.getLogger("posecrb")


# ---------------------------------------------------------------- shared options and helpers
def out_files(name: str, extra: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The files an experiment's ``--out DIR`` receives (``write_experiment_outputs``) and its figure."""
    return ("rows.csv", "rows.json", "run.json", f"{name}.png", *(f"{e}.csv" for e in extra))


def _run_options(default_trials: str, name: str, extra: tuple[str, ...] = ()
                 ) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    def deco(f):
        opts = [
            click.option("--trials", type=PlainInt(2, 10 ** 7), default=None,
                         help=f"Monte Carlo trials ({default_trials}); the memory they need is checked first."),
            click.option("--seed", type=SEED_RANGE, default=0, show_default=True,
                         help="Root seed; every trial has its own SeedSequence child."),
            click.option("--jobs", type=PlainInt(1, 1024), default=1, show_default=True,
                         help="Worker processes (local pool, or LocalCluster size for --executor dask)."),
            click.option("--executor", type=click.Choice(EXECUTORS), default="local", show_default=True,
                         help="local: serial (--jobs 1) or a process pool; dask: dask.distributed "
                              "(pip install 'posecrb[dask]').") ,
            click.option("--scheduler", metavar="ADDRESS", default=None,
                         help="Dask scheduler address (tcp://host:8786); without it a LocalCluster on "
                              "127.0.0.1 is started."),
            click.option("--plot", "plot_path", type=OutputFile(FIGURE_EXTENSIONS), default=None,
                         help="Write the figure (PNG, SVG or PDF, by the extension)."),
            click.option("--out", "out_dir", type=OutputDir(out_files(name, extra)), default=None,
                         help="Directory for the data (rows.csv, rows.json, per-trial data), run.json and "
                              f"{name}.png; created if missing (its parent must exist)."),
            click.option("--quick", is_flag=True, help="Small settings for CI (well under a minute)."),
            format_option(),
        ]
        for o in reversed(opts):
            f = o(f)
        return f
    return deco


def _write_out(out_dir: str | os.PathLike | None, experiment: str, settings: dict, rows: list[dict], seeds: list[dict],
               elapsed: float, extra: dict[str, list[dict]] | None = None,
               datasets: dict[str, dict] | None = None) -> None:
    if out_dir:
        record = run_record(experiment, settings=settings, seeds=seeds, datasets=datasets,
                            results={"rows": len(rows)}, elapsed_seconds=elapsed)
        write_experiment_outputs(out_dir, rows, record, extra)


# thesis --m: F_m = m F_1; the MLE's errors are about 1/sqrt(m) (1e-6 at the bound), far above its
# stopping tolerance (steps below 1e-15, gradients below 1e-12 relative) up to this m.
MAX_M = 10 ** 12

# Bookkeeping memory per Monte Carlo trial: its task and seed (~0.7 kB measured), its result, its
# row in the per-trial output; 4 kB leaves a margin.
TRIAL_BYTES = 4096


def _check_trials(trials: int, groups: int, what: str) -> None:
    """--trials against the memory its bookkeeping needs (before the work; exit 2)."""
    check_memory(float(trials) * groups * TRIAL_BYTES, f"--trials {trials} x {groups} {what}",
                 "ask for fewer trials")


@click.group("experiment", cls=Group)
def command() -> None:
    """The paper's and the thesis's experiments (Monte Carlo CRLB, T- vs D-optimality, thesis ch. 6)."""


# ---------------------------------------------------------------- crlb
CRLB_COLUMNS_2D = ["kc", "trials", "mse", "mse_stderr", "mse_bound", "ratio", "mse_trans", "mse_rot",
                   "uncertified", "fim_variant"]
CRLB_COLUMNS_3D = ["kc", "trials", "mse", "mse_stderr", "mse_bound", "mse_bound_curvature", "ratio",
                   "ratio_curvature", "mse_trans", "mse_rot", "uncertified", "fim_variant"]
CRLB_HEADERS = {"mse_stderr": "± s.e.", "mse_bound": "CRLB/n_p", "mse_bound_curvature": "CRLB+curv/n_p",
                "ratio": "MSE/CRLB", "ratio_curvature": "MSE/(CRLB+curv)", "fim_variant": "FIM variant"}


@command.command("crlb", short_help="Monte Carlo MSE vs CRLB over noise levels (paper Fig. 6/7).")
@click.argument("file", type=DatasetArg())
@click.option("--kc", "kc_spec", default=None,
              help="Noise levels k_c: one value (20), a list (1,5,20) or a range (1:20, 1:20:0.5). "
                   "Default 1:20 (--quick: 1,20).")
@click.option("--scale", type=click.Choice(NOISE_SCALES), default="both", show_default=True,
              help="both: k_c multiplies kappa and tau (the whole information); rotation: only kappa, "
                   "eq. (80) as printed.")
@click.option("--kappa", type=FiniteFloat(min=1e-12, max=1e12), default=None,
              help="Base Langevin concentration for every edge instead of the file's (paper Fig. 6: 150).")
@click.option("--tau", type=FiniteFloat(min=1e-12, max=1e12), default=None,
              help="Base translation precision 1/delta^2 for every edge instead of the file's (Fig. 6: 140).")
@anchor_option
@fim_variant_option
@data_dir_option
@_run_options("default 100; --quick: 20", "crlb", ("trials",))
def crlb_cmd(file, kc_spec, scale, kappa, tau, anchor, fim_variant, data_dir, trials, seed, jobs, executor,
             scheduler, plot_path, out_dir, quick, fmt):
    """Fig. 6/7: MSE per pose of the certified MLE vs trace(CRLB)/n_p over noise levels k_c.

    Ground truth is the certified solution of FILE. Each trial regenerates every measurement by
    eq. (80) at the level k_c, solves it, and measures the error in the FIM's coordinates
    (anchor aligned; 2D angle, 3D sqrt2*Log). Columns: ratio = MSE / CRLB (eq. 67 / 68) of the
    simulated model's Fisher information (fim_variant=consistent), or of eq. (64) as printed
    with --fim-variant eq64; ratio_curvature with the curvature term (3D).
    """

    kcs = parse_levels(kc_spec or ("1,20" if quick else "1:20"))
    trials = trials or (20 if quick else 100)
    _check_trials(trials, len(kcs), "noise levels")
    ex = executor_settings(executor, jobs, scheduler)
    graph, _ = load_dataset(file, data_dir)
    check_levels(graph, kcs, scale, tau, kappa, name="--kc")
    anchor_idx = graph.anchor_index(anchor)
    t0 = time.perf_counter()
    with progress(len(kcs) * trials, f"{graph.name}: trials") as cb:
        res = crlb_sweep(graph, kcs, trials, seed, scale=scale, tau=tau, kappa=kappa, anchor=anchor_idx,
                         progress=cb, fim_variant=fim_variant or "consistent", **ex)
    elapsed = time.perf_counter() - t0
    if not res.truth_certified:
        log.warning("the ground truth (solution of %s) is not certified", graph.name)
    for lv in res.levels:
        if lv.accuracy and lv.accuracy["status"] != "ok":
            log.warning("k_c = %g: CRLB %s: %s", lv.kc,
                        "not available" if lv.accuracy["status"] == "unavailable" else "doubtful",
                        lv.accuracy["reason"])
        if lv.ratio_status:
            log.warning("k_c = %g: MSE/CRLB %s: %s", lv.kc,
                        "not available" if lv.ratio_status["status"] == "unavailable" else "doubtful",
                        lv.ratio_status["reason"])
        if lv.curvature_status:
            log.warning("k_c = %g: curvature-corrected CRLB (eq. 68) %s: %s", lv.kc,
                        "not available" if lv.curvature_status["status"] == "unavailable" else "doubtful",
                        lv.curvature_status["reason"])
    bad = sum(lv.uncertified for lv in res.levels)
    if bad:
        log.warning("%d trial solve(s) were not certified (counted in the MSE)", bad)
    rows = res.rows()
    cols = CRLB_COLUMNS_3D if graph.dim == 3 else CRLB_COLUMNS_2D
    print_rows(rows, fmt, cols if fmt == "table" else None,
               title=f"{graph.name}: MSE per pose vs CRLB ({res.trials} trials/level, scale={scale}, "
                     f"seed {seed}, {elapsed:.1f} s)", headers=CRLB_HEADERS)
    settings = {"file": graph.path, "sha256": graph.sha256, "dataset": graph.name, "dim": graph.dim,
                "poses": graph.n, "edges": graph.m, "anchor": res.anchor_id, "kc": kcs, "trials": trials,
                "seed": seed, "scale": scale, "kappa": kappa, "tau": tau, "quick": quick,
                "fim_variant": res.fim_variant, **ex,
                "truth_certified": res.truth_certified, "truth_objective": res.truth_objective}
    with output_folder(out_dir) as folder:     # --out DIR swapped in whole
        target = plot_target(plot_path, folder, "crlb")
        if target:
            from ...report.plots import plot_crlb_sweep  # noqa: PLC0415 -- matplotlib, only for --plot

            plot_crlb_sweep(res, target)
        _write_out(folder, "crlb", settings, rows, res.seeds, elapsed, {"trials": res.trial_rows()},
                   {graph.name: dataset_entry(graph.path, graph.sha256)})


# ---------------------------------------------------------------- thesis
THESIS_HEADERS = {"frob": "‖Cov−CRB‖_F", "frob_rel": "relative", "frob_rel_noise": "MC noise level",
                  "eig_min": "λmin Sym(Cov−CRB)", "eig_max": "λmax", "not_converged": "not conv."}


@command.command("thesis", short_help="Thesis ch. 6: MLE covariance vs anchored and quotient CRB.")
@click.option("--m", "m_spec", default=None,
              help="Measurements per arc, a list (default 1,2,5,10,20,50,100,150; --quick: 1,10,100).")
@_run_options("default 200; --quick: 100", "thesis", ("eigenvalues",))
def thesis_cmd(m_spec, trials, seed, jobs, executor, scheduler, plot_path, out_dir, quick, fmt):
    """Thesis ch. 6: empirical covariance of the intrinsic MLE vs the anchored (Pi F Pi)^+ and
    quotient F^+ bounds with F_m = m F_1, on the built-in 5-pose SE(2) case (nullity 6)."""

    if m_spec is not None:
        parts = [x.strip() for x in m_spec.split(",") if x.strip()]
        # digits only (int() would take 1_0, +5 and non-ASCII digits)
        bad = next((x for x in parts if re.fullmatch(r"[0-9]{1,13}", x) is None), None)
        if bad is not None or not parts:
            raise UsageError(f"--m takes a comma-separated list of integers 1..{MAX_M}, got {m_spec!r}")
        ms = sorted({int(x) for x in parts})
        if ms[0] < 1 or ms[-1] > MAX_M or len(ms) > MAX_LEVELS:
            raise UsageError(f"--m values must be integers in 1..{MAX_M} (at most {MAX_LEVELS} of them): F_m = m F_1 "
                             "beyond that makes the MLE's errors (about 1/sqrt(m)) approach its own numerical "
                             "resolution, and the covariance would measure rounding")
    else:
        ms = list(QUICK_M if quick else DEFAULT_M)
    trials = trials or (100 if quick else 200)
    ex = executor_settings(executor, jobs, scheduler)
    _check_trials(trials, len(ms), "values of m")
    t0 = time.perf_counter()
    with progress(len(ms) * trials, "thesis: trials") as cb:
        res = thesis_experiment(ms, trials, seed, progress=cb, **ex)
    elapsed = time.perf_counter() - t0
    rows = res.rows()
    print_rows(rows, fmt, None, title=f"thesis ch. 6: ‖Cov − CRB‖ vs m ({trials} trials per m, seed {seed}, "
                                      f"{elapsed:.1f} s)", headers=THESIS_HEADERS)
    settings = {"m": ms, "trials": trials, "seed": seed, "quick": quick, **ex}
    with output_folder(out_dir) as folder:     # --out DIR swapped in whole
        target = plot_target(plot_path, folder, "thesis")
        if target:
            from ...report.plots import plot_thesis  # noqa: PLC0415 -- matplotlib, only for --plot

            plot_thesis(res, target)
        _write_out(folder, "thesis", settings, rows, res.seeds, elapsed, {"eigenvalues": res.eigenvalue_rows()})


# ---------------------------------------------------------------- octagon
OCTAGON_HEADERS = {"extra_edges": "extra", "m": "edges", "total_degree": "degree", "trace_eq73": "eq.(73)",
                   "best_fewer_logdet": "best logdet, fewer edges", "flagged": "worse than fewer"}


@command.command("octagon", short_help="T- vs D-optimality vs node degree (paper Fig. 4/5).")
@click.option("--radius", type=FiniteFloat(min=1e-6, max=1e6), default=0.1, show_default=True,
              help="Circumradius of the octagon. The paper gives no size; 0.1 keeps sum tau||p||^2 small, "
                   "as it states.")
@_run_options("random graphs per number of extra edges; default 50; --quick: 5", "octagon", ("graphs",))
def octagon_cmd(radius, trials, seed, jobs, executor, scheduler, plot_path, out_dir, quick, fmt):
    """Fig. 4/5: T-optimality (trace F) and D-optimality (log det F) vs total node degree on the
    8-pose octagon with 0..21 extra edges; flags graphs worse than one with fewer edges."""

    trials = trials or (5 if quick else 50)
    ex = executor_settings(executor, jobs, scheduler)
    _check_trials(trials, 22, "levels")
    t0 = time.perf_counter()
    with progress(22, "octagon: levels") as cb:
        res = octagon_experiment(trials, seed, radius=radius, progress=cb, **ex)
    elapsed = time.perf_counter() - t0
    rows = res.rows()
    print_rows(rows, fmt, None, headers=OCTAGON_HEADERS,
               title=f"octagon: {len(res.graphs)} graphs; corr(trace, degree) = {res.corr_trace_degree:.5f}, "
                     f"corr(logdet, degree) = {res.corr_logdet_degree:.5f}; {res.flagged} graphs have more "
                     f"edges but a smaller log det")
    settings = {"trials": trials, "seed": seed, "radius": radius, "tau": res.tau, "kappa": res.kappa,
                "corr_trace_degree": res.corr_trace_degree, "corr_logdet_degree": res.corr_logdet_degree,
                "trace_slope": res.trace_slope, "flagged": res.flagged, "quick": quick, **ex}
    with output_folder(out_dir) as folder:     # --out DIR swapped in whole
        target = plot_target(plot_path, folder, "octagon")
        if target:
            from ...report.plots import plot_octagon  # noqa: PLC0415 -- matplotlib, only for --plot

            plot_octagon(res, target)
        _write_out(folder, "octagon", settings, rows, res.seeds, elapsed, {"graphs": res.graph_rows()})


# ---------------------------------------------------------------- sparsify (posecrb.cli.commands._sparsify)
command.add_command(sparsify_cmd)
