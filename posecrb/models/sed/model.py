"""The sed model behind the one model protocol (``posecrb.models.Model``): its FIM and its CRLB at
an estimate as the public results ``FimResult`` and ``CrlbResult``.

The thesis's right-invariant FIM on SE(d)^n with the full information matrices
(docs/design.md#thesis-fim), its anchored (5.1) or quotient (5.5) bound (docs/design.md#anchored-crb),
in world or body coordinates (docs/design.md#frames). Anchors and per-pose requests are pose ids
here, internal indices below.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ...core.choices import Frame, Ordering
from ...core.errors import ArgumentError
from ...core.graph import PoseGraph
from ...core.status import OK
from ...linalg.accuracy import LogdetAccuracy, logdet_accuracy
from ...linalg.ordering import anchored_logdet_accuracy, resolve_ordering
from ...solver.estimate import Estimate
from ..inputs import input_files
from ..results import CrlbResult, FimResult, accuracy_keys, graph_keys
from .fim import sed_fim
from .frames import convert_information, coordinate_names, sed_crlb_in_frame


@dataclass(frozen=True, kw_only=True)
class SedSettings:
    """The sed model's settings: the coordinates of every per-pose number (the thesis's ``world``
    frame or GTSAM's and g2o's ``body`` frame), the quotient bound (5.5) instead of the anchored
    one (5.1), and the factorizations' fill-reducing ordering (cost only)."""

    frame: Frame = "world"
    quotient: bool = False
    ordering: Ordering = "auto"


@dataclass(frozen=True)
class SedModel:
    """Bertini's model on SE(d)^n with its settings (``posecrb.models.Model``)."""

    settings: SedSettings = field(default_factory=SedSettings)
    name: ClassVar[str] = "sed"

    def fim(self, graph: PoseGraph, estimate: Estimate, *, anchor: int | None = None) -> FimResult:
        """The whole FIM (4.6) in ``settings.frame``, its rank and nullity (Th. 4.8.1) and the
        log-det with one anchor per component (or ``anchor``, a pose id, on a connected graph)."""
        opts = self.settings
        sfim = sed_fim(graph, estimate.rot, estimate.trans, ordering=opts.ordering)
        times = dict(sfim.times)
        # log-det, rank and nullity are the same in both frames (det B_i = +-1, posecrb.models.sed.frames)
        matrix = sfim.matrix if opts.frame == "world" else \
            convert_information(sfim.matrix, estimate.rot, estimate.trans, "body")
        acc: LogdetAccuracy | None = None
        if anchor is not None:
            if graph.n_components > 1:
                raise ArgumentError("anchor", anchor, f"is one anchor for a graph of {graph.n_components} "
                                    "components; the sed model's log-det takes the default anchors (the smallest "
                                    "id of each component)")
            anchors = [graph.anchor_index(anchor)]
            t0 = time.perf_counter()
            logdet, acc = anchored_logdet_accuracy(sfim.matrix, sfim.q, anchors, "SE(d) FIM on the free poses",
                                                   ordering=opts.ordering, dim=graph.dim)
            times["fim_logdet"] = time.perf_counter() - t0
            ld: float | None = logdet
            status = acc.status if acc is not None else OK
        else:
            anchors, ld, status = list(sfim.anchors), sfim.logdet_anchored, sfim.logdet_status
            if ld is not None and sfim.factor is not None:
                t0 = time.perf_counter()
                acc = logdet_accuracy(sfim.factor, ld, "SE(d) FIM on the free poses", matrix=sfim.free_matrix,
                                      overwrite_factor=True)
                times["logdet_accuracy"] = time.perf_counter() - t0
                status = acc.status
        names = coordinate_names(graph.dim, opts.frame)
        layout = "poses (rotation first)" if opts.frame == "world" else \
            f"poses (GTSAM order: {', '.join(names)})"
        used = resolve_ordering(opts.ordering, dim=graph.dim, poses=graph.n, matrix="fim")
        return FimResult(**graph_keys(graph, self.name), anchors=[int(graph.ids[a]) for a in anchors], layout=layout,
                         size=int(matrix.shape[0]), nnz=int(matrix.nnz), logdet=ld, logdet_status=status,
                         logdet_accuracy=accuracy_keys(acc), trace=float(matrix.diagonal().sum()), rank=sfim.rank,
                         nullity=sfim.nullity, expected_nullity=sfim.q * sfim.components,
                         ordering={"requested": opts.ordering, "fim": str(used)}, frame=opts.frame,
                         estimate=estimate, times=times, matrix=matrix, row_ids=np.repeat(graph.ids, sfim.q),
                         row_coord=np.tile(np.arange(sfim.q), graph.n), coordinate_names=names,
                         inputs=input_files(graph, estimate))

    def crlb(self, graph: PoseGraph, estimate: Estimate, *, anchors: Sequence[int] = (),
             poses: bool | Sequence[int] = False) -> CrlbResult:
        """The anchored (5.1, at the pose ids ``anchors``: one or more per component) or quotient
        (5.5, ``opts.quotient``) bound in ``settings.frame`` coordinates; per-pose blocks for
        every pose (``poses=True``) or the listed pose ids."""
        opts = self.settings
        index = [graph.anchor_index(a) for a in anchors] or None
        want: bool | list[int] = True if poses is True else \
            [graph.index_of(p, "poses") for p in poses] if poses else False
        res = sed_crlb_in_frame(graph, estimate.rot, estimate.trans, opts.frame, anchors=index,
                                quotient=opts.quotient, per_pose=want, ordering=opts.ordering)
        usable = res.accuracy is None or res.accuracy.status.available
        blocks = None if res.per_pose is None or not usable else \
            {int(graph.ids[k]): v for k, v in res.per_pose.items()}
        ordering = {"requested": opts.ordering,
                    "crlb": str(resolve_ordering(opts.ordering, dim=graph.dim, poses=graph.n, matrix="crlb"))}
        return CrlbResult(**graph_keys(graph, self.name), kind=res.kind,
                          anchors=[int(graph.ids[a]) for a in res.anchors], nullity=res.nullity,
                          accuracy=res.accuracy, trace_crlb=res.trace_crlb, mse_bound=res.mse_bound,
                          coordinates=coordinate_names(graph.dim, opts.frame), frame=opts.frame,
                          ordering=ordering, per_pose=blocks, estimate=estimate, times=dict(res.times),
                          inputs=input_files(graph, estimate))
