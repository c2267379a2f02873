"""The two models behind one call each: ``model_fim`` and ``model_crlb`` at an estimate.

``"paper"``: Chen et al.'s anchored FIM on (R^d x SO(d))^n (docs/design.md#paper-fim) and its CRLB
(docs/design.md#crlb); ``"sed"``: the thesis's FIM on SE(d)^n (docs/design.md#thesis-fim) and its
anchored or quotient CRLB (docs/design.md#anchored-crb), in world or body coordinates
(docs/design.md#frames). Both return the public results of ``posecrb.models.results``; anchors and
per-pose requests are pose ids here, internal indices below.
"""
from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from ..core.choices import MODELS
from ..core.errors import ArgumentError
from ..core.graph import PoseGraph
from ..core.status import OK, Status
from ..linalg.accuracy import LogdetAccuracy, logdet_accuracy
from ..linalg.ordering import anchored_logdet_accuracy, resolve_ordering
from ..solver.estimate import Estimate
from .paper.bounds import t_optimality
from .paper.crlb import InverseAccuracy, PaperCrlb, paper_crlb
from .paper.fim import fim_symbolic_choice, paper_fim, trace_fim
from .results import CrlbResult, FimResult
from .sed.crlb import SedCrlb
from .sed.fim import sed_fim
from .sed.frames import convert_information, coordinate_names, coordinates_description, sed_crlb_in_frame


def _graph_keys(graph: PoseGraph, model: str) -> dict[str, object]:
    return {"dataset": graph.name, "model": model, "dim": graph.dim, "poses": graph.n, "edges": graph.m,
            "components": graph.n_components}


def _accuracy_keys(acc: LogdetAccuracy | None) -> dict[str, float] | None:
    """The JSON's ``logdet_accuracy``: the log-det's condition number and its rounding-error bound."""
    return None if acc is None else {"condition": acc.condition, "error_bound": acc.error_bound}


def model_fim(graph: PoseGraph, estimate: Estimate, *, model: str = "paper", anchor: int | None = None,
              rotation_weight: str = "eq59", fim_variant: str = "consistent", frame: str = "world",
              ordering: str = "auto") -> FimResult:
    """The Fisher information of ``model`` at ``estimate`` (its ``rot`` and ``trans``).

    paper: anchored at the pose id ``anchor`` (default the smallest id), eq. (42)/(64), log-det and
    trace (eq. 69/70) and eq. (72)'s approximation. sed: the whole FIM (4.6) in ``frame``, its rank
    and nullity (Th. 4.8.1) and the log-det with one anchor per component (or ``anchor`` on a
    connected graph; several components with an anchor is an ArgumentError)."""
    if not estimate.has_poses:
        raise ArgumentError("estimate", f"Estimate from {estimate.source}", "carries no poses", sep=": ")
    rot, trans = estimate.rot, estimate.trans
    if model == "paper":
        idx = graph.anchor_index(anchor)
        fim = paper_fim(graph, rot, trans, anchor=idx, rotation_weight=rotation_weight, variant=fim_variant)
        times = {"fim_build": fim.build_time}
        t0 = time.perf_counter()
        sym, choice = fim_symbolic_choice(fim, ordering)
        factor, ld_paper = sym.factor_logdet(fim.matrix, name="paper FIM")
        times["fim_logdet"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        acc_paper = logdet_accuracy(factor, ld_paper, "paper FIM")
        times["logdet_accuracy"] = time.perf_counter() - t0
        ids, coord = fim.index_map()
        return FimResult(**_graph_keys(graph, model), anchors=[fim.anchor_id], layout=fim.layout,  # type: ignore[arg-type]
                         size=fim.size, nnz=fim.nnz, logdet=ld_paper, logdet_status=acc_paper.status,
                         logdet_accuracy=_accuracy_keys(acc_paper), trace=trace_fim(fim),
                         t_opt_approx=t_optimality(graph, idx, rotation_weight)[1], rank=fim.size, nullity=0,
                         rotation_weight=rotation_weight, fim_variant=fim.variant,
                         ordering={"requested": ordering, "fim": str(choice)}, frame="mixed",
                         coordinates_description=coordinates_description(graph.dim, "mixed"), estimate=estimate,
                         times=times, matrix=fim.matrix, row_ids=ids, row_coord=coord,
                         coordinate_names=fim.coordinate_names())
    if model != "sed":
        raise ArgumentError("model", model, f"is not one of {', '.join(MODELS)}")
    sfim = sed_fim(graph, rot, trans, ordering=ordering)
    acc: LogdetAccuracy | None
    times = dict(sfim.times)
    # log-det, rank and nullity are the same in both frames (det B_i = +-1, posecrb.models.sed.frames)
    matrix = sfim.matrix if frame == "world" else convert_information(sfim.matrix, rot, trans, "body")
    status = OK
    if anchor is not None:
        if graph.n_components > 1:
            raise ArgumentError("anchor", anchor, f"is one anchor for a graph of {graph.n_components} components; "
                                "the sed model's log-det takes the default anchors (the smallest id of each "
                                "component)")
        anchors = [graph.anchor_index(anchor)]
        t0 = time.perf_counter()
        ld_anchor, acc = anchored_logdet_accuracy(sfim.matrix, sfim.q, anchors, "SE(d) FIM on the free poses",
                                                  ordering=ordering, dim=graph.dim)
        times["fim_logdet"] = time.perf_counter() - t0
        ld: float | None = ld_anchor
        status = acc.status if acc is not None else OK
    else:
        anchors, ld, status = list(sfim.anchors), sfim.logdet_anchored, sfim.logdet_status
        acc = None
        if ld is not None and sfim.factor is not None:
            t0 = time.perf_counter()
            acc = logdet_accuracy(sfim.factor, ld, "SE(d) FIM on the free poses")
            times["logdet_accuracy"] = time.perf_counter() - t0
            status = acc.status
    names = coordinate_names(graph.dim, frame)
    layout = "poses (rotation first)" if frame == "world" else f"poses (GTSAM order: {', '.join(names)})"
    used = resolve_ordering(ordering, dim=graph.dim, poses=graph.n, matrix="fim")
    return FimResult(**_graph_keys(graph, model), anchors=[int(graph.ids[a]) for a in anchors],  # type: ignore[arg-type]
                     layout=layout, size=int(matrix.shape[0]), nnz=int(matrix.nnz), logdet=ld, logdet_status=status,
                     logdet_accuracy=_accuracy_keys(acc),
                     trace=float(matrix.diagonal().sum()), rank=sfim.rank, nullity=sfim.nullity,
                     expected_nullity=sfim.q * sfim.components, ordering={"requested": ordering, "fim": str(used)},
                     frame=frame, coordinates_description=coordinates_description(graph.dim, frame),
                     estimate=estimate, times=times, matrix=matrix, row_ids=np.repeat(graph.ids, sfim.q),
                     row_coord=np.tile(np.arange(sfim.q), graph.n), coordinate_names=names)


def model_crlb(graph: PoseGraph, estimate: Estimate, *, model: str = "paper", anchor: Sequence[int] = (),
               quotient: bool = False, poses: bool | Sequence[int] = False, rotation_weight: str = "eq59",
               fim_variant: str = "consistent", frame: str = "mixed", ordering: str = "auto") -> CrlbResult:
    """The Cramér-Rao bound of ``model`` at ``estimate``.

    paper: anchored at one pose id (docs/design.md#crlb), with eq. (68)'s curvature correction in
    3D; sed: anchored (5.1) at ``anchor`` (pose ids, one or more per component) or ``quotient``
    (5.5) in ``frame`` coordinates (docs/design.md#anchored-crb). ``poses``: per-pose covariance
    blocks for every pose (True) or the listed pose ids. ``ordering``: the factorizations'
    fill-reducing ordering (posecrb.linalg.ordering; cost only)."""
    if not estimate.has_poses:
        raise ArgumentError("estimate", f"Estimate from {estimate.source}", "carries no poses", sep=": ")
    rot, trans = estimate.rot, estimate.trans
    keys = _graph_keys(graph, model)
    used = {"requested": ordering, "crlb": str(resolve_ordering(ordering, dim=graph.dim, poses=graph.n,
                                                                matrix="crlb"))}
    res: PaperCrlb | SedCrlb
    if model == "paper":
        if quotient:
            raise ArgumentError("quotient", quotient, "applies to the sed model (the paper model is anchored)")
        if len(anchor) > 1:
            raise ArgumentError("anchor", list(anchor), "is several anchors; the paper model takes one (its graph "
                                "must be connected)")
        idx = graph.anchor_index(anchor[0] if anchor else None)
        if poses is not True and poses:
            for p in poses:
                graph.index_of(p, "poses")
        res = paper_crlb(graph, rot, trans, anchor=idx, per_pose=poses, rotation_weight=rotation_weight,
                         variant=fim_variant, ordering=ordering)
        acc = _unavailable(res.accuracy)
        curv = res.curvature_status if acc.available else acc
        three = graph.dim == 3
        blocks, curv_blocks = (res.per_pose, res.per_pose_curvature) if acc.available else (None, None)
        return CrlbResult(**keys, kind="anchored", fim_variant=res.fim_variant,  # type: ignore[arg-type]
                          rotation_weight=rotation_weight, anchors=[res.anchor_id], nullity=0,
                          accuracy=res.accuracy, trace_crlb=res.trace_crlb, trace_crlb_status=acc,
                          mse_bound=res.mse_bound, mse_bound_status=acc, trace_translation=res.trace_translation,
                          trace_translation_status=acc, trace_rotation=res.trace_rotation,
                          trace_rotation_status=acc,
                          trace_crlb_curvature=res.trace_crlb_curvature if three else None,
                          trace_crlb_curvature_status=curv if three else OK,
                          mse_bound_curvature=res.mse_bound_curvature if three else None,
                          mse_bound_curvature_status=curv if three else OK,
                          curvature_correction_max=res.curvature_correction_max if three else None,
                          curvature_status=res.curvature_status, coordinates=res.coordinates, frame=frame,
                          ordering=used, coordinates_description=coordinates_description(graph.dim, frame),
                          per_pose=blocks, per_pose_curvature=curv_blocks, estimate=estimate, times=dict(res.times))
    if model != "sed":
        raise ArgumentError("model", model, f"is not one of {', '.join(MODELS)}")
    anchors = [graph.anchor_index(a) for a in anchor] or None
    want: bool | list[int] = True if poses is True else [graph.index_of(p, "poses") for p in poses] if poses else False
    res = sed_crlb_in_frame(graph, rot, trans, frame, anchors=anchors, quotient=quotient, per_pose=want,
                            ordering=ordering)
    acc = _unavailable(res.accuracy)
    blocks = None if res.per_pose is None or not acc.available else \
        {int(graph.ids[k]): v for k, v in res.per_pose.items()}
    return CrlbResult(**keys, kind=res.kind, anchors=[int(graph.ids[a]) for a in res.anchors],  # type: ignore[arg-type]
                      nullity=res.nullity, accuracy=res.accuracy, trace_crlb=res.trace_crlb, trace_crlb_status=acc,
                      mse_bound=res.mse_bound, mse_bound_status=acc, coordinates=coordinate_names(graph.dim, frame),
                      frame=frame, ordering=used, coordinates_description=coordinates_description(graph.dim, frame),
                      per_pose=blocks, estimate=estimate, times=dict(res.times))


def _unavailable(accuracy: InverseAccuracy | None) -> Status:
    """The status the bound's numbers inherit from the inverse's accuracy: its own when the
    inverse is unusable, ok otherwise (a warning stays on ``accuracy``)."""
    if accuracy is None or accuracy.status.available:
        return OK
    return accuracy.status
