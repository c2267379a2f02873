"""The paper model behind the one model protocol (``posecrb.models.Model``): its FIM and its CRLB at
an estimate as the public results ``FimResult`` and ``CrlbResult``.

Chen et al.'s anchored FIM on (R^d x SO(d))^n with isotropic noise (docs/design.md#paper-fim) and
its CRLB, with eq. (68)'s curvature term in 3D (docs/design.md#crlb). Anchors and per-pose
requests are pose ids here, internal indices below.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

from ...core.choices import FimVariant, Ordering, RotationWeight
from ...core.errors import ArgumentError
from ...core.graph import PoseGraph
from ...core.status import OK
from ...linalg.ordering import resolve_ordering
from ...solver.estimate import Estimate
from ..inputs import input_files
from ..results import CrlbResult, FimResult, accuracy_keys, graph_keys
from .bounds import t_optimality
from .crlb import paper_crlb
from .fim import fim_logdet_accuracy, fim_symbolic_choice, paper_fim, trace_fim


@dataclass(frozen=True, kw_only=True)
class PaperSettings:
    """The paper model's settings: the 3D rotation weight (eq. 59, or the fit to the printed
    Table II), the FIM variant (the model's Fisher information, or eq. 64 as printed) and the
    factorizations' fill-reducing ordering (cost only)."""

    rotation_weight: RotationWeight = "eq59"
    fim_variant: FimVariant = "consistent"
    ordering: Ordering = "auto"


@dataclass(frozen=True)
class PaperModel:
    """Chen et al.'s model on (R^d x SO(d))^n with its settings (``posecrb.models.Model``)."""

    settings: PaperSettings = field(default_factory=PaperSettings)
    name: ClassVar[str] = "paper"

    def fim(self, graph: PoseGraph, estimate: Estimate, *, anchor: int | None = None) -> FimResult:
        """The anchored FIM at ``estimate``, anchored at the pose id ``anchor`` (default the smallest
        id): eq. (42)/(64), its log-det and its accuracy, trace (eq. 69/70), eq. (72)'s
        approximation."""
        opts = self.settings
        idx = graph.anchor_index(anchor)
        fim = paper_fim(graph, estimate.rot, estimate.trans, anchor=idx, rotation_weight=opts.rotation_weight,
                        variant=opts.fim_variant)
        times = {"fim_build": fim.build_time}
        t0 = time.perf_counter()
        sym, choice = fim_symbolic_choice(fim, opts.ordering)
        factor, logdet = sym.factor_logdet(fim.matrix, name="paper FIM")
        times["fim_logdet"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        acc = fim_logdet_accuracy(fim, factor, logdet, graph, estimate.rot, estimate.trans)
        times["logdet_accuracy"] = time.perf_counter() - t0
        ids, coord = fim.index_map()
        return FimResult(**graph_keys(graph, self.name), anchors=[fim.anchor_id], layout=fim.layout, size=fim.size,
                         nnz=fim.nnz, logdet=logdet, logdet_status=acc.status, logdet_accuracy=accuracy_keys(acc),
                         trace=trace_fim(fim), t_opt_approx=t_optimality(graph, idx, opts.rotation_weight)[1],
                         rank=fim.size, nullity=0, rotation_weight=opts.rotation_weight,
                         fim_variant=fim.variant, ordering={"requested": opts.ordering, "fim": str(choice)},
                         frame="mixed", estimate=estimate, times=times, matrix=fim.matrix, row_ids=ids,
                         row_coord=coord, coordinate_names=fim.coordinate_names(),
                         inputs=input_files(graph, estimate))

    def crlb(self, graph: PoseGraph, estimate: Estimate, *, anchors: Sequence[int] = (),
             poses: bool | Sequence[int] = False) -> CrlbResult:
        """``C >= F^{-1}`` of the FIM anchored at one pose id (2D eq. 67; 3D with eq. 68's curvature
        term); per-pose blocks for every pose (``poses=True``) or the listed pose ids."""
        opts = self.settings
        if len(anchors) > 1:
            raise ArgumentError("anchor", list(anchors), "is several anchors; the paper model takes one (its graph "
                                "must be connected)")
        idx = graph.anchor_index(anchors[0] if anchors else None)
        if poses is not True and poses:
            for p in poses:
                graph.index_of(p, "poses")
        res = paper_crlb(graph, estimate.rot, estimate.trans, anchor=idx, per_pose=poses,
                         rotation_weight=opts.rotation_weight, variant=opts.fim_variant,
                         ordering=opts.ordering)
        usable = res.accuracy is None or res.accuracy.status.available
        three = graph.dim == 3
        ordering = {"requested": opts.ordering,
                    "crlb": str(resolve_ordering(opts.ordering, dim=graph.dim, poses=graph.n, matrix="crlb"))}
        return CrlbResult(**graph_keys(graph, self.name), kind="anchored", fim_variant=res.fim_variant,
                          rotation_weight=opts.rotation_weight, anchors=[res.anchor_id], nullity=0,
                          accuracy=res.accuracy, trace_crlb=res.trace_crlb, mse_bound=res.mse_bound,
                          trace_translation=res.trace_translation, trace_rotation=res.trace_rotation,
                          trace_crlb_curvature=res.trace_crlb_curvature if three else None,
                          mse_bound_curvature=res.mse_bound_curvature if three else None,
                          curvature_correction_max=res.curvature_correction_max if three else None,
                          curvature_status=res.curvature_status if three else OK, coordinates=res.coordinates,
                          frame="mixed", ordering=ordering,
                          per_pose=res.per_pose if usable else None,
                          per_pose_curvature=res.per_pose_curvature if usable else None,
                          estimate=estimate, times=dict(res.times), inputs=input_files(graph, estimate))
