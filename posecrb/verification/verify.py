"""``verify_estimate``: the whole judgement of an estimate computed elsewhere (docs/design.md#verify).

1. The certificate at the estimate itself (posecrb.verification.judge): proven optimal or not.
2. The certified optimum (``posecrb.solver.solve``) and the suboptimality against it.
3. The basin: the rank-d refinement from the estimate (posecrb.solver.refine), and where it ends.
4. Distances to the optimum: ATE/RPE in map units, ``delta^T F delta`` and per-pose Mahalanobis
   distances in units of the CRLB, g2o's chi-square at both.
5. With a ground truth: the trajectory errors of both against it and the estimate's NEES.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..core.choices import Verdict
from ..core.graph import PoseGraph
from ..core.status import OK, Status
from ..models.paper.crlb import crlb_blocks
from ..models.paper.fim import paper_fim
from ..solver.problem import Problem
from ..solver.refine import refine
from ..solver.solve import SolveResult, solve, solver_thread_policy
from .distance import paper_delta, pose_mahalanobis, squared_mahalanobis
from .g2o_cost import g2o_chi2
from .judge import Judgement, Precision, judge
from .result import VerifyResult
from .trajectory import ALIGNMENT, trajectory_error

# The keys that need the certified optimum (they share its status).
_NEEDS_OPTIMUM = ("optimum_objective", "suboptimality", "relative_suboptimality", "refined_objective", "ate_trans",
                  "ate_rot_deg", "rpe_trans", "rpe_rot_deg", "mahalanobis", "g2o_cost_optimum")
# Where the refinement ends at the optimum's value within this fraction of it (beyond solve's own
# certified duality gap), it reached the optimum's basin: the trust region stops at a Newton
# decrement of 1e-11 F, and F is a sum of m positive terms rounded to about m eps relative.
BASIN_RTOL = 1e-8


@dataclass(frozen=True)
class Poses:
    """Poses to judge or to compare with: row k the pose with the k-th smallest id, and how
    precisely they were written (``describe``: the estimate object of the JSON)."""

    rot: np.ndarray
    trans: np.ndarray
    precision: Precision
    describe: dict[str, Any]


def verify_estimate(graph: PoseGraph, estimate: Poses, *, anchor: int = 0, run_solve: bool = True,
                    certificate_tol: float = 1e-3, truth: Poses | None = None) -> VerifyResult:
    """The judgement of ``estimate`` on ``graph`` (``anchor``: internal index of the gauge's pose)."""
    graph.require_connected()
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    problem = Problem.from_graph(graph)
    times["problem"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    with solver_thread_policy(graph):
        at_estimate = judge(problem, estimate.rot, estimate.trans, estimate.precision, certificate_tol=certificate_tol)
    times["certificate"] = time.perf_counter() - t1
    g2o_cost = g2o_chi2(graph, estimate.rot, estimate.trans)
    keys: dict[str, Any] = {
        "dataset": graph.name, "path": graph.path, "sha256": graph.sha256, "dim": graph.dim, "poses": graph.n,
        "edges": graph.m, "anchor": int(graph.ids[anchor]), "estimate": estimate.describe,
        "inputs": tuple(p for p in (graph.path, estimate.describe.get("path"),
                                    None if truth is None else truth.describe.get("path")) if p),
        "objective": at_estimate.objective, "gradient_norm": at_estimate.gradient_norm,
        "lambda_min": at_estimate.certificate.lambda_min,
        "certificate": _certificate_dict(at_estimate, certificate_tol),
        "alignment": ALIGNMENT, "g2o_cost": g2o_cost,
    }
    if not run_solve:
        return _without_solve(keys, at_estimate, times, t0)
    t1 = time.perf_counter()
    optimum = solve(graph, anchor=anchor, certificate_tol=certificate_tol)
    times["solve"] = time.perf_counter() - t1
    exact = optimum.certified and optimum.duality_gap_status.ok
    t1 = time.perf_counter()
    with solver_thread_policy(graph):
        refined = None if at_estimate.certified else refine(problem, estimate.rot)
    times["refine"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    with solver_thread_policy(graph):
        at_optimum = judge(problem, optimum.rot, optimum.trans, Precision.exact(graph.n),
                           certificate_tol=certificate_tol)
    times["optimum_certificate"] = time.perf_counter() - t1
    lower, source = _lower_bound(at_estimate, at_optimum, optimum, problem.n * problem.d, certificate_tol)
    f_opt = optimum.objective
    f_ref = at_estimate.objective_optimal_translations if refined is None else refined.objective
    verdict, reason = _verdict(at_estimate, exact, optimum, f_ref, certificate_tol)
    t1 = time.perf_counter()
    distances = _distances(graph, estimate, optimum, anchor)
    times["distances"] = time.perf_counter() - t1
    extra: dict[str, Any] = {}
    if truth is not None:
        t1 = time.perf_counter()
        extra["truth"] = _truth(graph, estimate, optimum, truth, anchor)
        times["truth"] = time.perf_counter() - t1
    times["total"] = time.perf_counter() - t0
    sub = at_estimate.objective - f_opt
    optimum_status = OK if optimum.certified else Status.warning(
        f"solve does not certify its estimate ({optimum.reason}): the optimum is the best estimate found")
    if not optimum.duality_gap_status.ok:
        optimum_status = optimum.duality_gap_status
    return VerifyResult(optimum_status=optimum_status,
        **keys, verdict=verdict, verdict_reason=reason, optimum_objective=f_opt, suboptimality=sub,
        relative_suboptimality=sub / abs(f_opt) if f_opt else None, lower_bound=lower, lower_bound_source=source,
        refined_objective=f_ref,
        refinement=None if refined is None else {
            "iterations": refined.iterations, "gradient_norm": refined.gradient.relative_norm,
            "status": refined.status, "hessian_vector_products": refined.hessian_vector_products},
        g2o_cost_optimum=g2o_chi2(graph, optimum.rot, optimum.trans), times=times, **distances, **extra)


def _certificate_dict(j: Judgement, tol: float) -> dict[str, Any]:
    return {"certified": j.certificate.certified, "critical": j.critical, "tolerance": j.tolerance,
            "decrement": None if np.isnan(j.decrement) else j.decrement, "translation_excess": j.translation_excess,
            "certificate_tol": tol, "proven_shift": j.proven_shift, "lower_bound": j.lower_bound}


def _without_solve(keys: dict[str, Any], j: Judgement, times: dict[str, float], t0: float) -> VerifyResult:
    skipped = Status.unavailable("not computed: --no-solve (the certified optimum was not computed)",
                                 hint="without --no-solve, verify also solves the graph and refines the estimate")
    verdict: Verdict
    if j.certified:
        verdict, reason = "certified-optimal", _certified_reason(j)
    else:
        verdict = "uncertified"
        reason = (f"{_not_certified_reason(j)}; without a solve (--no-solve) the optimum and the estimate's "
                  "basin are not known")
    times["total"] = time.perf_counter() - t0
    absent: dict[str, Any] = dict.fromkeys(_NEEDS_OPTIMUM + ("refinement",))
    return VerifyResult(**keys, **absent, optimum_status=skipped,
                        verdict=verdict, verdict_reason=reason, lower_bound=j.lower_bound,
                        lower_bound_source="certificate at the estimate" if j.lower_bound is not None else None,
                        times=times)


def _certified_reason(j: Judgement) -> str:
    assert j.lower_bound is not None
    return (f"the certificate holds at the estimate (lambda_min(Q - Lambda) = {j.certificate.lambda_min:.3e}) and it "
            f"is a critical point within its digits (Newton decrement {j.decrement:.3g}, translation excess "
            f"{j.translation_excess:.3g}, tolerance {j.tolerance:.3g}): globally optimal, within "
            f"{j.objective - j.lower_bound:.3g} of the optimum")


def _not_certified_reason(j: Judgement) -> str:
    parts = []
    if not j.certificate.certified:
        parts.append(f"the certificate fails at the estimate (lambda_min(Q - Lambda) = {j.certificate.lambda_min:.3e} "
                     f"< -{j.certificate.tol:g})")
    if not j.critical:
        what = (f"Newton decrement {j.decrement:.3g}, " if not np.isnan(j.decrement) else "") + \
            f"translation excess {j.translation_excess:.3g}"
        parts.append(f"it is not a critical point ({what}, relative gradient {j.gradient_norm:.3g}, tolerance "
                     f"{j.tolerance:.3g})")
    return " and ".join(parts)


def _verdict(j: Judgement, exact: bool, optimum: SolveResult, f_ref: float, tol: float) -> tuple[Verdict, str]:
    if j.certified:
        return "certified-optimal", _certified_reason(j)
    f_opt = optimum.objective
    gap = f_ref - f_opt
    where = f"the refinement from it ends at F = {f_ref:.9g}, {gap:+.3g} from the optimum's {f_opt:.9g}"
    if not exact:
        why = (optimum.duality_gap_status.reason if not optimum.duality_gap_status.ok
               else f"solve does not certify its estimate ({optimum.reason})")
        return "uncertified", f"{_not_certified_reason(j)}; {why}; {where}"
    if gap <= max(optimum.duality_gap, 0.0) + BASIN_RTOL * abs(f_opt):
        return "global-basin", f"{_not_certified_reason(j)}; {where}: the global optimum's basin"
    return "local-minimum", (f"{_not_certified_reason(j)}; {where} ({gap / abs(f_opt):.3g} relative): a higher "
                             "critical point, a local minimum (or saddle) of F")


def _lower_bound(at_est: Judgement, at_opt: Judgement, optimum: SolveResult, nd: int,
                 tol: float) -> tuple[float | None, str | None]:
    """The largest proven lower bound on F: the certificates' at the estimate and at the optimum, and
    solve's relaxation, certified at its rank with ``lambda_min >= -tol`` (``F_opt >= f(Y) - n d tol``,
    the bound that remains where the relaxation is not exact and the rounded optimum's certificate fails)."""
    relaxation = optimum.relaxation_value - nd * tol if optimum.certified else None
    candidates = [(b, s) for b, s in ((at_est.lower_bound, "certificate at the estimate"),
                                      (at_opt.lower_bound, "certificate at the optimum"),
                                      (relaxation, "solve's certified relaxation")) if b is not None]
    if not candidates:
        return None, None
    return max(candidates)


def _distances(graph: PoseGraph, estimate: Poses, optimum: SolveResult, anchor: int) -> dict[str, Any]:
    err = trajectory_error(estimate.rot, estimate.trans, optimum.rot, optimum.trans)
    fim = paper_fim(graph, optimum.rot, optimum.trans, anchor=anchor)
    delta = paper_delta(estimate.rot, estimate.trans, optimum.rot, optimum.trans, anchor)
    total = squared_mahalanobis(fim, graph, delta)
    dof = fim.size
    mahal: dict[str, Any] = {"total": total, "dof": dof, "per_dof": total / dof if dof else None,
                             "fim": f"paper model, {fim.variant} variant, rotation weight {fim.rotation_weight}, "
                                    f"anchored at pose {int(graph.ids[anchor])}, at the optimum"}
    status = OK
    # only the first-order blocks: eq. (68)'s curvature term is not part of the distance
    blocks, accuracy, _ = crlb_blocks(fim, graph)
    if accuracy is not None and not accuracy.status.available:
        status = Status.warning(f"the per-pose distances are not available: {accuracy.status.reason}")
        mahal.update(max_pose=None, max_pose_id=None)
    else:
        ids = fim.pose_ids
        values = pose_mahalanobis(ids, blocks, graph, delta)
        k = int(np.argmax(values)) if values.size else None
        mahal.update(max_pose=None if k is None else float(values[k]), max_pose_id=None if k is None else int(ids[k]))
    if not status.ok:
        mahal["max_pose_status"] = status.as_json()
    return {"ate_trans": err.ate_trans, "ate_rot_deg": err.ate_rot_deg, "rpe_trans": err.rpe_trans,
            "rpe_rot_deg": err.rpe_rot_deg, "mahalanobis": mahal}


def _truth(graph: PoseGraph, estimate: Poses, optimum: SolveResult, truth: Poses, anchor: int) -> dict[str, Any]:
    est = trajectory_error(estimate.rot, estimate.trans, truth.rot, truth.trans)
    opt = trajectory_error(optimum.rot, optimum.trans, truth.rot, truth.trans)
    fim = paper_fim(graph, truth.rot, truth.trans, anchor=anchor)
    delta = paper_delta(estimate.rot, estimate.trans, truth.rot, truth.trans, anchor)
    nees = squared_mahalanobis(fim, graph, delta) / fim.size if fim.size else None
    return {"source": truth.describe, "estimate": asdict(est), "optimum": asdict(opt), "nees": nees,
            "nees_dof": fim.size}


__all__ = ["BASIN_RTOL", "Poses", "verify_estimate"]
