"""``posecrb.bounds``: D-optimality of a pose graph, the paper's Table I/II row."""
from __future__ import annotations

import os
from typing import TYPE_CHECKING, Literal

from ..core.arguments import choice
from ..core.choices import FIM_VARIANTS, ORDERINGS, ROTATION_WEIGHTS, FimVariant, Ordering, RotationWeight
from . import arguments as arg
from .arguments import OptionalEstimateSpec, Source, public

if TYPE_CHECKING:
    from ..models.paper.result import BoundsResult


@public()
def bounds(source: Source, *, anchor: int | None = None, repeat: int | Literal["auto"] = 1,
           rotation_weight: RotationWeight = "eq59", estimate: OptionalEstimateSpec = "solve",
           fim_variant: FimVariant | None = None, ordering: Ordering = "auto",
           data_dir: str | os.PathLike[str] | None = None) -> BoundsResult:
    """D-optimality of a pose graph: the graph-only bounds on the FIM's log-det (the paper's
    Table I/II row) and the log-det itself at an estimate.

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    anchor : int, optional
        The anchored pose id; default the smallest id.
    repeat : int or "auto"
        Timing of each stage (``times``; ``runs`` says how many runs each is the median of): 1,
        each step once (the default here); K > 1, a warm-up, then the median of K runs;
        ``"auto"`` (the command's default), one run when a stage takes 1 s or more, else a warm-up
        and the median of the runs that fit in about 2 s (at most 5).
    rotation_weight : {"eq59", "table2"}
        3D rotation weight: eq. (59), or the empirical fit to the paper's printed Table II.
    estimate : "solve", "vertices", path, SolveResult, Estimate or None
        Where the poses of ``fim_logdet`` come from: the certified solver (default), the file's
        VERTEX lines, another file's vertices, a result of ``posecrb.solve``, given poses; None
        (or ``"none"``) for the graph-only columns.
    fim_variant : {"consistent", "eq64"}, optional
        The FIM whose log-det is reported: the model's Fisher information (default) or eq. (64)
        as printed (3D; the same matrix in 2D).
    ordering : {"auto", "amd", "colamd", "metis", "nesdis"}
        Fill-reducing ordering of the factorizations (cost only).
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.

    Returns
    -------
    BoundsResult
        ``bounds`` (``lb``, ``ub``, ``ub_lambda``, Lemma 4's ``gap_bound``, T-optimality) and,
        with an estimate, ``fim`` (the FIM's log-det and trace there); natural logs.

    Raises
    ------
    DisconnectedGraph
        The graph is not connected.
    ArgumentError
        An argument out of range or an anchor that is not a pose id.

    Examples
    --------
    >>> import posecrb
    >>> b = posecrb.bounds("intel", estimate=None)
    >>> round(b.lb, 3), round(b.ub_lambda, 3), b.fim_logdet is None
    (30155.231, 33537.021, True)
    """
    from ..evaluation.evaluate import EvaluationSettings, evaluate  # noqa: PLC0415 -- lazy: start-up time

    ids = arg.one_anchor(anchor)
    repeat = arg.repeat_setting(repeat)
    choice("rotation_weight", rotation_weight, ROTATION_WEIGHTS)
    variant = "consistent" if fim_variant is None else choice("fim_variant", fim_variant, FIM_VARIANTS)
    choice("ordering", ordering, ORDERINGS)
    graph, times, runs = arg.load_graph_timed(source, data_dir, repeat=repeat)
    idx = graph.anchor_index(ids[0] if ids else None)
    given = arg.resolve_estimate(graph, estimate) if arg.is_pose_object(estimate) else None
    spec = "none" if given is not None else arg.estimate_spec(estimate, allow_none=True)
    settings = EvaluationSettings(anchor=idx, rotation_weight=rotation_weight, fim_variant=variant, repeat=repeat,
                                  estimate=spec, solver={"anchor": idx} if spec == "solve" else {},
                                  ordering=ordering)
    return evaluate(graph, settings, estimate=given, times=times, runs=runs).result
