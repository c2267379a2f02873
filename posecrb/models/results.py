"""The results of ``posecrb.fim`` and ``posecrb.crlb``: ``FimResult`` and ``CrlbResult``.

Both follow the result protocol (``posecrb.core.result``): ``to_dict()`` is the ``fim`` /
``crlb`` command's ``--format json`` object, field by field in the same order.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.errors import UsageError
from ..core.graph import PoseGraph
from ..core.result import (
    ARRAY,
    NESTED,
    Result,
    array_field,
    derived_field,
    inputs_field,
    internal_field,
    optional_field,
    plain,
    shared_status_field,
    status_field,
)
from ..core.status import OK, Status
from ..linalg.accuracy import LogdetAccuracy
from ..solver.estimate import Estimate
from .paper.crlb import InverseAccuracy
from .sed.frames import coordinates_description


def pose_blocks_codec() -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
    """Per-pose matrices: ``{pose id: array}`` in Python, ``{"id": [[...]]}`` in JSON."""

    def encode(blocks: Mapping[int, np.ndarray] | None) -> Any:
        return None if blocks is None else {str(k): plain(np.asarray(v)) for k, v in blocks.items()}

    def decode(blocks: Mapping[str, Any] | None) -> Any:
        return None if blocks is None else {int(k): np.asarray(v, dtype=float) for k, v in blocks.items()}

    return encode, decode


def graph_keys(graph: PoseGraph, model: str) -> dict[str, Any]:
    """The first keys of the ``fim`` and ``crlb`` JSON: the graph and the model."""
    return {"dataset": graph.name, "model": model, "dim": graph.dim, "poses": graph.n, "edges": graph.m,
            "components": graph.n_components}


def accuracy_keys(acc: LogdetAccuracy | None) -> dict[str, float | str] | None:
    """The JSON's ``logdet_accuracy``: the log-det's condition number, its rounding-error bound, the
    tier that bounded them and whether ``condition`` is exact or an upper bound."""
    return None if acc is None else {"condition": acc.condition, "error_bound": acc.error_bound, "tier": acc.tier,
                                     "condition_kind": acc.condition_kind}


def _description(res: FimResult | CrlbResult) -> str:
    """The JSON's ``coordinates_description``: what the coordinates of a pose are, from the frame."""
    return coordinates_description(res.dim, res.frame)


@dataclass(frozen=True, kw_only=True)
class _ModelKeys(Result):
    """The first keys of the ``fim`` and ``crlb`` JSON: the graph and the model."""

    dataset: str
    model: str
    dim: int
    poses: int
    edges: int
    components: int


@dataclass(frozen=True, kw_only=True)
class FimResult(_ModelKeys):
    """The Fisher information matrix of one model at an estimate: what ``posecrb fim`` prints.

    Two models (docs/design.md#models): ``"paper"``, Chen et al.'s anchored FIM on
    (R^d x SO(d))^n with isotropic noise (eq. 42 in 2D, eq. 64 in 3D; rows: the translations of
    the free poses, then their rotations; rotation coordinates: the angle in 2D, along
    ``G_k / sqrt(2)`` in 3D); ``"sed"``, the thesis's FIM on SE(d)^n (4.6) with the full
    information matrices, of size n q, pose-major, in ``frame`` coordinates. Log-determinants
    are natural logarithms; translations are in the file's length units, so the log-det
    changes by ``2 d n_p log s`` when the lengths are scaled by s.

    ``to_dict()`` is the command's JSON object; the matrix itself (scipy sparse CSC) and its
    index map are left out of it and kept by ``save``, in a file that
    ``scipy.sparse.load_npz`` also reads. ``to_frame()`` has one row of the scalar values.

    Attributes
    ----------
    dataset : str
        The graph's name.
    model : str
        ``"paper"`` or ``"sed"``.
    dim, poses, edges, components : int
        d, n, m and the number of connected components.
    anchors : list of int
        Anchored pose ids of the log-det (one per component for ``sed``).
    layout : str
        Row order of the matrix.
    size, nnz : int
        Rows and stored entries of the matrix.
    logdet : float or None
        log det of the anchored FIM (D-optimality); None when unavailable (``logdet_status``).
    logdet_accuracy : dict or None
        ``condition`` (the log-det's componentwise condition number), ``error_bound`` (a
        first-order bound on its rounding error; ``posecrb.linalg.accuracy``), ``tier`` (what
        bounded them: ``"spanning_tree"``, the inverse's diagonal bounded by a spanning tree's
        covariance, ``"lambda_min"``, a certified smallest eigenvalue of the scaled FIM, or
        ``"selected_inversion"``, the exact sum) and ``condition_kind`` (``"exact"`` or ``"upper
        bound"``: the first two tiers' ``condition`` is an upper bound of the exact one).
        ``logdet_status`` is a warning when the bound exceeds 1e-6 relative and unavailable when
        no digit is correct.
    trace : float
        Its trace (T-optimality, eq. 69/70 for the paper model).
    t_opt_approx : float or None
        The paper model's eq. (72) approximation of the trace (paper only).
    rank, nullity : int
        Rank and nullity of the matrix (sed: nullity = q x components, Th. 4.8.1).
    expected_nullity : int or None
        q x components (sed only).
    rotation_weight, fim_variant : str or None
        The paper model's 3D rotation weight (``"eq59"`` or ``"table2"``) and FIM variant
        (``"consistent"``: the model's Fisher information; ``"eq64"``: eq. (64) as printed).
    ordering : dict of str to str
        ``requested`` and the ordering of the log-det factorization (``fim``).
    frame : str
        ``"mixed"`` (paper), ``"world"`` or ``"body"`` (sed).
    coordinates_description : str
        What the coordinates of a pose are (from ``frame``).
    saved : str or None
        The file the command line's ``--save`` wrote.
    estimate : Estimate
        Where the poses come from.
    times : dict of str to float
        Seconds per step.
    matrix, row_ids, row_coord : scipy.sparse matrix and numpy.ndarray
        The matrix, the pose id of each row and its coordinate number within the pose (None and
        empty after ``from_dict``; ``load`` keeps them).
    coordinate_names : list of str
        Names of a pose's coordinates (``row_coord`` indexes them).

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.fim("intel")
    >>> res.model, res.size, res.anchors
    ('paper', 5181, [0])
    >>> round(res.logdet, 3)
    30194.332
    """

    anchors: list[int]
    layout: str
    size: int
    nnz: int
    logdet: float | None
    logdet_status: Status = status_field("log det of the FIM")
    logdet_accuracy: dict[str, float | str] | None = optional_field()
    trace: float
    t_opt_approx: float | None = optional_field()
    rank: int
    nullity: int
    expected_nullity: int | None = optional_field()
    rotation_weight: str | None = optional_field()
    fim_variant: str | None = optional_field()
    ordering: dict[str, str] = field(default_factory=dict)
    frame: str
    coordinates_description: str = derived_field(_description)
    saved: str | None = optional_field()
    estimate: Estimate | None = field(default=None, metadata={NESTED: Estimate})
    times: dict[str, float] = field(default_factory=dict)
    inputs: tuple[str, ...] = inputs_field()
    matrix: Any = array_field(None)
    row_ids: np.ndarray = array_field()
    row_coord: np.ndarray = array_field()
    coordinate_names: list[str] = field(default_factory=list, repr=False, metadata={ARRAY: True})

    def arrays(self) -> dict[str, np.ndarray]:
        """The scipy sparse layout (``data``, ``indices``, ``indptr``, ``format``, ``shape``)
        plus the index map: ``row_pose_id``, ``row_coordinate`` (into ``coordinate_names``),
        ``model``, ``anchor_ids`` and ``frame``."""
        if self.matrix is None:
            return {}
        m = self.matrix.tocsc()
        return {"data": m.data, "indices": m.indices, "indptr": m.indptr, "format": np.array("csc"),
                "shape": np.array(m.shape), "row_pose_id": np.asarray(self.row_ids, np.int64),
                "row_coordinate": np.asarray(self.row_coord, np.int64),
                "coordinate_names": np.array(self.coordinate_names or []), "model": np.array(self.model),
                "anchor_ids": np.asarray(self.anchors, np.int64), "frame": np.array(self.frame)}

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> dict[str, Any]:
        if "data" not in arrays:
            return {}
        import scipy.sparse as sp  # noqa: PLC0415 -- lazy: start-up time (scipy only when a FIM is read)

        matrix = sp.csc_matrix((arrays["data"], arrays["indices"], arrays["indptr"]),
                               shape=tuple(int(x) for x in arrays["shape"]))
        return {"matrix": matrix, "row_ids": arrays["row_pose_id"], "row_coord": arrays["row_coordinate"],
                "coordinate_names": [str(x) for x in arrays["coordinate_names"]]}


@dataclass(frozen=True, kw_only=True)
class CrlbResult(_ModelKeys):
    """The Cramér-Rao lower bound of one model at an estimate: what ``posecrb crlb`` prints.

    ``"paper"``: ``C >= F^{-1}`` of the anchored paper FIM (2D, eq. 67), with eq. (68)'s
    curvature term in 3D (``trace_crlb_curvature``); coordinates: translation in the world frame
    (the file's length units), rotation in the body frame (radians; 3D along ``G_k/sqrt(2)``).
    ``"sed"``: the thesis's intrinsic bound on SE(d)^n, anchored (5.1) or quotient (5.5), in
    ``frame`` coordinates. ``trace_crlb`` is the trace of the bound and ``mse_bound`` the trace
    per pose that carries error (anchored: n - #anchors).

    ``to_dict()`` is the command's JSON object. ``to_frame()`` has one row per pose for which
    blocks were asked (``poses=``): its id, the variance of each coordinate (the diagonal of its
    block) and the block's trace (3D paper: also ``trace_curvature``).

    Attributes
    ----------
    dataset, model : str
        The graph's name and ``"paper"`` or ``"sed"``.
    dim, poses, edges, components : int
        d, n, m and the number of connected components.
    kind : str
        ``"anchored"`` or ``"quotient"``.
    fim_variant, rotation_weight : str or None
        The paper model's FIM variant and 3D rotation weight (paper only).
    anchors : list of int
        Anchored pose ids (quotient: the one per component used for the computation).
    nullity : int
        The FIM's nullity (0 for the anchored paper FIM).
    accuracy : InverseAccuracy or None
        How far the computed inverse can be trusted.
    trace_crlb, mse_bound : float or None
        Trace of the bound and trace per free pose; None when unavailable (``*_status``).
    trace_translation, trace_rotation : float or None
        The paper model's trace split into translations and rotations.
    trace_crlb_curvature, mse_bound_curvature, curvature_correction_max : float or None
        3D paper model: the same with eq. (68)'s curvature correction, and its largest ratio
        to the first-order term over poses.
    coordinates : list of str
        Coordinates of a pose's block.
    frame, coordinates_description : str
        What the coordinates mean.
    ordering : dict of str to str
        ``requested`` and the factorization's ordering (``crlb``).
    per_pose, per_pose_curvature : dict of int to numpy.ndarray, or None
        The (q, q) block of the bound of each asked pose id (3D paper: also eq. 68's).
    estimate : Estimate
        Where the poses come from.
    times : dict of str to float
        Seconds per step.

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.crlb("intel", poses=[1, 2])
    >>> round(res.trace_crlb, 2), res.anchors
    (23894.17, [0])
    >>> res.to_frame().round(6)
       id     var_x     var_y  var_theta     trace
    0   1  0.005794  0.005794   0.002226  0.013814
    1   2  0.011651  0.012008   0.004436  0.028095
    """

    kind: str
    fim_variant: str | None = optional_field()
    rotation_weight: str | None = optional_field()
    anchors: list[int]
    nullity: int
    accuracy: InverseAccuracy | None = optional_field(**{NESTED: InverseAccuracy})
    trace_crlb: float | None = shared_status_field("inverse_status")
    mse_bound: float | None = shared_status_field("inverse_status")
    trace_translation: float | None = shared_status_field("inverse_status", None, omit_none=True)
    trace_rotation: float | None = shared_status_field("inverse_status", None, omit_none=True)
    trace_crlb_curvature: float | None = shared_status_field("curvature_numbers_status", None, omit_none=True)
    mse_bound_curvature: float | None = shared_status_field("curvature_numbers_status", None, omit_none=True)
    curvature_correction_max: float | None = optional_field()
    curvature_status: Status = internal_field(OK)
    coordinates: list[str]
    frame: str
    ordering: dict[str, str] = field(default_factory=dict)
    coordinates_description: str = derived_field(_description)
    per_pose: dict[int, np.ndarray] | None = optional_field(codec=pose_blocks_codec())
    per_pose_curvature: dict[int, np.ndarray] | None = optional_field(codec=pose_blocks_codec())
    estimate: Estimate | None = field(default=None, metadata={NESTED: Estimate})
    times: dict[str, float] = field(default_factory=dict)
    inputs: tuple[str, ...] = inputs_field()

    @property
    def inverse_status(self) -> Status:
        """The status every number of the bound inherits from the inverse's accuracy: its own when
        the inverse is unusable, ok otherwise (a warning stays on ``accuracy``)."""
        if self.accuracy is None or self.accuracy.status.available:
            return OK
        return self.accuracy.status

    @property
    def curvature_numbers_status(self) -> Status:
        """The status of eq. (68)'s curvature-corrected numbers (3D paper model): the inverse's
        when it is unusable, else the validity of the expansion (``curvature_status``)."""
        if not (self.dim == 3 and self.model == "paper"):
            return OK
        return self.curvature_status if self.inverse_status.available else self.inverse_status

    def statuses(self) -> dict[str, Status]:
        """The inverse's accuracy (``"CRLB"``), eq. (68)'s validity in 3D and the estimate's
        certificate; the ``*_status`` of each number follow from them."""
        out: dict[str, Status] = {}
        if self.accuracy is not None:
            out["CRLB"] = self.accuracy.status
        if self.dim == 3 and self.model == "paper":
            out["curvature-corrected CRLB (eq. 68)"] = self.curvature_status
        if self.estimate is not None:
            out.update(self.estimate.statuses())
        return out

    @classmethod
    def _restore(cls, kwargs: dict[str, Any], d: Mapping[str, Any]) -> None:
        """eq. (68)'s status comes back from ``trace_crlb_curvature_status`` when the inverse itself
        is usable (the JSON carries it only there)."""
        accuracy = kwargs.get("accuracy")
        if d.get("dim") == 3 and d.get("model") == "paper" and (accuracy is None or accuracy.status.available) \
                and d.get("trace_crlb_curvature_status") is not None:
            kwargs["curvature_status"] = Status.from_json(d["trace_crlb_curvature_status"])

    def pose_rows(self) -> list[dict[str, Any]]:
        """One dict per pose with blocks: ``id``, ``var_<coordinate>`` (the block's diagonal),
        ``trace`` and (3D paper) ``trace_curvature``."""
        rows: list[dict[str, Any]] = []
        for k, v in (self.per_pose or {}).items():
            r: dict[str, Any] = {"id": int(k), **{f"var_{c}": float(x) for c, x in zip(self.coordinates, np.diag(v))},
                                 "trace": float(np.trace(v))}
            if self.per_pose_curvature is not None:
                r["trace_curvature"] = float(np.trace(self.per_pose_curvature[k]))
            rows.append(r)
        return rows

    def to_frame(self) -> Any:
        """One row per pose with blocks (``pose_rows``); ``UsageError`` when none were asked."""
        import pandas as pd  # noqa: PLC0415 -- lazy: start-up time (pandas only for frames)

        if self.per_pose is None:
            raise UsageError("this CrlbResult has no per-pose blocks: ask for them with poses='all' or a "
                             "list of pose ids")
        return pd.DataFrame(self.pose_rows())

