"""What a selection returns (``SelectResult``) and the pruned graph it keeps (fixed + selected edges).

One result class, under the result protocol (posecrb.core.result): ``select_edges`` makes it and
``posecrb.select`` passes it through; ``to_dict()`` is the ``select`` command's JSON object.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..core.errors import UsageError
from ..core.graph import PoseGraph
from ..core.result import CODEC, NESTED, Result, array_field, inputs_field, optional_field, part_field
from ..models.inputs import input_files
from ..solver.estimate import Estimate
from .budget import EdgeSplit
from .certificate import RatioCertificate


def _int_array_codec(width: int | None) -> tuple[Any, Any]:
    """An int64 array in Python, a list (of ``width``-lists) in JSON; None stays None."""

    def decode(value: Any) -> np.ndarray | None:
        if value is None:
            return None
        out = np.asarray(value, dtype=np.int64)
        if out.ndim != (1 if width is None else 2) or (width is not None and out.size and out.shape[1] != width):
            raise ValueError(f"not a list of {'integers' if width is None else f'{width} integers each'}")
        return out.reshape(-1, width) if width is not None else out

    return (lambda v: v), decode


@dataclass(frozen=True, kw_only=True)
class FixedEdges(Result):
    """The edges every selection keeps: the ``rule`` (``"odometry"`` or the pairs file), how many
    (``edges``), and those the odometry rule ``added_for_connectivity`` as ``[id_i, id_j, edge]``.

    Examples
    --------
    >>> import posecrb
    >>> fixed = posecrb.select("intel", budget=5).fixed
    >>> fixed.rule, fixed.edges
    ('odometry', 1727)
    """

    rule: str
    edges: int
    added_for_connectivity: list[list[int]]


@dataclass(frozen=True, kw_only=True)
class CertificateBounds(Result):
    """The bounds behind a selection's ``upper_bound``: the relaxation's (Frank-Wolfe, value plus
    duality gap), the submodular one (Minoux; log-det objectives), the relaxation's value at its
    last iterate, its iterations, whether it converged and its step rule.

    Examples
    --------
    >>> import posecrb
    >>> b = posecrb.select("intel", budget=5).certificate.bounds
    >>> b.submodular is not None, b.relaxation is None
    (True, True)
    """

    relaxation: float | None
    submodular: float | None
    relaxed_value: float | None
    iterations: int
    converged: bool | None
    step: str | None


@dataclass(frozen=True, kw_only=True)
class SelectionCertificate(Result):
    """A selection's ratio certificate (docs/design.md#glossary): ``upper_bound`` on the best
    ``budget``-subset's value, the smallest of the ``bounds``, and ``certified_ratio`` ``(value -
    base_value) / (upper_bound - base_value)``, the fraction of the best gain guaranteed.

    Examples
    --------
    >>> import posecrb
    >>> c = posecrb.select("intel", budget=5).certificate
    >>> 0 < c.certified_ratio <= 1
    True
    """

    upper_bound: float | None
    certified_ratio: float | None
    bounds: CertificateBounds = field(metadata={NESTED: CertificateBounds})

    @classmethod
    def of(cls, cert: RatioCertificate, value: float, base_value: float) -> SelectionCertificate:
        """The certificate of a selection of ``value`` over ``base_value``."""
        return cls(upper_bound=cert.upper_bound, certified_ratio=cert.ratio(value, base_value),
                   bounds=CertificateBounds(relaxation=cert.relaxation_bound, submodular=cert.submodular_bound,
                                            relaxed_value=cert.relaxed_value, iterations=cert.iterations,
                                            converged=cert.converged, step=cert.step))


@dataclass(frozen=True, kw_only=True)
class SelectResult(Result):
    """A measurement selection with its certificate: what ``posecrb select`` prints.

    ``budget`` of the ``candidates`` edges (every edge not ``fixed``) chosen to maximise the
    ``objective`` (natural log): ``"tree"``, ``d logdet L_tau + d_r logdet L_w`` (eq. 75, the
    weighted tree-connectivity); ``"fim"``, the log-det of the anchored paper FIM (consistent
    variant) at the estimate; ``"fiedler"``, lambda_2 of the rotation-weighted Laplacian. The
    ``certificate``'s ``upper_bound`` bounds the best ``budget``-subset's value, so its
    ``certified_ratio`` is the fraction of the best gain guaranteed.

    ``to_dict()`` is the command's JSON object (the certificate's keys inlined); ``selected`` lists
    ``[id_i, id_j, edge]`` with the pose ids of the edge's ends and its position among the file's
    edges (0-based). ``to_frame()`` has one row per selected edge: ``id_i``, ``id_j``, ``edge`` and
    ``step`` (the greedy step that chose it, 1-based; None for the other methods).
    ``pruned_graph(graph)`` is the graph with the fixed and the selected edges only (write it with
    ``posecrb.io.write_g2o``).

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
    fixed : FixedEdges
        The rule, the number of fixed edges and those added for connectivity.
    candidates : int
        Number of candidate edges.
    selected : numpy.ndarray
        (K, 3) ``[id_i, id_j, edge]`` per selected edge (``selected_edges``: the edge column).
    value, base_value, full_value : float
        The objective with the selection, with the fixed edges only, with every candidate.
    certificate : SelectionCertificate
        ``upper_bound``, ``certified_ratio`` (None when no bound was computed) and the ``bounds``
        behind them (relaxation, submodular) with Frank-Wolfe's state.
    order : numpy.ndarray or None
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
        The pruned graph the command line's ``--out`` wrote.
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
    fixed: FixedEdges = field(metadata={NESTED: FixedEdges})
    candidates: int
    selected: np.ndarray = field(compare=False, metadata={CODEC: _int_array_codec(3)})
    value: float
    base_value: float
    full_value: float
    certificate: SelectionCertificate = part_field(SelectionCertificate)
    order: np.ndarray | None = field(compare=False, metadata={CODEC: _int_array_codec(None)})
    rounding: str | None
    seed: int
    stats: dict[str, Any]
    estimate: Estimate | None = field(default=None, metadata={NESTED: Estimate})
    saved: str | None = optional_field()
    times: dict[str, float] = field(default_factory=dict)
    fixed_edges: np.ndarray = array_field()
    inputs: tuple[str, ...] = inputs_field()

    @property
    def upper_bound(self) -> float | None:
        """``certificate.upper_bound``."""
        return self.certificate.upper_bound

    @property
    def certified_ratio(self) -> float | None:
        """``certificate.certified_ratio``."""
        return self.certificate.certified_ratio

    @property
    def selected_edges(self) -> np.ndarray:
        """The selected edges' positions in the file (file order, int64)."""
        return np.asarray(self.selected, dtype=np.int64).reshape(-1, 3)[:, 2]

    @property
    def kept_edges(self) -> np.ndarray:
        """The fixed and the selected edges (positions, sorted): the pruned graph's edges."""
        if self.fixed.edges and np.size(self.fixed_edges) != self.fixed.edges:
            raise UsageError("this SelectResult carries no fixed edges (rebuilt from a dict); "
                             "SelectResult.load of a saved result has them")
        return np.union1d(np.asarray(self.fixed_edges, dtype=np.int64), self.selected_edges)

    def pruned_graph(self, graph: PoseGraph) -> PoseGraph:
        """``graph`` (the one selected from) with the fixed and the selected edges only, every vertex
        kept; its ``path`` is still ``graph``'s, so no writer writes it over that file."""
        if graph.m != self.edges or graph.n != self.poses:
            raise UsageError(f"the selection is of a graph of {self.poses} poses and {self.edges} edges, not of "
                             f"{graph.name} ({graph.n} poses, {graph.m} edges)")
        return pruned_graph(graph, self.kept_edges)

    def to_frame(self) -> Any:
        """One row per selected edge: ``id_i``, ``id_j``, ``edge`` and the greedy ``step``."""
        import pandas as pd  # noqa: PLC0415 -- lazy: start-up time (pandas only for frames)

        step = {int(e): k + 1 for k, e in enumerate([] if self.order is None else self.order)}
        rows = np.asarray(self.selected, dtype=np.int64).reshape(-1, 3).tolist()
        return pd.DataFrame([{"id_i": a, "id_j": b, "edge": e, "step": step.get(e)} for a, b, e in rows],
                            columns=["id_i", "id_j", "edge", "step"])


def selection_result(graph: PoseGraph, *, anchor: int, objective: str, method: str, budget: int, budget_spec: str,
                     split: EdgeSplit, chosen: np.ndarray, value: float, base_value: float, full_value: float,
                     certificate: RatioCertificate, rounding: str | None, order: np.ndarray | None, seed: int,
                     stats: dict[str, Any], estimate: Estimate | None, times: dict[str, float]) -> SelectResult:
    """The ``SelectResult`` of choosing the edges ``chosen`` (indices, file order) of ``graph`` with the
    fixed edges of ``split``; ``anchor`` an internal index."""
    ends = np.stack([graph.ids[graph.src], graph.ids[graph.dst]], axis=1)
    chosen = np.asarray(chosen, dtype=np.int64)
    triples = np.concatenate([ends[chosen], chosen[:, None]], axis=1) if chosen.size else np.zeros((0, 3), np.int64)
    added = np.asarray(split.connectivity, dtype=np.int64)
    fixed = FixedEdges(rule=split.rule, edges=int(split.fixed.size),
                       added_for_connectivity=np.concatenate([ends[added], added[:, None]], axis=1).tolist()
                       if added.size else [])
    return SelectResult(dataset=graph.name, path=graph.path, dim=graph.dim, poses=graph.n, edges=graph.m,
                        anchor=int(graph.ids[anchor]), objective=objective, method=method, budget=int(budget),
                        budget_spec=budget_spec, fixed=fixed, candidates=int(split.candidates.size),
                        selected=triples, value=float(value), base_value=float(base_value),
                        full_value=float(full_value),
                        certificate=SelectionCertificate.of(certificate, value, base_value),
                        rounding=rounding, order=None if order is None else np.asarray(order, dtype=np.int64),
                        seed=int(seed), stats=stats, estimate=estimate, times=times,
                        fixed_edges=np.asarray(split.fixed, dtype=np.int64),
                        inputs=input_files(graph, estimate) + (() if split.rule == "odometry" else (split.rule,)))


def pruned_graph(graph: PoseGraph, keep: np.ndarray) -> PoseGraph:
    """The graph with only the edges ``keep`` (indices, file order); vertices and estimate kept."""
    keep = np.sort(np.asarray(keep, dtype=np.int64))
    lines = graph.edge_lines[keep] if graph.edge_lines is not None else None
    return replace(graph, src=graph.src[keep], dst=graph.dst[keep], rot=graph.rot[keep],
                   trans=graph.trans[keep], info=graph.info[keep], edge_lines=lines, sha256=None)
