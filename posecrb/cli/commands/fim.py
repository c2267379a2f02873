"""`posecrb fim FILE`: the Fisher information matrix at an estimate, paper or thesis model."""
from __future__ import annotations

import logging

import click

from ...io.npz import npz_path
from ...models import fisher_information
from ...models.thesis.frames import coordinates_description
from ...report.render import key_value_rows, print_rows
from ..options import (
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
from ..paths import Command, DatasetArg, OutputFile

log = logging.getLogger("posecrb")


def fim_row(file: str, data_dir: str | None, model: str, source: str, anchor_id: int | None,
            rotation_model: str, save: str | None, fim_variant: str | None = None,
            frame: str | None = None, ordering: str = "auto") -> dict:
    variant, frame = resolve_model_settings(model, fim_variant, frame)
    if save:   # checked before the work with the command's inputs (posecrb.cli.paths)
        save = npz_path(save)   # the file really written (and reported as `saved`)
    graph, est, est_info, times = load_with_estimate(file, data_dir, source)
    row: dict = {"dataset": graph.name, "model": model, "dim": graph.dim, "poses": graph.n,
                 "edges": graph.m, "components": graph.n_components}
    fim = fisher_information(graph, est.rot, est.trans, model=model, anchor_id=anchor_id,
                             rotation_model=rotation_model, variant=variant,
                             frame=frame if model == "sed" else "world", ordering=ordering)
    times.update(fim.times)
    row.update(fim.to_row())
    row["ordering"] = fim.ordering
    if save:
        fim.save(save)
    row["frame"] = frame
    row["coordinates_description"] = coordinates_description(graph.dim, frame)
    if save:
        row["saved"] = save
    row["estimate"] = est_info
    row["times"] = times
    return row


@click.command("fim", cls=Command)
@click.argument("file", type=DatasetArg())
@model_option
@estimate_option
@click.option("--anchor", type=POSE_ID, default=None,
              help="Pose id anchored for the log-det; default: the smallest id (of each component, sed).")
@model_settings_options
@ordering_option
@click.option("--save", type=OutputFile((".npz",), append=".npz"), default=None,
              help="Write the FIM as a scipy sparse .npz with its index map "
                   "(row_pose_id, row_coordinate, coordinate_names) and its frame; .npz is appended "
                   "unless present. With --model sed --frame body it is comparable with a GTSAM Hessian.")
@data_dir_option
@format_option()
def command(file, model, estimate_source, anchor, rotation_model, fim_variant, frame, ordering, save, data_dir, fmt):
    """Fisher information matrix of FILE at an estimate: size, nnz, log-det, trace, rank.

    paper: anchored FIM of eq. (42) (2D) / (64) (3D), rows [translations; rotations]
    (rotation coordinates: angle in 2D, along G_k/sqrt(2) in 3D); logdet = D-optimality,
    trace = T-optimality (eq. 69/70), t_opt_approx = eq. (72). In 3D the default is the
    model's Fisher information (fim_variant=consistent); --fim-variant eq64 gives eq. (64)
    exactly as printed. sed: thesis FIM on SE(d)^n (size n q, pose-major), rank and nullity
    (nullity = q x components, Th. 4.8.1) and the log-det with one anchor per component; a
    numerically singular FIM has logdet null with a logdet_status and a warning. --frame world
    (default, the thesis' coordinates, rotation first) or body (GTSAM's and g2o's,
    F_body = M^-T F M^-1, M = blkdiag(-P Ad_{X_i^-1})): trace and the saved matrix change,
    log-det, rank and nullity do not. JSON: frame, coordinates_description, ordering (the
    log-det factorization's fill-reducing ordering, --ordering: cost only).
    """
    row = fim_row(file, data_dir, model, estimate_source, anchor, rotation_model, save, fim_variant, frame,
                  ordering)
    if fmt != "json":
        row = {k: (",".join(map(str, v)) if isinstance(v, list) else v) for k, v in row.items()}
    if fmt == "table":

        kv = key_value_rows(row)
        print_rows(kv, "table", title=f"FIM ({model}) of {row['dataset']}")
    else:
        print_rows([row], fmt)

