"""``VerifyResult``: the judgement of an estimate, what ``posecrb verify`` prints (docs/design.md#verify)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, get_args

from ..core.result import Result, optional_field, status_field
from ..core.status import Status

Verdict = Literal["certified-optimal", "global-basin", "local-minimum", "uncertified"]
VERDICTS: tuple[str, ...] = get_args(Verdict)
# --require: the verdicts at least as strong as each (uncertified proves nothing)
STRENGTH = {"certified-optimal": 3, "global-basin": 2, "local-minimum": 1, "uncertified": 0}


@dataclass(frozen=True, kw_only=True)
class VerifyResult(Result):
    """Whether an estimate computed elsewhere is the global optimum of the maximum-likelihood
    problem ``posecrb solve`` minimises, how far it is from it, and in which units that matters.

    ``verdict`` is exactly one of:

    * ``"certified-optimal"``: the dual certificate at the estimate's own rotations holds and the
      estimate is a critical point within its digits: proven globally optimal (within
      ``objective - lower_bound``), without any solve;
    * ``"global-basin"``: not itself optimal, but the local refinement from it reaches the certified
      optimum (``refined_objective`` = ``optimum_objective`` within tolerance);
    * ``"local-minimum"``: the refinement from it stops at a higher critical point;
    * ``"uncertified"``: nothing is proven: the relaxation is not exact on this graph (``solve``
      itself cannot certify its optimum), or, without a solve, the certificate at the estimate
      does not hold.

    ``to_dict()`` is the command's JSON object. Objectives are SE-Sync's ``F`` (no factor 1/2) in
    the file's units; ``g2o_cost`` is g2o's chi-square of the file's own edges, a different cost
    (anisotropic information kept), so an estimate may have a lower ``g2o_cost`` than the optimum
    of F and still not be F's optimum.

    Attributes
    ----------
    dataset, path, sha256 : str or None
        The graph.
    dim, poses, edges : int
        d, n, m.
    anchor : int
        The pose id of the anchored gauge (ATE, Mahalanobis distances).
    estimate : dict
        ``path``, ``format`` and the largest quanta of its rotation and translation numbers.
    verdict : str
        One of ``VERDICTS``; ``verdict_reason`` says why.
    objective : float
        F at the estimate as given.
    optimum_objective : float or None
        F at the certified optimum (``posecrb solve``'s objective); None without a solve.
    suboptimality, relative_suboptimality : float or None
        ``objective - optimum_objective``, and over ``optimum_objective``.
    lower_bound : float or None
        A proven lower bound on F over all poses (the larger of the certificates' at the estimate
        and at the optimum); ``lower_bound_source`` says which.
    refined_objective : float or None
        F where the rank-d refinement from the estimate ends (None without a solve).
    gradient_norm : float
        The relative norm of the Riemannian gradient at the estimate's rotations (0 at a critical
        point, at most 1).
    lambda_min : float
        ``lambda_min(Q - Lambda)`` of the certificate at the estimate's rotations.
    certificate : dict
        The test at the estimate: ``certified`` (the certificate holds at ``tolerance``),
        ``critical``, the Newton ``decrement`` and ``translation_excess`` against ``tolerance``
        (F units), the ``proven_shift`` and the lower bound it proves.
    refinement : dict or None
        The refinement: iterations, relative gradient norm at its end, and whether its end is
        certified.
    ate_trans, ate_rot_deg, rpe_trans, rpe_rot_deg : float or None
        Trajectory errors of the estimate against the optimum (``alignment``: rigid, Umeyama).
    mahalanobis : dict or None
        ``delta^T F delta`` of the difference with the optimum (``total``), its degrees of freedom
        (``dof``), their ratio (``per_dof``), and the largest per-pose distance with the CRLB's
        marginal blocks (``max_pose`` at ``max_pose_id``); the FIM is ``posecrb fim``'s default.
    g2o_cost, g2o_cost_optimum : float or None
        g2o's chi-square at the estimate and at the optimum.
    truth : dict or None
        With a ground truth: the trajectory errors of the estimate and of the optimum against it,
        and the estimate's NEES against the CRLB at the truth.
    times : dict of str to float
        Seconds per step.
    """

    dataset: str
    path: str | None
    sha256: str | None
    dim: int
    poses: int
    edges: int
    anchor: int
    estimate: dict[str, Any]
    verdict: str
    verdict_reason: str
    objective: float
    optimum_objective: float | None
    optimum_objective_status: Status = status_field("optimum objective")
    suboptimality: float | None
    suboptimality_status: Status = status_field("suboptimality")
    relative_suboptimality: float | None
    relative_suboptimality_status: Status = status_field("relative suboptimality")
    lower_bound: float | None
    lower_bound_source: str | None
    refined_objective: float | None
    refined_objective_status: Status = status_field("refined objective")
    gradient_norm: float
    lambda_min: float
    certificate: dict[str, Any]
    refinement: dict[str, Any] | None
    ate_trans: float | None
    ate_trans_status: Status = status_field("ATE")
    ate_rot_deg: float | None
    ate_rot_deg_status: Status = status_field("ATE (rotation)")
    rpe_trans: float | None
    rpe_trans_status: Status = status_field("RPE")
    rpe_rot_deg: float | None
    rpe_rot_deg_status: Status = status_field("RPE (rotation)")
    alignment: str
    mahalanobis: dict[str, Any] | None
    mahalanobis_status: Status = status_field("Mahalanobis distance")
    g2o_cost: float
    g2o_cost_optimum: float | None
    g2o_cost_optimum_status: Status = status_field("g2o cost at the optimum")
    truth: dict[str, Any] | None = optional_field()
    times: dict[str, float] = field(default_factory=dict)

    def statuses(self) -> dict[str, Status]:
        """The statuses of the numbers, each distinct status once (without a solve every number that
        needs the optimum carries the same one)."""
        out: dict[str, Status] = {}
        seen: set[Status] = set()
        for quantity, status in super().statuses().items():
            if status not in seen:
                out[quantity] = status
                seen.add(status)
        return out

    def at_least(self, verdict: str) -> bool:
        """Whether the verdict is at least as strong as ``verdict`` (certified-optimal > global-basin
        > local-minimum > uncertified)."""
        return STRENGTH[self.verdict] >= STRENGTH[verdict]
