"""`posecrb fim FILE`: the Fisher information matrix at an estimate, paper or sed model."""
from __future__ import annotations

import logging
from dataclasses import replace

import click

from ...api.models import fim
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
)
from ..paths import Command, DatasetArg, OutputFile

log = logging.getLogger("posecrb")


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
def command(file, model, estimate_source, anchor, rotation_weight, fim_variant, frame, ordering, save, data_dir, fmt):
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
    res = fim(file, model=model, estimate=estimate_source, anchor=anchor, rotation_weight=rotation_weight,
              fim_variant=fim_variant, frame=frame, ordering=ordering, data_dir=data_dir)
    if save is not None:    # checked before the work (posecrb.cli.paths)
        res = replace(res, saved=res.save(save))
    log_statuses(log, res.dataset, res.statuses())
    row = res.to_dict()
    if fmt != "json":
        row = {k: (",".join(map(str, v)) if isinstance(v, list) else v) for k, v in row.items()}
    if fmt == "table":

        kv = key_value_rows(row)
        print_rows(kv, "table", title=f"FIM ({model}) of {row['dataset']}")
    else:
        print_rows([row], fmt)

