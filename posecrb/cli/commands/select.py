"""`posecrb select FILE --budget K|P%`: measurement selection with a certificate (posecrb.selection.select)."""
from __future__ import annotations

import logging
import warnings
from collections.abc import Callable
from dataclasses import replace

import click

from ...api.select import select
from ...core.choices import ESTIMATE_SOURCES, FIXED_RULES, GAINS, METHODS, OBJECTIVES, Gains
from ...core.errors import ArgumentError, UsageError
from ...core.status import log_statuses
from ...report.render import print_rows
from ..options import (
    SEED_RANGE,
    FiniteFloat,
    PlainInt,
    anchor_option,
    data_dir_option,
    format_option,
    load_dataset,
)
from ..paths import GRAPH_EXTENSIONS, Command, DatasetArg, InputFile, OutputFile

log = logging.getLogger("posecrb")

HEADERS = {"quantity": "quantity", "value": "value"}


def _summary(d: dict) -> list[dict]:
    """The result as (quantity, value) rows for the terminal table."""
    b = d["bounds"]
    added = d["fixed"]["added_for_connectivity"]
    rows = [
        ("dataset", f"{d['dataset']} ({d['dim']}D, {d['poses']} poses, {d['edges']} edges)"),
        ("objective / method",
         f"{d['objective']} / {d['method']}" + (f" ({d['rounding']} rounding)" if d["rounding"] else "")),
        ("fixed edges", f"{d['fixed']['edges']} ({d['fixed']['rule']}"
                        + (f", {len(added)} added for connectivity" if added else "") + ")"),
        ("candidates", d["candidates"]),
        ("budget", f"{d['budget']} ({d['budget_spec']})"),
        ("value", d["value"]),
        ("base value (fixed edges only)", d["base_value"]),
        ("full value (every candidate)", d["full_value"]),
        ("upper bound", d["upper_bound"]),
        ("  relaxation bound (Frank-Wolfe)", b["relaxation"]),
        ("  submodular bound", b["submodular"]),
        ("certified ratio", d["certified_ratio"]),
    ]
    if b["iterations"]:
        stop = "converged" if b["converged"] else "stopped at --max-iter"
        rows.append(("relaxation iterations", f"{b['iterations']} ({stop})"))
    if d["estimate"]:
        e = d["estimate"]
        rows.append(("estimate", f"{e['source']}" + ("" if e["certified"] is None else
                                                     (", certified" if e["certified"] else ", NOT certified"))))
    rows.append(("time (s)", ", ".join(f"{k} {v:.3g}" for k, v in d["times"].items())))
    return [{"quantity": k, "value": v} for k, v in rows]


@click.command("select", cls=Command,
               short_help="Measurement selection: keep K edges, D-optimal, with a certificate.")
@click.argument("file", type=DatasetArg())
@click.option("--budget", required=True, metavar="K|P%",
              help="Number of candidate edges to keep, or a percentage of the candidates (rounded down).")
@click.option("--objective", type=click.Choice(OBJECTIVES), default="tree", show_default=True,
              metavar="|".join(OBJECTIVES),
              help="tree: d logdet L_tau + d_r logdet L_w (eq. 75, weighted tree-connectivity); fim: logdet of "
                   "the anchored frame-consistent FIM at --estimate; fiedler: algebraic connectivity of the "
                   "rotation-weighted Laplacian (MAC's objective).")
@click.option("--method", type=click.Choice(METHODS), default="greedy", show_default=True,
              metavar="|".join(METHODS),
              help="greedy (exact greedy; MAC's GreedyEig for fiedler), relax (the concave relaxation's bound, "
                   "top-K and Madow rounding; tree and fim keep the greedy set unless a rounding beats it), "
                   "random (seeded), naive (heaviest rotation weights).")
@click.option("--fixed", default="odometry", show_default=True, type=InputFile(FIXED_RULES),
              metavar="odometry|FILE",
              help="Edges always kept: the odometry chain (consecutive ids, plus edges needed to connect it), "
                   "or a file of pose-id pairs 'i j'. Every other edge is a candidate.")
@click.option("--certify", is_flag=True,
              help="Also run the relaxation for an upper bound (greedy, random, naive); relax always has it.")
@click.option("--max-iter", type=PlainInt(1, 100000), default=None,
              help="Relaxation iterations (default 100; fiedler: Frank-Wolfe, 20 as MAC).")
@click.option("--tol", type=FiniteFloat(min=0, min_open=True, max=1), default=1e-3, show_default=True,
              help="Stop the relaxation when its duality gap is below TOL x (bound - base value).")
@click.option("--gains", type=click.Choice(GAINS), default=None,
              help="How the log-det greedy evaluates gains: auto (the incremental greedy, every gain exact at every "
                   "step; above 4096 steps on graphs of 20,000 poses or more the round greedy, which the JSON's "
                   "stats.strategy names), exact (the incremental greedy whatever the size), rounds (the round "
                   "greedy: exact gains once per round, local corrections within it), lazy (a priority queue, "
                   "seeded by random projections above 50000 candidates), lazy-exact (never random projections), "
                   "jl (always seeded by random projections).  [default: auto]")
@click.option("--lazy", is_flag=True, help="Deprecated: --gains lazy.")
@click.option("--jl", is_flag=True, help="Deprecated: --gains jl.")
@click.option("--exact", is_flag=True, help="Deprecated: --gains exact (with --lazy: --gains lazy-exact).")
@click.option("--estimate", default="solve", show_default=True, type=InputFile(ESTIMATE_SOURCES),
              metavar="solve|vertices|FILE",
              help="fim objective: the estimate at which the FIM is evaluated (default the certified optimum "
                   "of the full graph).")
@click.option("--seed", type=SEED_RANGE, default=0, show_default=True,
              help="Seed of random, Madow rounding and random projections.")
@click.option("--out", "out_path", type=OutputFile(GRAPH_EXTENSIONS), default=None,
              help="Write the pruned graph (fixed + selected edges, every vertex) as g2o.")
@anchor_option
@data_dir_option
@format_option()
def command(file, budget, objective, method, fixed, certify, max_iter, tol, gains, lazy, jl, exact, estimate, seed,
            out_path, anchor, data_dir, fmt):
    """Keep K of FILE's candidate edges maximising a D-optimality objective, with an upper bound
    on the best K-subset (certified ratio = (value - base) / (upper_bound - base)).

    The JSON output lists the selected edges as [id_i, id_j, position of the edge in the file
    (0-based, edges only)]; the table shows the summary.
    """

    if jl and exact:
        raise UsageError("--jl and --exact exclude each other")
    how = gains_of(gains, lazy, jl, exact)
    from ...selection.budget import budget_value  # noqa: PLC0415 -- lazy: start-up time

    amount = _budget(budget, budget_value)
    graph, _ = load_dataset(file, data_dir)
    try:
        res = select(graph, budget=amount, objective=objective, method=method, fixed=fixed, certify=certify,
                     max_iter=max_iter, tol=tol, gains=how, estimate=estimate, seed=seed,
                     anchor=anchor)
    except ArgumentError as exc:
        if exc.parameter == "budget":    # the budget as the user wrote it (20%, not 0.2)
            raise ArgumentError("budget", budget, exc.reason, sep=exc.sep) from None
        raise
    res = replace(res, budget_spec=budget)
    if out_path is not None:    # checked before the work (posecrb.cli.paths)
        from ...io import write_g2o  # noqa: PLC0415 -- lazy: start-up time

        write_g2o(res.pruned_graph(graph), out_path)
        res = replace(res, saved=out_path)
    log_statuses(log, res.dataset, res.statuses())
    if res.saved:
        log.info("wrote %s (%d edges)", res.saved, res.fixed.edges + res.budget)
    d = res.to_dict()
    if fmt == "json":
        print_rows([d], fmt)
    elif fmt == "table":
        print_rows(_summary(d), fmt, ["quantity", "value"], headers=HEADERS,
                   title=f"{d['dataset']}: {d['budget']} of {d['candidates']} candidate edges")
    else:    # one row: without the per-edge lists
        print_rows([{k: v for k, v in d.items() if k not in ("selected", "order")}], fmt)


def _budget(text: str, budget_value: Callable[[str], int | float]) -> int | float:
    """``--budget K|P%`` as the library takes it (K, or the fraction P / 100)."""
    try:
        return budget_value(text)
    except ArgumentError as exc:
        raise ArgumentError("budget", text, exc.reason, sep=exc.sep) from None


def gains_of(gains: Gains | None, lazy: bool, jl: bool, exact: bool) -> Gains:
    """The library's ``gains=``: ``--gains``, or the flags of 0.2 that it replaces (``--jl`` implies
    the lazy greedy; ``--exact``, never random projections, now also the exact greedy on graphs where
    ``auto`` takes the round greedy), each with a deprecation warning naming the new form."""
    flags = [name for name, on in (("--lazy", lazy), ("--jl", jl), ("--exact", exact)) if on]
    if gains is not None:
        if flags:
            raise UsageError(f"{' and '.join(flags)} and --gains exclude each other: give --gains alone")
        return gains
    if not flags:
        return "auto"
    new: Gains = "jl" if jl else ("lazy-exact" if lazy and exact else "lazy" if lazy else "exact")
    warnings.warn(f"{' '.join(flags)} is deprecated: use --gains {new}", DeprecationWarning, stacklevel=2)
    return new
