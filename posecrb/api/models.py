"""``posecrb.fim`` and ``posecrb.crlb``: the Fisher information and the Cramér-Rao bound of either model
at an estimate (``posecrb.models``: the model with its settings, ``model_for``)."""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from ..core.choices import FimVariant, Frame, Model, Ordering, RotationWeight
from ..core.errors import ArgumentError
from . import arguments as arg
from .arguments import EstimateSpec, PoseSelection, Source, public

if TYPE_CHECKING:
    from ..models.results import CrlbResult, FimResult
    from ..solver.estimate import Estimate


@public(save="write the result with res.save(path)")
def fim(source: Source, *, model: Model = "paper", estimate: EstimateSpec = "solve", anchor: int | None = None,
        rotation_weight: RotationWeight = "eq59", fim_variant: FimVariant | None = None, frame: Frame | None = None,
        ordering: Ordering = "auto", data_dir: str | os.PathLike[str] | None = None) -> FimResult:
    """The Fisher information matrix of a pose graph at an estimate, paper or sed model.

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    model : {"paper", "sed"}
        ``"paper"``: Chen et al.'s anchored FIM on (R^d x SO(d))^n, isotropic noise (eq. 42 in
        2D, 64 in 3D); rotation coordinates: the angle (2D), along G_k/sqrt(2) (3D).
        ``"sed"``: the thesis's FIM on SE(d)^n with the full information matrices (4.6).
    estimate : "solve", "vertices", path, SolveResult or Estimate
        Where the poses come from (see ``bounds``).
    anchor : int, optional
        Pose id anchored for the log-det; default the smallest id (of each component, sed).
    rotation_weight : {"eq59", "table2"}
        Paper model, 3D rotation weight.
    fim_variant : {"consistent", "eq64"}, optional
        Paper model: the model's Fisher information (default) or eq. (64) as printed.
    frame : {"world", "body"}, optional
        sed model: the thesis's coordinates (default) or GTSAM's and g2o's (``X_i Exp(xi)``).
    ordering : {"auto", "amd", "colamd", "metis", "nesdis"}
        Fill-reducing ordering of the log-det factorization (cost only).
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.

    Returns
    -------
    FimResult
        Size, nnz, log-det (natural log; translations in the file's length units), trace, rank,
        nullity, and the matrix (``FimResult.save(path)`` writes it with its index map, a file
        that ``scipy.sparse.load_npz`` also reads).

    Raises
    ------
    ArgumentError
        An unknown model, a setting of the other model (``frame`` with ``"paper"``,
        ``fim_variant`` with ``"sed"``), an anchor that is not a pose id.

    Examples
    --------
    >>> import posecrb
    >>> f = posecrb.fim("intel", model="sed")
    >>> f.size, f.rank, f.nullity, f.frame
    (5184, 5181, 3, 'world')
    """
    from ..models import model_for  # noqa: PLC0415 -- lazy: start-up time

    chosen = model_for(model, rotation_weight=rotation_weight, fim_variant=fim_variant, frame=frame, ordering=ordering)
    ids = arg.one_anchor(anchor)
    graph, times = arg.load_graph(source, data_dir)
    if ids:
        arg.check_anchors(graph, ids)
    est = _estimate(graph, estimate)
    res = chosen.fim(graph, est, anchor=ids[0] if ids else None)
    return replace(res, times={**times, **arg.estimate_times(est), **res.times})


@public()
def crlb(source: Source, *, model: Model = "paper", quotient: bool = False, anchor: int | Sequence[int] | None = None,
         poses: PoseSelection = None, estimate: EstimateSpec = "solve", rotation_weight: RotationWeight = "eq59",
         fim_variant: FimVariant | None = None, frame: Frame | None = None, ordering: Ordering = "auto",
         data_dir: str | os.PathLike[str] | None = None) -> CrlbResult:
    """The Cramér-Rao lower bound of a pose graph at an estimate, paper or sed model.

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    model : {"paper", "sed"}
        ``"paper"``: ``C >= F^{-1}`` of the anchored paper FIM (eq. 67), with eq. (68)'s
        curvature term in 3D. ``"sed"``: the thesis's intrinsic bound on SE(d)^n, anchored
        (5.1) or quotient (5.5).
    quotient : bool
        sed: the quotient bound ``F^+`` (5.5) instead of the anchored one.
    anchor : int or sequence of int, optional
        Anchored pose id (paper: one; sed: one or more per component). Default: the smallest id
        (of each component).
    poses : True, "all" or sequence of int, optional
        Also compute the per-pose blocks of every pose (True or ``"all"``) or of these pose ids
        (the command line's ``--poses 0,5,10-12`` is ``[0, 5, *range(10, 13)]``).
    estimate : "solve", "vertices", path, SolveResult or Estimate
        Where the poses come from (see ``bounds``).
    rotation_weight, fim_variant, frame, ordering
        As for ``fim``.
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.

    Returns
    -------
    CrlbResult
        ``trace_crlb`` (the trace of the bound; translations in the file's length units squared,
        rotations in radians squared), ``mse_bound`` per free pose, the inverse's accuracy, and
        the per-pose blocks asked (``to_frame()``).

    Raises
    ------
    ArgumentError
        An anchor or pose that is not a pose id, several anchors for the paper model,
        ``quotient`` with the paper model, a setting of the other model.

    Examples
    --------
    >>> import posecrb
    >>> c = posecrb.crlb("intel", model="sed")
    >>> c.kind, c.anchors, round(c.trace_crlb, 2)
    ('anchored', [0], 12647.08)
    """
    from ..models import model_for  # noqa: PLC0415 -- lazy: start-up time

    chosen = model_for(model, rotation_weight=rotation_weight, fim_variant=fim_variant, frame=frame,
                       quotient=quotient, ordering=ordering)
    ids = arg.anchor_ids(anchor)
    want = arg.pose_selection(poses)
    graph, times = arg.load_graph(source, data_dir)
    arg.check_anchors(graph, ids)
    est = _estimate(graph, estimate)
    res = chosen.crlb(graph, est, anchors=ids, poses=want)
    return replace(res, times={**times, **arg.estimate_times(est), **res.times})


def _estimate(graph: Any, estimate: Any) -> Estimate:
    est = arg.resolve_estimate(graph, estimate)
    if est is None:  # pragma: no cover - resolve_estimate refuses None here
        raise ArgumentError("estimate", estimate, "is required")
    return est
