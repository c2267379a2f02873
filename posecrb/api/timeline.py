"""``posecrb.timeline``: the information timeline of a pose graph (the ``timeline`` command).

A module of its own beside ``posecrb.api.functions``, with the same conventions: sources, keywords
named as the command's options, arguments checked in Python terms, a result whose ``to_dict()`` is
the command's JSON.
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING

from ..core.graph import PoseGraph
from ..core.result import check_output_argument
from . import arguments as arg
from .functions import ROTATION_WEIGHTS, EstimateSpec, Source

if TYPE_CHECKING:
    from ..incremental.result import TimelineResult


def timeline(source: Source, *, estimate: EstimateSpec = "solve", every: int = 1, start: int | None = None,
             stop: int | None = None, rotation_weight: str = "eq59", fim_variant: str | None = None,
             plot: str | os.PathLike[str] | None = None,
             data_dir: str | os.PathLike[str] | None = None) -> TimelineResult:
    """D- and T-optimality of every prefix of a pose graph as it grows, and which loop closures
    matter: the information timeline.

    Poses are added in id order. Step K is the graph on the K poses with the smallest ids and the
    edges among them, anchored at the smallest id; each row holds what ``bounds`` reports for that
    prefix: ``lb`` and ``ub`` (eq. 75, graph only), ``t_opt_graph`` (eq. 73) and ``fim_logdet``
    at the estimate restricted to the prefix. Every edge a step adds beyond the new pose's edge to
    its largest older neighbour is a loop closure; its ``gain`` is its sequential increase of
    ``lb`` in file order. Computed incrementally (closed forms for new poses, rank-one updates for
    loop closures) and checked against factorizations from scratch (docs/design.md#timeline).

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    estimate : "solve", "vertices", "none", path, SolveResult, Estimate or None
        Where the poses of ``fim_logdet`` come from: the certified optimum of the whole graph
        (default, the final map), the file's VERTEX lines, another file with the same ids, or
        ``"none"``/None for graph-only rows.
    every : int
        Keep every ``every``-th row from ``start`` on, and the last one (every step is computed).
    start, stop : int, optional
        The range of steps as numbers of poses (the command's ``--from`` / ``--to``); default
        2 to all poses.
    rotation_weight : {"eq59", "table2"}
        3D rotation weight, as for ``bounds``.
    fim_variant : {"consistent", "eq64"}, optional
        The FIM's variant (default ``"consistent"``, the model's Fisher information).
    plot : str or os.PathLike, optional
        Also draw the timeline into this figure (``.png``, ``.svg`` or ``.pdf``; checked before
        the work, never onto an input).
    data_dir : str or os.PathLike, optional
        Searched first for a bare dataset name.

    Returns
    -------
    TimelineResult
        One row per kept step (``to_frame()``), the monotonicity of every metric, raw and per
        dimension (``monotonicity``), every loop closure's gain (``closures_frame()``); log-dets
        are natural logarithms. ``to_dict()`` is the ``timeline`` command's JSON object.

    Raises
    ------
    ArgumentError
        A bad range, ``every``, estimate or output path.
    ParseError, DatasetNotFound
        The file cannot be read.
    SolverError
        The whole graph's optimum could not be computed (``estimate="solve"``).

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.timeline("intel", estimate="none", every=500)
    >>> res.to_frame()["poses"].tolist()
    [2, 502, 1002, 1502, 1728]
    >>> m = res.monotonicity["lb"]                    # a leaf adds d log tau + d_r log w: raw lb rises here,
    >>> m["raw"].monotone, m["per_dimension"].monotone  # the per-dimension D-criterion does not
    (True, False)
    """
    from ..incremental import timeline as compute_timeline  # noqa: PLC0415 -- lazy: start-up time
    from ..models.paper.fim import FIM_VARIANTS  # noqa: PLC0415 -- lazy: start-up time
    from ..report.figures import FIGURE_EXTENSIONS  # noqa: PLC0415 -- lazy: start-up time

    every = arg.integer("every", every, 1)
    start = None if start is None else arg.integer("start", start, 2)
    stop = None if stop is None else arg.integer("stop", stop, 2)
    arg.choice("rotation_weight", rotation_weight, ROTATION_WEIGHTS)
    variant = "consistent" if fim_variant is None else arg.choice("fim_variant", fim_variant, FIM_VARIANTS)
    target = None
    if plot is not None:
        inputs = () if isinstance(source, PoseGraph) else (arg.resolve_source(source, data_dir),)
        est_input = (os.fspath(estimate),) if isinstance(estimate, (str, os.PathLike)) and \
            os.fspath(estimate) not in ("solve", "vertices", "none") else ()
        target = check_output_argument("plot", plot, inputs + est_input, extensions=FIGURE_EXTENSIONS)
    graph, _ = arg.load_graph(source, data_dir)
    if arg.is_pose_object(estimate):
        poses = arg.resolve_estimate(graph, estimate)
    else:
        poses = None if arg.estimate_spec(estimate, allow_none=True) == "none" else \
            arg.resolve_estimate(graph, arg.estimate_spec(estimate))
    res = compute_timeline(graph, estimate=poses, every=every, start=start, stop=stop,
                           rotation_weight=rotation_weight, fim_variant=variant)
    if target is not None:
        from ..report.plots import plot_timeline  # noqa: PLC0415 -- matplotlib, only for a figure

        plot_timeline(res, target)
    return res
