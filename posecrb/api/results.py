"""``SelectResult`` (``posecrb.select``).

It follows the result protocol (``posecrb.core.result``): ``to_dict()`` is the ``bounds`` /
``select`` command's ``--format json`` object, field by field in the same order.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from ..core.result import NESTED, Result, optional_field
from ..solver.estimate import Estimate


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

