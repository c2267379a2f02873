"""`posecrb bounds FILE...`: D-optimality bounds (Table I/II row) per dataset."""
from __future__ import annotations

import logging

import click

from ...api.bounds import bounds
from ...core.errors import PosecrbError, status_of
from ...core.status import log_statuses
from ...report.render import print_rows
from ..options import (
    anchor_option,
    data_dir_option,
    fim_variant_option,
    format_option,
    make_estimate_option,
    ordering_option,
    repeat_option,
    rotation_weight_option,
)
from ..paths import Command, DatasetArg

log = logging.getLogger("posecrb")

TABLE_COLUMNS = ["dataset", "poses", "edges", "fim_logdet", "fim_variant", "times.fim_logdet", "ub", "times.ub", "lb",
                 "times.lb", "ub_lambda", "gap_bound", "estimate.source"]
HEADERS = {"times.lb": "lb time [s]", "times.ub": "ub time [s]", "ub_lambda": "ub (λ∞)",
           "gap_bound": "Lemma 4 gap ≤", "t_opt_graph": "T-opt (73)", "fim_logdet": "FIM logdet",
           "times.fim_logdet": "FIM time [s]", "estimate.source": "estimate", "fim_variant": "FIM variant"}


@click.command("bounds", cls=Command)
@click.argument("files", nargs=-1, required=True, type=DatasetArg())
@anchor_option
@repeat_option
@rotation_weight_option
@make_estimate_option("estimate", allow_none=True)
@fim_variant_option
@ordering_option
@data_dir_option
@format_option()
def command(files, anchor, repeat, rotation_weight, estimate, fim_variant, ordering, data_dir, fmt):
    """D-optimality of each FILE: FIM log-det at an estimate and its graph-only bounds (one
    Table I/II row per file).

    lb = d logdet(L_tau) + d_r logdet(L_w) (eq. 75, Algorithm 1); ub = the paper's
    Table I/II upper bound (eq. 75 middle, measured p_ij); ub_lambda = eq. 75 right
    with lambda_inf (eq. 77); gap_bound = Lemma 4; t_opt_graph = eq. (73).
    fim_logdet is log det of the anchored FIM at --estimate: the model's Fisher information
    (fim_variant=consistent) unless --fim-variant eq64 (eq. 64 as printed); same in 2D.
    lambda_min_rot and gap_bound carry a status when double precision cannot resolve them.
    Times follow --repeat (auto: one run of a stage that takes >= 1 s, else the median of a few
    after a warm-up; the JSON's runs says how many); the lb time covers the
    ordering and both factorizations, ub/ub_lambda their own extra work. --ordering changes
    the cost only; the JSON key "ordering" names the ordering of each factorization.
    """
    rows, failures = [], []
    for f in files:
        try:
            res = bounds(f, anchor=anchor, repeat=repeat, rotation_weight=rotation_weight, estimate=estimate,
                         fim_variant=fim_variant, ordering=ordering, data_dir=data_dir)
            log_statuses(log, res.dataset, res.statuses())
            rows.append(res.to_dict())
        except PosecrbError as exc:
            if len(files) == 1:
                raise
            log.error("%s", exc)
            failures.append(f)
            rows.append({"dataset": f, "status": status_of(exc), "error": str(exc)})
    columns = TABLE_COLUMNS + (["status"] if failures else [])
    print_rows(rows, fmt, columns=columns if fmt in ("table", "markdown") else None,
               headers=HEADERS, title="D-optimality bounds")
    uncertified = [r["dataset"] for r in rows if r.get("status") == "uncertified"]
    if uncertified:
        raise PosecrbError(f"the solver did not certify the estimate of: {', '.join(uncertified)}")
    if failures:
        raise PosecrbError(f"{len(failures)} of {len(files)} file(s) failed: {', '.join(failures)}")
