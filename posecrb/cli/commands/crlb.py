"""`posecrb crlb FILE`: Cramér-Rao lower bounds at an estimate, paper or thesis model."""
from __future__ import annotations

import logging
import re

import click

from ...core.errors import UsageError
from ...models import cramer_rao_bound
from ...report.render import key_value_rows, print_rows
from ..options import (
    INT64_MAX,
    POSE_ID,
    data_dir_option,
    estimate_option,
    format_option,
    load_with_estimate,
    model_option,
    model_settings_options,
    ordering_option,
    resolve_model_settings,
)
from ..paths import Command, DatasetArg

log = logging.getLogger("posecrb")


def parse_pose_ids(text: str | None) -> bool | list[int]:
    """``--poses``: ``all`` or a comma-separated list of ids and ranges (``3,7,10-12``)."""
    if text is None:
        return False
    text = text.strip()
    if text.lower() == "all":
        return True
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        # digits only (int() would take 1_0 and non-ASCII digits), ids that fit int64
        if re.fullmatch(r"[0-9]+(?:-[0-9]+)?", part) is None or max(map(int, part.split("-"))) > INT64_MAX:
            raise UsageError(f"--poses: {part!r} is not a pose id or an id range a-b")
        if "-" in part[1:]:
            lo_i, hi_i = map(int, part.split("-", 1))   # both digits only (checked above)
            if hi_i < lo_i or hi_i - lo_i > 10 ** 7:     # (a huge range would exhaust memory)
                raise UsageError(f"--poses: {part!r} is not a pose id or an id range a-b")
            out.extend(range(lo_i, hi_i + 1))
        else:
            out.append(int(part))
    return out


def crlb_result(file: str, data_dir: str | None, model: str, source: str, anchor_ids: tuple[int, ...],
                quotient: bool, poses: bool | list[int], rotation_model: str,
                fim_variant: str | None = None, frame: str | None = None,
                ordering: str = "auto") -> tuple[dict, list[dict]]:
    """The JSON-ready result and, when per-pose blocks were asked, one row per pose.
    ``fim_variant``: None (default: consistent, the model's Fisher information), "eq64" or
    "consistent". ``frame``: sed only, None/"world" or "body" (``posecrb.models.thesis.frames``).
    Doubtful numbers carry a ``<key>_status`` and a warning on stderr."""
    variant, frame = resolve_model_settings(model, fim_variant, frame)
    graph, est, est_info, times = load_with_estimate(file, data_dir, source)
    row: dict = {"dataset": graph.name, "model": model, "dim": graph.dim, "poses": graph.n,
                 "edges": graph.m, "components": graph.n_components}
    crb = cramer_rao_bound(graph, est.rot, est.trans, model=model, anchor_ids=anchor_ids, quotient=quotient,
                           poses=poses, rotation_model=rotation_model, variant=variant, frame=frame,
                           ordering=ordering)
    times.update(crb.times)
    row.update(crb.to_row())
    row["estimate"] = est_info
    row["times"] = times
    return row, crb.pose_rows


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
def command(file, model, quotient, anchors, poses, estimate_source, rotation_model, fim_variant, frame, ordering,
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
    row, per_rows = crlb_result(file, data_dir, model, estimate_source, anchors, quotient,
                                parse_pose_ids(poses), rotation_model, fim_variant, frame, ordering)
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
