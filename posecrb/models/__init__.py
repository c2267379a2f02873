"""The two models behind one call: ``fisher_information(graph, rot, trans, model=...)``.

``"paper"``: Chen et al.'s anchored FIM on (R^d x SO(d))^n (docs/design.md#paper-fim); ``"sed"``:
the thesis's FIM on SE(d)^n (docs/design.md#thesis-fim), in world or body coordinates
(docs/design.md#frames). The result holds what ``posecrb fim`` prints (``to_row``) and the matrix
with its index map (``save``).
"""
from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.errors import UsageError
from ..core.graph import PoseGraph
from ..core.status import OK, Status, log_status, put
from ..io.npz import save_npz
from ..linalg.accuracy import LogdetAccuracy, logdet_accuracy
from ..linalg.cholesky import anchored_logdet_accuracy
from ..linalg.ordering import resolve_ordering
from .paper.bounds import t_optimality
from .paper.crlb import CrlbResult, InverseAccuracy, paper_crlb
from .paper.fim import fim_symbolic_choice, paper_fim, trace_fim
from .thesis.crb import SedCrbResult
from .thesis.fim import _free_matrix, sed_fim
from .thesis.frames import convert_information, coordinate_names, coordinates_description, sed_crb_in_frame

log = logging.getLogger("posecrb")

MODELS = ("paper", "sed")


@dataclass(frozen=True, kw_only=True)
class FisherInformation:
    """The FIM of one model at an estimate, with the numbers ``posecrb fim`` reports."""

    model: str
    matrix: Any                      # scipy sparse, the saved matrix (sed: in ``frame`` coordinates)
    row_ids: np.ndarray              # pose id of every row
    row_coord: np.ndarray            # index into ``coordinate_names`` of every row
    coordinate_names: list[str]
    frame: str                       # "mixed" (paper), "world" or "body" (sed)
    anchors: list[int]               # anchored pose ids (the log-det's)
    layout: str
    logdet: float | None
    logdet_status: Status = OK
    logdet_accuracy: LogdetAccuracy | None = None   # conditioning of the factored matrix (its digits)
    trace: float
    rank: int
    nullity: int
    expected_nullity: int | None = None      # sed only
    t_opt_approx: float | None = None        # paper only (eq. 72)
    rotation_weight: str | None = None       # paper only
    fim_variant: str | None = None           # paper only
    times: dict[str, float] = field(default_factory=dict)
    ordering: str = ""                       # the log-det factorization's ordering (posecrb.linalg.ordering)

    def to_row(self) -> dict:
        """The model's part of the ``fim`` row (keys and order of the command's JSON)."""
        row: dict = {"anchors": self.anchors, "layout": self.layout, "size": int(self.matrix.shape[0]),
                     "nnz": int(self.matrix.nnz)}
        put(row, "logdet", self.logdet, self.logdet_status)
        if self.logdet_accuracy is not None:
            row["logdet_accuracy"] = {"condition": self.logdet_accuracy.condition,
                                      "error_bound": self.logdet_accuracy.error_bound}
        if self.model == "paper":
            row.update({"trace": self.trace, "t_opt_approx": self.t_opt_approx,
                        "rank": self.rank, "nullity": self.nullity, "rotation_weight": self.rotation_weight,
                        "fim_variant": self.fim_variant})
        else:
            row.update({"trace": self.trace, "rank": self.rank, "nullity": self.nullity,
                        "expected_nullity": self.expected_nullity})
        return row

    def save(self, path: str) -> str:
        """The matrix and its index map as a scipy sparse .npz (``posecrb.io.npz``); the path written."""
        return save_npz(path, self.matrix, self.row_ids, self.row_coord, self.coordinate_names, self.model,
                        self.anchors, **({} if self.model == "paper" else {"frame": self.frame}))


def fisher_information(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, *, model: str = "paper",
                       anchor_id: int | None = None, rotation_model: str = "eq59", variant: str = "consistent",
                       frame: str = "world", ordering: str = "auto") -> FisherInformation:
    """The Fisher information of ``model`` at the estimate (rot, trans).

    paper: anchored at ``anchor_id`` (default the smallest id), eq. (42)/(64), log-det and trace
    (eq. 69/70) and eq. (72)'s approximation. sed: the whole FIM (4.6) in ``frame``, its rank and
    nullity (Th. 4.8.1) and the log-det with one anchor per component (or ``anchor_id`` on a
    connected graph; several components with an anchor is a UsageError)."""
    if model not in MODELS:
        raise UsageError(f"model must be one of {MODELS}, got {model!r}")
    if model == "paper":
        anchor = graph.anchor_index(anchor_id)
        fim = paper_fim(graph, rot, trans, anchor=anchor, rotation_model=rotation_model, variant=variant)
        times = {"fim_build": fim.build_time}
        t0 = time.perf_counter()
        sym, choice = fim_symbolic_choice(fim, ordering)
        factor, ld_paper = sym.factor_logdet(fim.matrix, name="paper FIM")
        times["fim_logdet"] = time.perf_counter() - t0
        acc_paper = logdet_accuracy(fim.matrix, factor, ld_paper, "paper FIM")
        log_status(log, f"{graph.name}: log det of the FIM", acc_paper.status)
        ids, coord = fim.index_map()
        return FisherInformation(model="paper", matrix=fim.matrix, row_ids=ids, row_coord=coord,
                                 coordinate_names=fim.coordinate_names(), frame="mixed", anchors=[fim.anchor_id],
                                 layout=fim.layout, logdet=ld_paper, logdet_status=acc_paper.status,
                                 logdet_accuracy=acc_paper,
                                 trace=trace_fim(fim), rank=fim.size, nullity=0,
                                 t_opt_approx=t_optimality(graph, anchor, rotation_model)[1],
                                 rotation_weight=rotation_model, fim_variant=fim.variant, times=times,
                                 ordering=str(choice))
    sfim = sed_fim(graph, rot, trans, ordering=ordering)
    acc: LogdetAccuracy | None
    times = dict(sfim.times)
    # log-det, rank and nullity are the same in both frames (det B_i = +-1, posecrb.models.thesis.frames)
    matrix = sfim.matrix if frame == "world" else convert_information(sfim.matrix, rot, trans, "body")
    if anchor_id is not None:
        if graph.n_components > 1:
            raise UsageError("--anchor with --model sed needs a connected graph "
                             "(`posecrb crlb --anchor` takes one anchor per component)")
        anchors = [graph.anchor_index(anchor_id)]
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
            free, _ = _free_matrix(sfim.matrix, graph.n, sfim.q, anchors)
            acc = logdet_accuracy(free, sfim.factor, ld, "SE(d) FIM on the free poses")
            status = acc.status
    log_status(log, f"{graph.name}: log det of the SE(d) FIM", status)
    names = coordinate_names(graph.dim, frame)
    layout = "poses (rotation first)" if frame == "world" else f"poses (GTSAM order: {', '.join(names)})"
    return FisherInformation(model="sed", matrix=matrix, row_ids=np.repeat(graph.ids, sfim.q),
                             row_coord=np.tile(np.arange(sfim.q), graph.n), coordinate_names=names, frame=frame,
                             anchors=[int(graph.ids[a]) for a in anchors], layout=layout, logdet=ld,
                             logdet_status=status, logdet_accuracy=acc, trace=float(matrix.diagonal().sum()),
                             rank=sfim.rank,
                             nullity=sfim.nullity, expected_nullity=sfim.q * sfim.components, times=times,
                             ordering=str(resolve_ordering(ordering, dim=graph.dim, poses=graph.n, matrix="fim")))


@dataclass(frozen=True, kw_only=True)
class CramerRaoBound:
    """What ``posecrb crlb`` reports for one model: the model's part of the row (keys and order of
    the command's JSON), one row per pose when per-pose blocks were asked, and the timings."""

    row: dict
    pose_rows: list[dict]
    times: dict[str, float]

    def to_row(self) -> dict:
        return dict(self.row)


def cramer_rao_bound(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, *, model: str = "paper",
                     anchor_ids: Sequence[int] = (), quotient: bool = False, poses: bool | list[int] = False,
                     rotation_model: str = "eq59", variant: str = "consistent",
                     frame: str = "mixed", ordering: str = "auto") -> CramerRaoBound:
    """The Cramér-Rao bound of ``model`` at the estimate (rot, trans).

    paper: anchored at one pose (docs/design.md#crlb), with eq. (68)'s curvature correction in 3D;
    sed: anchored (5.1) or ``quotient`` (5.5) in ``frame`` coordinates (docs/design.md#anchored-crb).
    ``poses``: per-pose covariance blocks for every pose (True) or the listed ids. Doubtful numbers
    carry a ``<key>_status`` and a warning on stderr. ``ordering``: the factorizations' fill-reducing
    ordering (posecrb.linalg.ordering; cost only), reported in the row's ``ordering``."""
    if model not in MODELS:
        raise UsageError(f"model must be one of {MODELS}, got {model!r}")
    row: dict = {}
    res: CrlbResult | SedCrbResult
    if model == "paper":

        if quotient:
            raise UsageError("--quotient applies to --model sed (the paper model is anchored)")
        if len(anchor_ids) > 1:
            raise UsageError("--model paper takes a single --anchor (its graph must be connected)")
        anchor = graph.anchor_index(anchor_ids[0] if anchor_ids else None)
        res = paper_crlb(graph, rot, trans, anchor=anchor, per_pose=poses, rotation_model=rotation_model,
                         variant=variant, ordering=ordering)
        row.update({"kind": "anchored", "fim_variant": res.fim_variant, "rotation_weight": rotation_model,
                    "anchors": [res.anchor_id], "nullity": 0})
        acc = _accuracy(row, res.accuracy, graph.name)
        for key in ("trace_crlb", "mse_bound", "trace_translation", "trace_rotation"):
            put(row, key, getattr(res, key), acc)
        if graph.dim == 3:
            st = res.curvature_status if acc.available else acc
            log_status(log, f"{graph.name}: curvature-corrected CRLB (eq. 68)", res.curvature_status)
            put(row, "trace_crlb_curvature", res.trace_crlb_curvature, st)
            put(row, "mse_bound_curvature", res.mse_bound_curvature, st)
            row["curvature_correction_max"] = res.curvature_correction_max
        row["coordinates"] = res.coordinates
        blocks, curv = res.per_pose, res.per_pose_curvature
        if not acc.available:
            blocks = curv = None
    else:

        anchors = None if not anchor_ids else [graph.index_of(a) for a in anchor_ids]
        if poses is True:
            want: bool | list[int] = True
        elif poses:
            want = [graph.index_of(p) for p in poses]
        else:
            want = False
        res = sed_crb_in_frame(graph, rot, trans, frame, anchors=anchors, quotient=quotient, per_pose=want,
                               ordering=ordering)
        row.update({"kind": res.kind, "anchors": [int(graph.ids[a]) for a in res.anchors],
                    "nullity": res.nullity})
        acc = _accuracy(row, res.accuracy, graph.name)
        put(row, "trace_crlb", res.trace_crlb, acc)
        put(row, "mse_bound", res.mse_bound, acc)
        row["coordinates"] = coordinate_names(graph.dim, frame)
        blocks = None if res.per_pose is None else {int(graph.ids[k]): v for k, v in res.per_pose.items()}
        curv = None
        if not acc.available:
            blocks = None

    row["frame"] = frame
    row["ordering"] = str(resolve_ordering(ordering, dim=graph.dim, poses=graph.n, matrix="crlb"))
    row["coordinates_description"] = coordinates_description(graph.dim, frame)
    per_rows: list[dict] = []
    if blocks is not None:
        row["per_pose"] = {str(k): v for k, v in blocks.items()}
        if curv is not None:
            row["per_pose_curvature"] = {str(k): v for k, v in curv.items()}
        names = row["coordinates"]
        for k, v in blocks.items():
            r = {"id": k, **{f"var_{c}": float(x) for c, x in zip(names, np.diag(v))}, "trace": float(np.trace(v))}
            if curv is not None:
                r["trace_curvature"] = float(np.trace(curv[k]))
            per_rows.append(r)
    return CramerRaoBound(row=row, pose_rows=per_rows, times=dict(res.times))


def _accuracy(row: dict, accuracy: InverseAccuracy | None, name: str) -> Status:
    """Record the inverse's accuracy estimate in ``row`` (key ``accuracy``), warn on stderr when it
    is not ok, and return the status that the bound's numbers inherit when it is unavailable."""
    if accuracy is None:
        return Status()
    row["accuracy"] = accuracy.as_json()
    log_status(log, f"{name}: CRLB", accuracy.status)
    return accuracy.status if not accuracy.status.available else Status()
