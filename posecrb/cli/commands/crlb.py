"""`posecrb crlb FILE`: Cramér-Rao lower bounds at an estimate, paper or thesis model."""
from __future__ import annotations

import logging
import re

import click
import numpy as np

from ...core.errors import UsageError
from ...core.status import Status, log_status, put
from ...models.paper.crlb import paper_crlb
from ...models.thesis.frames import coordinate_names, coordinates_description, sed_crb_in_frame
from ...report.render import key_value_rows, print_rows
from ..options import (
    INT64_MAX,
    POSE_ID,
    data_dir_option,
    estimate_option,
    fim_variant_option,
    format_option,
    frame_option,
    load_with_estimate,
    model_option,
    resolve_fim_variant,
    resolve_frame,
    rotation_weight_option,
)

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
                fim_variant: str | None = None, frame: str | None = None) -> tuple[dict, list[dict]]:
    """The JSON-ready result and, when per-pose blocks were asked, one row per pose.
    ``fim_variant``: None (default: consistent, the model's Fisher information), "eq64" or
    "consistent". ``frame``: sed only, None/"world" or "body" (``posecrb.models.thesis.frames``).
    Doubtful numbers carry a ``<key>_status`` and a warning on stderr."""
    variant = resolve_fim_variant(model, fim_variant)
    frame = resolve_frame(model, frame)
    graph, est, est_info, times = load_with_estimate(file, data_dir, source)
    row: dict = {"dataset": graph.name, "model": model, "dim": graph.dim, "poses": graph.n,
                 "edges": graph.m, "components": graph.n_components}
    if model == "paper":

        if quotient:
            raise UsageError("--quotient applies to --model sed (the paper model is anchored)")
        if len(anchor_ids) > 1:
            raise UsageError("--model paper takes a single --anchor (its graph must be connected)")
        anchor = graph.anchor_index(anchor_ids[0] if anchor_ids else None)
        res = paper_crlb(graph, est.rot, est.trans, anchor=anchor, per_pose=poses, rotation_model=rotation_model,
                         variant=variant)
        times.update(res.times)
        row.update({"kind": "anchored", "fim_variant": res.fim_variant, "rotation_weight": rotation_model,
                    "anchors": [res.anchor_id], "nullity": 0})
        acc = _accuracy(row, res.accuracy, graph.name)
        for key in ("trace_crlb", "mse_bound", "trace_translation", "trace_rotation"):
            put(row, key, getattr(res, key), acc)
        if graph.dim == 3:
            st = res.curvature_status if acc.available else acc
            log_status(log, f"{graph.name}: curvature-corrected CRLB (eq. 68)", res.curvature_status)
            put(row, "trace_crlb_curvature", res.trace_crlb_curvature, st)
            put(row, "mse_bound_curvature", res.mse_bound_curvature, st)
            row["curvature_correction_max"] = res.curvature_correction_max
        row["coordinates"] = res.coordinates
        blocks, curv = res.per_pose, res.per_pose_curvature
        if not acc.available:
            blocks = curv = None
    else:

        anchors = None if not anchor_ids else [graph.index_of(a) for a in anchor_ids]
        if poses is True:
            want: bool | list[int] = True
        elif poses:
            want = [graph.index_of(p) for p in poses]
        else:
            want = False
        res = sed_crb_in_frame(graph, est.rot, est.trans, frame, anchors=anchors, quotient=quotient, per_pose=want)
        times.update(res.times)
        row.update({"kind": res.kind, "anchors": [int(graph.ids[a]) for a in res.anchors],
                    "nullity": res.nullity})
        acc = _accuracy(row, res.accuracy, graph.name)
        put(row, "trace_crlb", res.trace_crlb, acc)
        put(row, "mse_bound", res.mse_bound, acc)
        row["coordinates"] = coordinate_names(graph.dim, frame)
        blocks = None if res.per_pose is None else {int(graph.ids[k]): v for k, v in res.per_pose.items()}
        curv = None
        if not acc.available:
            blocks = None

    row["frame"] = frame
    row["coordinates_description"] = coordinates_description(graph.dim, frame)
    per_rows: list[dict] = []
    if blocks is not None:
        row["per_pose"] = {str(k): v for k, v in blocks.items()}
        if curv is not None:
            row["per_pose_curvature"] = {str(k): v for k, v in curv.items()}
        names = row["coordinates"]
        for k, v in blocks.items():
            r = {"id": k, **{f"var_{c}": float(x) for c, x in zip(names, np.diag(v))}, "trace": float(np.trace(v))}
            if curv is not None:
                r["trace_curvature"] = float(np.trace(curv[k]))
            per_rows.append(r)
    row["estimate"] = est_info
    row["times"] = times
    return row, per_rows


def _accuracy(row: dict, accuracy, name: str) -> Status:
    """Record the inverse's accuracy estimate in ``row`` (key ``accuracy``), warn on stderr when it
    is not ok, and return the status that the bound's numbers inherit when it is unavailable."""
    if accuracy is None:
        return Status()
    row["accuracy"] = accuracy.as_json()
    log_status(log, f"{name}: CRLB", accuracy.status)
    return accuracy.status if not accuracy.status.available else Status()


@click.command("crlb")
@click.argument("file")
@model_option
@click.option("--quotient", is_flag=True, help="sed: quotient CRB F^+ (thesis 5.5) instead of the anchored one (5.1).")
@click.option("--anchor", "anchors", type=POSE_ID, multiple=True,
              help="Anchored pose id (repeatable; sed: one or more per component). "
                   "Default: the smallest id (of each component).")
@click.option("--poses", default=None, metavar="IDS",
              help="Also report per-pose covariance blocks: 'all' or ids/ranges, e.g. 0,5,10-12.")
@estimate_option
@rotation_weight_option
@fim_variant_option
@frame_option
@data_dir_option
@format_option()
def command(file, model, quotient, anchors, poses, estimate_source, rotation_model, fim_variant, frame, data_dir,
            fmt):
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
    """
    row, per_rows = crlb_result(file, data_dir, model, estimate_source, anchors, quotient,
                                parse_pose_ids(poses), rotation_model, fim_variant, frame)
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
