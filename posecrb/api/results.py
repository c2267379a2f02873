"""``BoundsResult`` (``posecrb.bounds``) and ``SelectResult`` (``posecrb.select``).

Both follow the result protocol (``posecrb.core.result``): ``to_dict()`` is the ``bounds`` /
``select`` command's ``--format json`` object, field by field in the same order.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from ..core.result import NESTED, Result, optional_field, status_field
from ..core.status import Status
from ..solver.estimate import Estimate


@dataclass(frozen=True, kw_only=True)
class BoundsResult(Result):
    """D-optimality of a pose graph: the paper's Table I/II row, what ``posecrb bounds`` prints.

    The graph-only bounds on the log-determinant of the paper model's anchored FIM (section
    VII-B): ``lb = d logdet(L_tau) + d_r logdet(L_w)`` (eq. 75 left, Algorithm 1),
    ``ub`` the paper's Table I/II upper bound (eq. 75 middle with the measured p_ij),
    ``ub_lambda`` eq. 75 right with lambda_inf (eq. 77), Lemma 4's bound on ``fim_logdet - lb``,
    and T-optimality (eq. 73, 72); with an estimate, ``fim_logdet`` is the log-det of the FIM
    itself there (``fim_variant``: ``"consistent"``, the model's Fisher information, or
    ``"eq64"`` as printed). Natural logarithms. Translations are in the file's length units:
    scaling every length by s scales the translation information by 1/s^2 and moves ``lb``,
    ``ub``, ``ub_lambda`` and ``fim_logdet`` together by ``-2 d n_p log s`` (n_p = n - 1).
    3D rotation weights by eq. (59) or the ``"table2"`` fit (``rotation_weight``).

    ``to_dict()`` is the command's JSON object (``status`` is ``"uncertified"`` when the solver
    did not certify the estimate, absent otherwise); ``to_frame()`` one row of it, so that
    ``pandas.concat`` of several is a table over datasets.

    Attributes
    ----------
    dataset, path, sha256 : str or None
        The graph's name, file and the file's sha256.
    dim, poses, edges, components : int
        d, n, m and the number of connected components.
    anchor : int
        The anchored pose id.
    rotation_weight : str
        ``"eq59"`` or ``"table2"``.
    lb, ub, ub_lambda : float or None
        The bounds (``ub`` None when unavailable, see ``ub_status``).
    lambda_inf : float
        eq. (77)'s lambda_inf.
    lambda_min_rot, lambda_min_rot_lower : float or None
        lambda_min(L_w) (an upper estimate) and a certified lower bound of it.
    gap_bound : float or None
        Lemma 4: ``0 <= logdet F - lb <= gap_bound``.
    t_opt_graph, t_opt_approx : float
        T-optimality, eq. (73) and eq. (72).
    total_degree : int
        Sum of the degrees of the free poses.
    times : dict of str to float
        Seconds per step (medians of ``repeat`` runs).
    runs : dict of str to int
        Per key of ``times``: how many runs its median is of.
    fim_logdet, trace_fim : float or None
        log det and trace of the FIM at the estimate (None without one). ``fim_logdet_status``
        is a warning when the log-det's rounding-error bound (``posecrb.linalg.accuracy``)
        exceeds 1e-6 relative, unavailable when no digit is correct.
    fim_variant : str or None
        The FIM's variant.
    estimate : Estimate or None
        Where the poses come from (None: ``estimate=None``).
    ordering : dict of str to str
        ``requested`` and the ordering of each factorization (``lb``, ``ub``, ``fim``).

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.bounds("intel")
    >>> round(res.lb, 3), round(res.ub, 3), round(res.fim_logdet, 3)
    (30155.231, 30352.516, 30194.332)
    >>> res.lb <= res.fim_logdet <= res.lb + res.gap_bound
    True
    """

    dataset: str
    path: str | None
    sha256: str | None
    dim: int
    poses: int
    edges: int
    components: int
    anchor: int
    rotation_weight: str
    lb: float
    ub: float | None
    ub_status: Status = status_field("ub")
    ub_lambda: float
    lambda_inf: float
    lambda_min_rot: float | None
    lambda_min_rot_status: Status = status_field("lambda_min(L_w)")
    lambda_min_rot_lower: float | None
    gap_bound: float | None
    gap_bound_status: Status = status_field("Lemma 4 gap bound")
    t_opt_graph: float
    t_opt_approx: float
    total_degree: int
    times: dict[str, float] = field(default_factory=dict)
    runs: dict[str, int] = field(default_factory=dict)
    fim_logdet: float | None = optional_field()
    fim_logdet_status: Status = status_field("FIM log-det")
    trace_fim: float | None = optional_field()
    fim_variant: str | None = optional_field()
    estimate: Estimate | None = optional_field(**{NESTED: Estimate})
    ordering: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        if self.estimate is not None and self.estimate.certified is False:
            ordering = out.pop("ordering")
            out["status"] = "uncertified"
            out["ordering"] = ordering
        return out


@dataclass(frozen=True, kw_only=True)
class SelectResult(Result):
    """A measurement selection with its certificate: what ``posecrb select`` prints.

    ``budget`` of the ``candidates`` edges (every edge not ``fixed``) chosen to maximise the
    ``objective`` (natural log): ``"tree"``, ``d logdet L_tau + d_r logdet L_w`` (eq. 75, the
    weighted tree-connectivity); ``"fim"``, the log-det of the anchored paper FIM (consistent
    variant) at the estimate; ``"fiedler"``, lambda_2 of the rotation-weighted Laplacian.
    ``upper_bound`` bounds the best ``budget``-subset's value, so ``certified_ratio = (value -
    base_value) / (upper_bound - base_value)`` is the fraction of the best gain guaranteed.

    ``to_dict()`` is the command's JSON object; ``selected`` lists ``[id_i, id_j, edge]`` with
    the pose ids of the edge's ends and its position among the file's edges (0-based).
    ``to_frame()`` has one row per selected edge: ``id_i``, ``id_j``, ``edge`` and ``step`` (the
    greedy step that chose it, 1-based; None for the other methods).

    Attributes
    ----------
    dataset, path : str or None
        The graph's name and file.
    dim, poses, edges : int
        d, n and m.
    anchor : int
        The anchored pose id (log-det objectives).
    objective, method : str
        What was maximised, and how (``greedy``, ``relax``, ``random``, ``naive``).
    budget : int
        K, the number of edges selected; ``budget_spec`` the budget as given.
    fixed : dict
        ``rule``, number of ``edges`` and the edges ``added_for_connectivity``.
    candidates : int
        Number of candidate edges.
    selected : list of list of int
        ``[id_i, id_j, edge]`` per selected edge.
    value, base_value, full_value : float
        The objective with the selection, with the fixed edges only, with every candidate.
    upper_bound, certified_ratio : float or None
        The certificate (None when no bound was computed).
    bounds : dict
        The bounds behind ``upper_bound`` (relaxation, submodular) and Frank-Wolfe's state.
    order : list of int or None
        Greedy: the edges in the order chosen.
    rounding : str or None
        relax: the rounding kept.
    seed : int
        Seed of the random choices.
    stats : dict
        The method's counters.
    estimate : Estimate or None
        ``"fim"`` objective: where the poses come from.
    saved : str or None
        The pruned graph written by ``out=``.
    times : dict of str to float
        Seconds per step.

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.select("intel", budget=5)
    >>> res.budget, res.candidates, len(res.selected)
    (5, 785, 5)
    >>> 0 < res.certified_ratio <= 1
    True
    >>> res.to_frame().columns.tolist()
    ['id_i', 'id_j', 'edge', 'step']
    """

    dataset: str
    path: str | None
    dim: int
    poses: int
    edges: int
    anchor: int
    objective: str
    method: str
    budget: int
    budget_spec: str
    fixed: dict[str, Any]
    candidates: int
    selected: list[list[int]]
    value: float
    base_value: float
    full_value: float
    upper_bound: float | None
    certified_ratio: float | None
    bounds: dict[str, Any]
    order: list[int] | None
    rounding: str | None
    seed: int
    stats: dict[str, Any]
    estimate: Estimate | None = field(default=None, metadata={NESTED: Estimate})
    saved: str | None = optional_field()
    times: dict[str, float] = field(default_factory=dict)

    def to_row(self) -> dict[str, Any]:
        """``to_dict()`` without the per-edge lists (``selected``, ``order``): one row of a table."""
        return {k: v for k, v in self.to_dict().items() if k not in ("selected", "order")}

    def to_frame(self) -> Any:
        """One row per selected edge: ``id_i``, ``id_j``, ``edge`` and the greedy ``step``."""
        import pandas as pd  # noqa: PLC0415 -- lazy: start-up time (pandas only for frames)

        step = {e: k + 1 for k, e in enumerate(self.order or [])}
        return pd.DataFrame([{"id_i": a, "id_j": b, "edge": e, "step": step.get(e)} for a, b, e in self.selected],
                            columns=["id_i", "id_j", "edge", "step"])


def selection_from_driver(d: Mapping[str, Any], saved: str | None) -> SelectResult:
    """The public result of the selection driver's ``to_dict()`` (its JSON object)."""
    res = SelectResult.from_dict(d)
    return res if saved is None else replace(res, saved=saved)

