"""`posecrb crlb FILE`: Cramér-Rao lower bounds at an estimate, paper or sed model."""
from __future__ import annotations

import logging

import click

from ...api.models import crlb
from ...core.status import log_statuses
from ...report.render import key_value_rows, print_rows
from ..options import (
    POSE_ID,
    data_dir_option,
    estimate_option,
    format_option,
    model_option,
    model_settings_options,
    ordering_option,
    parse_pose_ids,
)
from ..paths import Command, DatasetArg

log = logging.getLogger("posecrb")


@click.command("crlb", cls=Command)
@click.argument("file", type=DatasetArg())
@model_option
@click.option("--quotient", is_flag=True, help="sed: quotient CRB F^+ (thesis 5.5) instead of the anchored one (5.1).")
@click.option("--anchor", "anchors", type=POSE_ID, multiple=True,
              help="Anchored pose id (repeatable; sed: one or more per component). "
                   "Default: the smallest id (of each component).")
@click.option("--poses", default=None, metavar="IDS",
              help="Also report per-pose covariance blocks: 'all' or ids/ranges, e.g. 0,5,10-12.")
@estimate_option
@model_settings_options
@ordering_option
@data_dir_option
@format_option()
def command(file, model, quotient, anchors, poses, estimate_source, rotation_weight, fim_variant, frame, ordering,
            data_dir, fmt):
    """Cramér-Rao lower bound of FILE at an estimate: exact trace, MSE bound, per-pose blocks.

    paper: C >= F^{-1} (2D, eq. 67); 3D adds the curvature term of eq. (68)
    (trace_crlb_curvature; not available, with the reason, where the second-order correction
    reaches the first-order term). trace_crlb = trace(F^{-1}), mse_bound = trace_crlb / n_p.
    F is the model's Fisher information (fim_variant=consistent) unless --fim-variant eq64
    (eq. 64 as printed; in 3D the two differ, see `posecrb fim --help`).
    accuracy: backward error of sampled solves and the scaled condition number of F, with a
    warning on stderr when the inverse may carry relative errors above 1e-6.
    sed: the thesis' intrinsic CRB on SE(d)^n, anchored (5.1) or --quotient (5.5).
    Traces and blocks are exact (selected inversion of the sparse Cholesky factor).
    sed --frame world (default): the thesis' coordinates, X_i -> Exp(-delta) X_i about the
    world origin (blocks carry lever-arm terms); --frame body: GTSAM's and g2o's
    X_i -> X_i Exp(xi), C_body = B C B^T with B = -P Ad_{X_i^-1}, comparable with
    gtsam.Marginals (anchored: the anchor pose known exactly). Traces and MSE bounds are in
    the same frame as the blocks. Per-pose blocks use the coordinates listed in
    `coordinates`; `frame` and `coordinates_description` say what they mean (JSON: full matrices).
    --ordering: the factorization's fill-reducing ordering (cost only; JSON key ordering).
    """
    res = crlb(file, model=model, quotient=quotient, anchor=list(anchors),
               poses=None if poses is None else parse_pose_ids(poses), estimate=estimate_source,
               rotation_weight=rotation_weight, fim_variant=fim_variant, frame=frame, ordering=ordering,
               data_dir=data_dir)
    log_statuses(log, res.dataset, res.statuses())
    row, per_rows = res.to_dict(), res.pose_rows()
    if fmt == "json":
        print_rows([row], "json")
        return
    summary = {k: (",".join(map(str, v)) if isinstance(v, list) else v)
               for k, v in row.items() if k not in ("per_pose", "per_pose_curvature")}
    if fmt == "table":

        kv = key_value_rows(summary)
        print_rows(kv, "table", title=f"CRLB ({model}) of {row['dataset']}")
        if per_rows:
            print_rows(per_rows, "table", title="per-pose bound (diagonal)")
    else:
        print_rows([summary], fmt)
        if per_rows:
            print_rows(per_rows, fmt)
