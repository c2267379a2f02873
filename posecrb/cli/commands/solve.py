"""``posecrb solve``: certified maximum-likelihood estimate (SE-Sync style), docs/design.md#solver."""
from __future__ import annotations

import logging
from dataclasses import replace

import click

from ...api.solve import solve, solve_times
from ...core.choices import INITS
from ...core.errors import SolverError
from ...core.status import log_status
from ...report.render import print_rows
from ..options import POSE_ID, FiniteFloat, PlainInt, data_dir_option, format_option, load_dataset
from ..paths import GRAPH_EXTENSIONS, Command, DatasetArg, OutputFile

log = logging.getLogger("posecrb")

# Compact column set for the human-readable formats; json/csv carry every key.
TABLE_COLUMNS = ["dataset", "dim", "poses", "edges", "objective", "duality_gap", "lambda_min", "certified", "rank",
                 "iterations", "hessian_vector_products", "times.total"]
HEADERS = {"hessian_vector_products": "HVPs", "times.total": "time s", "duality_gap": "gap",
           "lambda_min": "lambda_min(S)", "iterations": "TR its"}


@click.command("solve", cls=Command)
@click.argument("file", type=DatasetArg())
@click.option("--out", type=OutputFile(GRAPH_EXTENSIONS), default=None,
              help="Write the estimate as g2o: original ids and edges, vertices replaced by the estimate, "
                   "anchored so that the anchor pose is the identity.")
@format_option()
@click.option("--r0", type=PlainInt(2, 100), default=None,
              help="First rank of the Riemannian staircase [default: d+1].")
@click.option("--rmax", type=PlainInt(2, 100), default=10, show_default=True,
              help="Last rank of the Riemannian staircase.")
@click.option("--init", "init", type=click.Choice(INITS), default="chordal", show_default=True,
              help="Initial rotations: chordal relaxation, or the file's own vertices.")
@click.option("--anchor", type=POSE_ID, default=None,
              help="Pose id (as in the file) put at the identity in the output; default: the smallest id.")
@click.option("--certificate-tol", type=FiniteFloat(min=0, min_open=True), default=1e-3, show_default=True,
              help="Accept lambda_min(Q - Lambda) >= -TOL as a certificate of global optimality. It bounds "
                   "the suboptimality by n d TOL (absolute, the objective's units); a warning says when "
                   "that bound is not below the objective.")
@click.option("--sesync-compat", is_flag=True,
              help="Read 3D quaternions as SE-Sync does (unnormalised) to reproduce its objective values.")
@data_dir_option
def command(file, out, fmt, r0, rmax, init, anchor, certificate_tol, sesync_compat, data_dir):
    """Certifiably correct pose-graph optimisation of FILE (SE-Sync's Riemannian staircase).

    Prints the objective F = sum kappa||R_j - R_i R~||_F^2 + tau||t_j - t_i - R_i t~||^2 at the
    estimate, the relaxation value, the duality gap between them, lambda_min of the certificate
    matrix and phase times. The estimate is the lowest rounding of the staircase's levels; a
    warning says when a certified gap is more than rounding (the relaxation is not exact on
    this graph: the estimate is then within the gap of the optimum, not proven optimal).
    Exit code 1 when the result is not certified (the estimate is still written).
    With --sesync-compat the rotation term is SE-Sync's kappa(2d - 2 tr(R_j^T R_i R~)) with
    R~ from the unnormalised quaternions (posecrb.io.load(..., quaternions="raw")).
    """
    graph, parse_seconds = load_dataset(file, data_dir, quaternions="raw" if sesync_compat else "normalize")
    res = solve(graph, r0=r0, rmax=rmax, init=init, anchor=anchor, certificate_tol=certificate_tol,
                sesync_compat=sesync_compat)
    res = replace(res, times=solve_times(res.times, parse_seconds))
    if out is not None:    # checked before the work (posecrb.cli.paths)
        from ...io import load, write_g2o  # noqa: PLC0415 -- lazy: start-up time

        # edges as the normalised reading: a raw, non-orthogonal R~ has no quaternion of its own
        write_g2o(load(graph.path) if sesync_compat and graph.path else graph, out, res.rot, res.trans)
        res = replace(res, saved=out)
    row = res.to_dict()
    human = fmt in ("table", "markdown")
    if human:   # the table formatter keeps 5 digits; the objective deserves all of SE-Sync's
        row = {**row, "objective": f"{res.objective:.11g}"}
    print_rows([row], fmt, columns=TABLE_COLUMNS if human else None, headers=HEADERS if human else None)
    log_status(log, f"{res.dataset}: duality gap", res.duality_gap_status)
    if not res.certified:
        raise SolverError(f"{res.dataset}: uncertified: {res.reason}")
