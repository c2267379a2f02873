"""``VerifyResult``: the judgement of an estimate, what ``posecrb verify`` prints (docs/design.md#verify)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ..core.choices import Verdict
from ..core.result import GraphKeys, inputs_field, internal_field, optional_field, shared_status_field
from ..core.status import OK, Status

# --require: how strong each verdict is (uncertified proves nothing)
STRENGTH = {"certified-optimal": 3, "global-basin": 2, "local-minimum": 1, "uncertified": 0}


@dataclass(frozen=True, kw_only=True)
class VerifyResult(GraphKeys):
    """Whether an estimate computed elsewhere is the global optimum of the maximum-likelihood
    problem ``posecrb solve`` minimises, how far it is from it, and in which units that matters.

    ``verdict`` is exactly one of:

    * ``"certified-optimal"``: the dual certificate at the estimate's own rotations holds and the
      estimate is a critical point within its digits: proven globally optimal (within
      ``objective - lower_bound``), without any solve;
    * ``"global-basin"``: not itself optimal, but the local refinement from it reaches the certified
      optimum (``refined_objective`` equals ``optimum_objective`` within tolerance);
    * ``"local-minimum"``: the refinement from it stops at a higher critical point;
    * ``"uncertified"``: nothing is proven: the relaxation is not exact on this graph (``solve``
      cannot certify its own estimate), or, without a solve, the certificate at the estimate does
      not hold.

    ``to_dict()`` is the command's JSON object. Objectives are SE-Sync's ``F`` (no factor 1/2), in
    the file's units. ``g2o_cost`` is g2o's chi-square of the file's own edges, a different cost
    (it keeps the anisotropic information matrices), so an estimate may have a lower ``g2o_cost``
    than the optimum of F without being F's optimum.

    Attributes
    ----------
    dataset, path, sha256 : str or None
        The graph.
    dim, poses, edges : int
        d, n, m.
    anchor : int
        The pose id of the anchored gauge (the Mahalanobis distances).
    estimate : dict
        Where the estimate comes from (``path``, ``format``) and the largest quanta (units of the
        last written digit) of its rotation and translation numbers.
    verdict : {"certified-optimal", "global-basin", "local-minimum", "uncertified"}
        The answer; ``verdict_reason`` says why.
    objective : float
        F at the estimate as given.
    optimum_objective : float or None
        F at the certified optimum (``posecrb solve``'s objective); None without a solve.
    suboptimality, relative_suboptimality : float or None
        ``objective - optimum_objective``, and that over ``optimum_objective``.
    lower_bound : float or None
        A proven lower bound on F over all poses (the larger of the certificates' at the estimate
        and at the optimum); ``lower_bound_source`` says which.
    refined_objective : float or None
        F where the rank-d refinement from the estimate ends (the estimate's own F with optimal
        translations when it is certified; None without a solve).
    gradient_norm : float
        The relative norm of the Riemannian gradient at the estimate's rotations (0 at a critical
        point, at most 1).
    lambda_min : float
        ``lambda_min(Q - Lambda)`` of the certificate at the estimate's rotations.
    certificate : dict
        The test at the estimate: ``certified`` (the certificate holds at ``certificate_tol``),
        ``critical``, the Newton ``decrement`` and the ``translation_excess`` against ``tolerance``
        (units of F: the solver's own tolerance or what the estimate's digits allow), the
        ``proven_shift`` and the ``lower_bound`` it proves.
    refinement : dict or None
        The refinement's iterations, its end's relative gradient norm and why it stopped.
    ate_trans, ate_rot_deg, rpe_trans, rpe_rot_deg : float or None
        Trajectory errors of the estimate against the optimum (``alignment``: rigid, Umeyama).
    mahalanobis : dict or None
        ``delta^T F delta`` of the difference with the optimum (``total``), its degrees of freedom
        (``dof``), their ratio (``per_dof``), the largest per-pose distance with the CRLB's marginal
        blocks (``max_pose`` at ``max_pose_id``) and which FIM (``posecrb fim``'s default).
    g2o_cost, g2o_cost_optimum : float or None
        g2o's chi-square at the estimate and at the optimum.
    truth : dict or None
        With a ground truth: the trajectory errors of the estimate and of the optimum against it,
        and the estimate's NEES against the CRLB at the truth.
    times : dict of str to float
        Seconds per step.

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.verify("intel", posecrb.solve("intel"), solve=False)
    >>> res.verdict, res.certificate["certified"], res.optimum_objective is None
    ('certified-optimal', True, True)
    >>> res.at_least("global-basin")
    True
    >>> sorted(res.statuses())
    ['optimum']
    """

    anchor: int
    estimate: dict[str, Any]
    verdict: Verdict
    verdict_reason: str
    objective: float
    optimum_objective: float | None = shared_status_field("optimum_status")
    suboptimality: float | None = shared_status_field("optimum_status")
    relative_suboptimality: float | None = shared_status_field("optimum_status")
    lower_bound: float | None
    lower_bound_source: str | None
    refined_objective: float | None = shared_status_field("optimum_status")
    gradient_norm: float
    lambda_min: float
    certificate: dict[str, Any]
    refinement: dict[str, Any] | None
    ate_trans: float | None = shared_status_field("optimum_status")
    ate_rot_deg: float | None = shared_status_field("optimum_status")
    rpe_trans: float | None = shared_status_field("optimum_status")
    rpe_rot_deg: float | None = shared_status_field("optimum_status")
    alignment: str
    mahalanobis: dict[str, Any] | None = shared_status_field("optimum_status")
    g2o_cost: float
    g2o_cost_optimum: float | None = shared_status_field("optimum_status")
    truth: dict[str, Any] | None = optional_field()
    times: dict[str, float] = field(default_factory=dict)
    optimum_status: Status = internal_field(OK)
    inputs: tuple[str, ...] = inputs_field()

    def statuses(self) -> dict[str, Status]:
        """The optimum's status, which every number that needs it shares: unavailable without a
        solve, a warning where the relaxation is not exact (the optimum is the best estimate found)."""
        return {"optimum": self.optimum_status}

    @classmethod
    def _restore(cls, kwargs: dict[str, Any], d: Mapping[str, Any]) -> None:
        if d.get("optimum_objective_status") is not None:
            kwargs["optimum_status"] = Status.from_json(d["optimum_objective_status"])

    def at_least(self, verdict: Verdict) -> bool:
        """Whether the verdict is at least as strong as ``verdict`` (certified-optimal, global-basin,
        local-minimum, uncertified, strongest first)."""
        return STRENGTH[self.verdict] >= STRENGTH[verdict]
