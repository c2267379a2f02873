"""``posecrb.verify``: is an estimate that another program computed the global optimum?"""
from __future__ import annotations

import os
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from ..core.arguments import choice, flag
from ..core.choices import ESTIMATE_FORMATS, ROW_ORDERS, EstimateFormat, RowOrder
from ..core.errors import ArgumentError
from ..core.graph import PoseGraph
from . import arguments as arg
from .arguments import Source, public

if TYPE_CHECKING:
    from ..solver.estimate import Estimate
    from ..solver.solve import SolveResult
    from ..verification.result import VerifyResult
    from ..verification.verify import Poses


@public()
def verify(source: Source, estimate: str | os.PathLike[str] | Estimate | SolveResult, *,
           estimate_format: EstimateFormat = "auto", tum_ids: RowOrder = "order",
           truth: str | os.PathLike[str] | Estimate | None = None, solve: bool = True,
           certificate_tol: float = 1e-3, anchor: int | None = None,
           data_dir: str | os.PathLike[str] | None = None) -> VerifyResult:
    """Whether an estimate computed elsewhere is the global optimum of the maximum-likelihood
    problem ``posecrb solve`` minimises, how far it is from it, and whether that matters.

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        The graph: a graph, a path or a dataset name (see ``load``).
    estimate : str, os.PathLike, Estimate or SolveResult
        The estimate to judge: a path or a dataset name (resolved as ``source``) of a file of g2o or
        TORO VERTEX lines (what g2o, GTSAM's ``writeG2o`` and ``posecrb solve --out`` write; the
        graph's own file judges its vertices), Ceres' ``id x y yaw`` / ``id x y z qx qy qz qw``
        lines, TUM ``timestamp x y z qx qy qz qw`` lines or KITTI's 12 numbers per line; or poses in
        memory.
    estimate_format : {"auto", "g2o", "toro", "ceres", "tum", "kitti"}
        The file's format: read from the content (``"auto"``) or insisted on.
    tum_ids : {"order", "timestamps"}
        TUM and KITTI rows carry no pose ids: row k is the pose with the k-th smallest id
        (``"order"``), or, TUM only, the timestamp is the pose id (``"timestamps"``).
    truth : str, os.PathLike or Estimate, optional
        The ground truth of a synthetic graph (any estimate format; ``posecrb datasets synth``
        writes it as the vertices): also the trajectory errors of the estimate and of the optimum
        against it, and the estimate's NEES against the CRLB at the truth.
    solve : bool
        Also compute the certified optimum, the refinement from the estimate and the distances to
        the optimum (default). Without, only the certificate at the estimate (about one
        certificate check of ``solve``); the keys that need the optimum are None with a status.
    certificate_tol : float
        Accept ``lambda_min(Q - Lambda) >= -certificate_tol`` as the certificate, as ``solve`` does.
    anchor : int, optional
        The pose id of the gauge (the Mahalanobis distances); default the smallest id.
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.

    Returns
    -------
    VerifyResult
        The verdict (``"certified-optimal"``, ``"global-basin"``, ``"local-minimum"`` or
        ``"uncertified"``) with the evidence behind it.

    Raises
    ------
    ParseError
        The estimate file is malformed or does not match the graph: ids missing or extra, the
        wrong dimension, non-finite numbers, rotations beyond their digits' rounding
        (``path:line: reason``).
    DisconnectedGraph
        The graph is not connected.

    Examples
    --------
    >>> import posecrb
    >>> opt = posecrb.solve("intel")
    >>> posecrb.verify("intel", opt, solve=False).verdict
    'certified-optimal'
    >>> res = posecrb.verify("intel", "intel")           # the file's own vertices: odometry
    >>> res.verdict, round(res.relative_suboptimality, 2)
    ('global-basin', 10.24)
    """
    from ..verification.verify import verify_estimate  # noqa: PLC0415 -- lazy: start-up time

    fmt: EstimateFormat = choice("estimate_format", estimate_format, ESTIMATE_FORMATS)
    rows: RowOrder = choice("tum_ids", tum_ids, ROW_ORDERS)
    solve = flag("solve", solve)
    certificate_tol = arg.finite("certificate_tol", certificate_tol, 0.0, low_open=True)
    ids = arg.one_anchor(anchor)
    graph, times = arg.load_graph(source, data_dir)
    est = _poses(graph, estimate, "estimate", fmt, rows, data_dir)
    gt = None if truth is None else _poses(graph, truth, "truth", "auto", "order", data_dir)
    res = verify_estimate(graph, est, anchor=graph.anchor_index(ids[0] if ids else None), run_solve=solve,
                          certificate_tol=certificate_tol, truth=gt)
    if times:
        res = replace(res, times={**times, **res.times, "total": res.times["total"] + times["parse"]})
    return res


def _poses(graph: PoseGraph, value: Any, parameter: str, fmt: EstimateFormat, tum_ids: RowOrder,
           data_dir: str | os.PathLike[str] | None) -> Poses:
    """The poses ``value`` gives on ``graph`` (a path or a dataset name, or poses in memory), with their
    precision."""
    import numpy as np  # noqa: PLC0415 -- lazy: start-up time

    from ..io.estimates import read_estimate_file  # noqa: PLC0415 -- lazy: start-up time
    from ..verification.judge import Precision  # noqa: PLC0415 -- lazy: start-up time
    from ..verification.verify import Poses  # noqa: PLC0415 -- lazy: start-up time

    if arg.is_pose_object(value):
        est = arg.resolve_estimate(graph, value)
        assert est is not None
        return Poses(est.rot, est.trans, Precision.exact(graph.n), {"source": est.source})
    if not isinstance(value, (str, os.PathLike)):
        raise ArgumentError(parameter, value, "is not a file, an Estimate or a SolveResult")
    path = arg.path_or_none(parameter, value)
    assert path is not None
    found = read_estimate_file(arg.resolve_source(path, data_dir), format=fmt)
    poses = found.poses_for(graph, rows=tum_ids)
    return Poses(poses.rot, poses.trans, Precision(poses.rotation_quantum, poses.translation_quantum),
                 {"path": found.path, "format": poses.format,
                  "rotation_quantum": float(np.max(poses.rotation_quantum, initial=0.0)),
                  "translation_quantum": float(np.max(poses.translation_quantum, initial=0.0))})


__all__ = ["verify"]
