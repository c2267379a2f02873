"""``posecrb verify FILE --estimate EST``: is an estimate another program computed the global optimum?"""
from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

import click

from ...api.verify import verify
from ...core.choices import ESTIMATE_FORMATS, REQUIRED_VERDICTS, ROW_ORDERS
from ...core.errors import PosecrbError
from ...core.status import log_statuses
from ...report.render import print_rows
from ..options import POSE_ID, FiniteFloat, data_dir_option, format_option, load_dataset
from ..paths import Command, DatasetArg

log = logging.getLogger("posecrb")

HEADERS = {"quantity": "quantity", "value": "value"}
# The flat row of csv and markdown: the scalar keys, the nested objects' main numbers.
ROW_KEYS = ("dataset", "poses", "edges", "verdict", "objective", "optimum_objective", "suboptimality",
            "relative_suboptimality", "lower_bound", "refined_objective", "gradient_norm", "lambda_min", "ate_trans",
            "ate_rot_deg", "rpe_trans", "rpe_rot_deg", "alignment", "g2o_cost", "g2o_cost_optimum")


def _number(value: Any, digits: int = 9) -> str:
    return "n/a" if value is None else f"{value:.{digits}g}" if isinstance(value, float) else str(value)


def _summary(d: dict[str, Any]) -> list[dict[str, Any]]:
    """The result as (quantity, value) rows for the terminal table, the verdict first."""
    c, m = d["certificate"], d.get("mahalanobis")
    why = d["verdict_reason"].split("; ")
    rows: list[tuple[str, Any]] = [
        ("verdict", d["verdict"]),
        *(("why" if k == 0 else "", part) for k, part in enumerate(why)),
        ("graph", f"{d['dataset']} ({d['dim']}D, {d['poses']} poses, {d['edges']} edges)"),
        ("estimate", f"{d['estimate'].get('path') or d['estimate'].get('source')} "
                     f"({d['estimate'].get('format', 'in memory')})"),
        ("F at the estimate", _number(d["objective"])),
        ("F at the certified optimum", _number(d["optimum_objective"])),
        ("suboptimality (relative)", f"{_number(d['suboptimality'], 6)} ({_number(d['relative_suboptimality'], 3)})"),
        ("proven lower bound on F", f"{_number(d['lower_bound'])} ({d['lower_bound_source'] or 'none proven'})"),
        ("F where the refinement ends", _number(d["refined_objective"])),
        ("certificate at the estimate", f"lambda_min(Q - Lambda) = {d['lambda_min']:.3e}: "
                                        f"{'holds' if c['certified'] else 'fails'}; "
                                        f"{'critical' if c['critical'] else 'not critical'} (tolerance "
                                        f"{c['tolerance']:.3g})"),
        ("relative gradient norm", _number(d["gradient_norm"], 3)),
        (f"ATE ({d['alignment']} alignment), rotation", f"{_number(d['ate_trans'], 4)}, "
                                                       f"{_number(d['ate_rot_deg'], 3)} deg"),
        ("RPE, rotation", f"{_number(d['rpe_trans'], 4)}, {_number(d['rpe_rot_deg'], 3)} deg"),
    ]
    if m:
        rows.append(("delta^T F delta / dof", f"{_number(m['per_dof'], 4)} ({m['dof']} dof); largest per pose "
                                              f"{_number(m['max_pose'], 4)} at id {m['max_pose_id']}"))
    rows.append(("g2o chi2 at the estimate, at the optimum", f"{_number(d['g2o_cost'], 6)}, "
                                                             f"{_number(d['g2o_cost_optimum'], 6)}"))
    if d.get("truth"):
        t = d["truth"]
        rows.append(("ATE to the truth: estimate, optimum", f"{_number(t['estimate']['ate_trans'], 4)}, "
                                                            f"{_number(t['optimum']['ate_trans'], 4)}"))
        rows.append(("NEES of the estimate", _number(t["nees"], 4)))
    rows.append(("time (s)", ", ".join(f"{k} {v:.3g}" for k, v in d["times"].items())))
    return [{"quantity": k, "value": v} for k, v in rows]


@click.command("verify", cls=Command, short_help="Is an estimate another program computed the global optimum? "
               "Certificate, basin and distances to the certified optimum.")
@click.argument("file", type=DatasetArg())
@click.option("--estimate", "estimate", required=True, type=DatasetArg(),
              help="The estimate to judge, a path or a dataset name: g2o or TORO VERTEX lines (g2o, GTSAM's "
                   "writeG2o, posecrb solve --out; FILE itself judges its own vertices), Ceres' 'id x y yaw' / "
                   "'id x y z qx qy qz qw' lines, TUM 'timestamp x y z qx qy qz qw' lines or KITTI's 12 numbers "
                   "per line.")
@click.option("--estimate-format", type=click.Choice(ESTIMATE_FORMATS), default="auto", show_default=True,
              help="The estimate file's format; auto reads it from the content (8-column lines are Ceres' when "
                   "the first column is the graph's ids, TUM's otherwise).")
@click.option("--tum-ids", type=click.Choice(ROW_ORDERS), default="order", show_default=True,
              help="TUM and KITTI rows carry no ids: row k is the pose with the k-th smallest id (order), or "
                   "the TUM timestamp is the pose id (timestamps).")
@click.option("--truth", type=DatasetArg(), default=None,
              help="Ground truth of a synthetic graph (any estimate format; posecrb datasets synth writes it as "
                   "the vertices): also the errors of the estimate and of the optimum against it, and the "
                   "estimate's NEES.")
@click.option("--no-solve", is_flag=True,
              help="Only the certificate at the estimate (no solve, no refinement, no distances to the optimum): "
                   "certified-optimal or uncertified.")
@click.option("--require", type=click.Choice(REQUIRED_VERDICTS), default=None,
              help="Exit 1 when the verdict is weaker (certified-optimal > global-basin > local-minimum > "
                   "uncertified): a regression job's check that a back-end still finds the optimum.")
@click.option("--certificate-tol", type=FiniteFloat(min=0, min_open=True), default=1e-3, show_default=True,
              help="Accept lambda_min(Q - Lambda) >= -TOL as the certificate, as posecrb solve does.")
@click.option("--anchor", type=POSE_ID, default=None,
              help="Pose id of the gauge of the Mahalanobis distances; default: the smallest id.")
@data_dir_option
@format_option()
def command(file, estimate, estimate_format, tum_ids, truth, no_solve, require, certificate_tol, anchor, data_dir,
            fmt):
    """Is the estimate EST of FILE, computed by another program, the global optimum of the
    maximum-likelihood problem posecrb solve minimises? How far from it, in map units and in
    units of the CRLB?

    The verdict is one of: certified-optimal (the dual certificate holds at the estimate itself and
    it is a critical point within its digits), global-basin (the local refinement from it reaches
    the certified optimum), local-minimum (the refinement stops at a higher critical point),
    uncertified (the relaxation is not exact on this graph; or, with --no-solve, the certificate at
    the estimate does not hold). Tolerances follow from the digits the estimate file was written
    with. g2o_cost is g2o's own chi-square of the file's edges, a different cost from posecrb's.
    """
    graph, parse_seconds = load_dataset(file, data_dir)
    res = verify(graph, estimate, estimate_format=estimate_format, tum_ids=tum_ids, truth=truth, solve=not no_solve,
                 certificate_tol=certificate_tol, anchor=anchor)
    res = replace(res, times={"parse": parse_seconds, **res.times, "total": res.times["total"] + parse_seconds})
    d = res.to_dict()
    log_statuses(log, res.dataset, {k: v for k, v in res.statuses().items() if not no_solve or v.available})
    if fmt == "json":
        print_rows([d], fmt)
    elif fmt == "table":
        print_rows(_summary(d), fmt, ["quantity", "value"], headers=HEADERS,
                   title=f"{d['dataset']}: {d['verdict']}")
    else:
        print_rows([{k: d[k] for k in ROW_KEYS}], fmt)
    if require is not None and not res.at_least(require):
        raise PosecrbError(f"{res.dataset}: the verdict {res.verdict} is weaker than --require {require}")
