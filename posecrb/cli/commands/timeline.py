"""`posecrb timeline FILE`: D- and T-optimality of every prefix as the graph grows (posecrb.incremental)."""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import click

from ...api.timeline import timeline
from ...core.errors import PosecrbError
from ...core.status import log_statuses
from ...report.render import print_rows, to_json_long, to_rich_table
from ..options import (
    PlainInt,
    data_dir_option,
    fim_variant_option,
    format_option,
    make_estimate_option,
    rotation_weight_option,
)
from ..paths import FIGURE_EXTENSIONS, Command, DatasetArg, OutputFile

if TYPE_CHECKING:
    from ...incremental import TimelineResult

log = logging.getLogger("posecrb")

ROW_COLUMNS = ["poses", "pose", "edges", "loop_closures", "components", "lb", "ub", "t_opt_graph", "fim_logdet",
               "gain"]
METRIC_HEADERS = {"final": "final value", "per_dimension": "per dimension", "raw_monotone": "monotone",
                  "raw_decreases": "decreases", "raw_first_break": "first decrease",
                  "per_dimension_monotone": "monotone / dim", "per_dimension_decreases": "decreases / dim",
                  "per_dimension_first_break": "first decrease / dim"}
TOP_COLUMNS = ["rank", "poses", "pose", "source", "target", "line", "gain"]


def _show_summary(res: TimelineResult) -> None:
    """The table view: final values and monotonicity per metric, the top loop closures."""
    from rich.console import Console  # noqa: PLC0415 -- lazy: start-up time (rich only for table output)

    metrics, top = res.summary_rows()
    est = res.estimate
    title = (f"{res.dataset}: {res.dim}D, {res.poses} poses, {res.edges} edges; steps {res.first}..{res.last} "
             "poses; " + (f"FIM at {est.source}" if est else "graph only") + "; first decrease: number of poses "
             "(newest id)")
    console = Console(soft_wrap=False, width=250)
    console.print(title, markup=False, highlight=False)
    console.print(to_rich_table(metrics, ["metric", "final", "per_dimension", "raw_monotone", "raw_decreases",
                                          "raw_first_break", "per_dimension_monotone", "per_dimension_decreases",
                                          "per_dimension_first_break"], headers=METRIC_HEADERS))
    if top:
        console.print(f"Top {len(top)} loop closures by gain (the increase of lb each brings, in file order):",
                      markup=False, highlight=False)
        console.print(to_rich_table(top, TOP_COLUMNS))
    else:
        console.print("No loop closure with a gain in this range.", markup=False, highlight=False)


@click.command("timeline", cls=Command)
@click.argument("file", type=DatasetArg())
@make_estimate_option("estimate", allow_none=True)
@click.option("--every", type=PlainInt(1, None), default=1, show_default=True,
              help="Keep every N-th step from --from on, and the last one (all steps are computed).")
@click.option("--from", "start", type=PlainInt(2, None), default=None, metavar="K",
              help="First step, as its number of poses (default 2).")
@click.option("--to", "stop", type=PlainInt(2, None), default=None, metavar="K",
              help="Last step, as its number of poses (default: all).")
@rotation_weight_option
@fim_variant_option
@click.option("--plot", "plot_path", type=OutputFile(FIGURE_EXTENSIONS), default=None,
              help="Write the figure (.png, .svg or .pdf): lb-ub band and FIM log-det against the step, loop "
                   "closures marked.")
@data_dir_option
@format_option()
def command(file, estimate, every, start, stop, rotation_weight, fim_variant, plot_path, data_dir, fmt):
    """D- and T-optimality of every prefix of FILE as the graph grows: lb, ub, t_opt_graph and the FIM
    log-det per step, computed incrementally, and the gain of every loop closure.

    Step K is the graph on the K poses with the smallest ids, anchored at the smallest id: the same
    lb, ub (eq. 75) and t_opt_graph (eq. 73) as `posecrb bounds`, and fim_logdet at --estimate (default:
    the certified optimum of the whole graph, restricted to each prefix). A loop closure's gain is its
    sequential increase of lb in file order; a step's gain is the sum over its loop closures. A
    disconnected prefix has a status and no values. The table view is a summary (final values,
    monotonicity of each metric raw and per dimension, the top 10 loop closures); json, csv and
    markdown give every row.
    """
    res = timeline(file, estimate=estimate, every=every, start=start, stop=stop, rotation_weight=rotation_weight,
                   fim_variant=fim_variant, data_dir=data_dir)
    if plot_path is not None:    # checked before the work (posecrb.cli.paths)
        if res.lb_status.available:
            from ...report.plots import plot_timeline  # noqa: PLC0415 -- matplotlib, only for a figure

            plot_timeline(res, plot_path)
        else:
            log.warning("no figure written to %s: %s", plot_path, res.lb_status.reason)
    log_statuses(log, res.dataset, res.statuses())
    uncertified = res.estimate is not None and res.estimate.certified is False
    if fmt == "json":
        # to_dict() is plain JSON already (no NaN, no numpy scalars): no conversion pass; one line
        # per row and per loop closure
        click.echo(to_json_long(res.to_dict(), ("rows", "loop_closures")))
    elif fmt == "table":
        _show_summary(res)
    else:
        print_rows(res.row_dicts(), fmt, columns=[c for c in ROW_COLUMNS if c != "fim_logdet" or res.estimate]
                   if fmt == "markdown" else None)
    if uncertified:
        raise PosecrbError(f"the solver did not certify the estimate of {res.dataset} (fim_logdet is at an "
                           "uncertified estimate)")
