"""The functions of the public API: ``load``, ``parse``, ``solve``, ``bounds``, ``fim``, ``crlb``,
``select``.

Each takes a ``PoseGraph``, a path or a bare dataset name (resolved as the command line does:
``data_dir``, ``$POSECRB_DATA``, ``./datasets``, ``~/.cache/posecrb``, the manifest's names),
and keywords named as the command's options in snake case with the same defaults, except that a
library call does the work once (``repeat=1``). Anchors and per-pose requests are pose ids as in
the file, never internal indices. Each returns a result of the one protocol
(``posecrb.core.result``) whose ``to_dict()`` is the command's ``--format json`` object.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any, TypeAlias

from ..core.errors import ArgumentError
from ..core.graph import PoseGraph
from ..core.outputs import GRAPH_EXTENSIONS
from ..core.result import check_output_argument
from . import arguments as arg

if TYPE_CHECKING:
    from ..evaluation.evaluate import DatasetMetrics
    from ..models.results import CrlbResult, FimResult
    from ..solver.estimate import Estimate
    from ..solver.solve import SolveResult
    from .results import BoundsResult, SelectResult

# Each function imports the layers it runs on when called (start-up time: the command line
# imports this module for one command, and ``solve`` must not load the models or the selection).
ROTATION_WEIGHTS = ("eq59", "table2")
FRAMES = ("world", "body")
MODELS = ("paper", "sed")                    # posecrb.models.MODELS
Source = PoseGraph | str | os.PathLike[str]
EstimateSpec: TypeAlias = "str | os.PathLike[str] | SolveResult | Estimate | None"


def load(source: str | os.PathLike[str], data_dir: str | os.PathLike[str] | None = None, *,
         quaternions: str = "normalize") -> PoseGraph:
    """Read a pose graph from a g2o or TORO file, by path or by dataset name.

    The format is found from the content, never from the file name. A bare name (``"intel"``,
    ``"garage"``) is resolved exactly as the command line resolves its FILE arguments.

    Parameters
    ----------
    source : str or os.PathLike
        A path, or a dataset name looked up in ``data_dir``, ``$POSECRB_DATA``, ``./datasets``
        and ``~/.cache/posecrb`` (then the manifest's names, e.g. the paper's ``garage``).
    data_dir : str or os.PathLike, optional
        Directory searched first for bare names (the command line's ``--data-dir``).
    quaternions : {"normalize", "raw"}
        How 3D edge quaternions become rotations: normalised (default), or as written, as
        SE-Sync reads them (only to reproduce SE-Sync's objective values).

    Returns
    -------
    PoseGraph
        The checked graph; pose ids as in the file (``graph.ids``).

    Raises
    ------
    DatasetNotFound
        A bare name that is nowhere on the search path.
    ParseError
        The file cannot be read or is malformed (``path:line: reason``).
    ArgumentError
        ``source`` is not a path or a name (bytes: use ``parse``).

    Examples
    --------
    >>> import posecrb
    >>> graph = posecrb.load("intel")
    >>> graph.dim, graph.n, graph.m
    (2, 1728, 2512)
    """
    arg.choice("quaternions", quaternions, ("normalize", "raw"))
    return arg.load_graph(source, data_dir, quaternions=quaternions)[0]


def parse(text: str | bytes) -> PoseGraph:
    """Read a pose graph from the content of a g2o or TORO file.

    Parameters
    ----------
    text : str or bytes
        The file's content (bytes are decoded as UTF-8). The format is detected from the records.

    Returns
    -------
    PoseGraph
        The checked graph (its ``path`` is ``"<string>"``).

    Raises
    ------
    ParseError
        Malformed content (``<string>:line: reason``).
    ArgumentError
        ``text`` is neither ``str`` nor ``bytes``.

    Examples
    --------
    >>> import posecrb
    >>> g = posecrb.parse('''
    ... EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000
    ... EDGE_SE2 1 2 1 0 0 100 0 0 100 0 1000
    ... EDGE_SE2 2 0 -2 0 0 100 0 0 100 0 1000
    ... ''')
    >>> g.dim, g.n, g.m, g.ids.tolist()
    (2, 3, 3, [0, 1, 2])
    """
    return arg.parse_content(text)


def solve(source: Source, *, r0: int | None = None, rmax: int = 10, init: str = "chordal",
          anchor: int | None = None, certificate_tol: float = 1e-3, sesync_compat: bool = False,
          out: str | os.PathLike[str] | None = None, data_dir: str | os.PathLike[str] | None = None,
          **options: Any) -> SolveResult:
    """The certified maximum-likelihood estimate of a pose graph (SE-Sync's Riemannian staircase).

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    r0, rmax : int
        First (default d + 1) and last rank of the staircase (2..100).
    init : {"chordal", "vertices"}
        Initial rotations: the chordal relaxation, or the file's own vertices.
    anchor : int, optional
        Pose id put at the identity; default the smallest id.
    certificate_tol : float
        Accept ``lambda_min(Q - Lambda) >= -certificate_tol`` as the certificate (> 0).
    sesync_compat : bool
        Read 3D quaternions as SE-Sync does (unnormalised) to reproduce its objective values.
    out : str or os.PathLike, optional
        Write the estimate as g2o (original ids and edges, vertices replaced), checked before
        the work.
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.
    **options
        Further ``posecrb.solver.SolverOptions`` fields (``max_iterations``, ``seed``, ...).

    Returns
    -------
    SolveResult
        The estimate, its objective and certificate. An uncertified estimate is returned too
        (``certified`` False, ``status`` a warning); the command line exits 1 then.

    Raises
    ------
    DisconnectedGraph
        The graph is not connected.
    ArgumentError
        An argument out of range, an anchor that is not a pose id.

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.solve("intel")
    >>> res.certified, res.rank
    (True, 3)
    >>> round(res.objective, 6)
    52.348227
    """
    from ..io import load as read_graph  # noqa: PLC0415 -- lazy: start-up time
    from ..io import write_g2o  # noqa: PLC0415 -- lazy: start-up time
    from ..solver import SolverOptions  # noqa: PLC0415 -- lazy: start-up time
    from ..solver import solve as run_solver  # noqa: PLC0415 -- lazy: start-up time

    arg.flag("sesync_compat", sesync_compat)
    quaternions = "raw" if sesync_compat else "normalize"
    if isinstance(source, PoseGraph) and source.quaternions != quaternions:
        raise ArgumentError("sesync_compat", sesync_compat, f"does not match the graph, read with "
                            f"quaternions={source.quaternions!r}: pass its path or name instead")
    r0 = None if r0 is None else arg.integer("r0", r0, 2, 100)
    rmax = arg.integer("rmax", rmax, 2, 100)
    arg.choice("init", init, ("chordal", "vertices"))
    certificate_tol = arg.finite("certificate_tol", certificate_tol, 0.0, low_open=True)
    ids = arg.anchor_ids(anchor)
    if len(ids) > 1:
        raise ArgumentError("anchor", anchor, "is several pose ids; the solver puts one at the identity")
    target = None
    if out is not None:
        inputs = () if isinstance(source, PoseGraph) else (arg.resolve_source(source, data_dir),)
        target = check_output_argument("out", out, inputs, extensions=GRAPH_EXTENSIONS)
    graph, times = arg.load_graph(source, data_dir, quaternions=quaternions)
    opts = SolverOptions.from_keywords(r0=r0, rmax=rmax, init=init, anchor=graph.anchor_index(ids[0] if ids else None),
                                       certificate_tol=certificate_tol, **options)
    res = run_solver(graph, opts)
    if target is not None:
        if sesync_compat and graph.path is None:
            raise ArgumentError("out", target, "needs the graph's file with sesync_compat=True (the edges are "
                                "written as the normalised reading)", sep=": ")
        # Edges as the normalised reading: a raw, non-orthogonal R~ has no quaternion of its own.
        write_g2o(read_graph(graph.path) if sesync_compat and graph.path else graph, target, res.rot, res.trans)
    parse_time = times.get("parse")
    if parse_time is not None:
        times = {"parse": parse_time, **{k: res.times[k] for k in ("init", "optimize", "verify", "round")},
                 "total": parse_time + res.times["total"]}
    else:
        times = dict(res.times)
    return replace(res, times=times, saved=target)


def bounds(source: Source, *, anchor: int | None = None, repeat: int | str = 1, rotation_weight: str = "eq59",
           estimate: EstimateSpec = "solve", fim_variant: str | None = None, ordering: str = "auto",
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
        ``lb``, ``ub``, ``ub_lambda``, Lemma 4's ``gap_bound``, T-optimality and, with an
        estimate, ``fim_logdet`` (natural logs).

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
    from ..linalg.ordering import ORDERINGS  # noqa: PLC0415 -- lazy: start-up time
    from ..models.paper.fim import FIM_VARIANTS  # noqa: PLC0415 -- lazy: start-up time

    ids = _one_anchor(anchor)
    repeat = arg.repeat_setting(repeat)
    arg.choice("rotation_weight", rotation_weight, ROTATION_WEIGHTS)
    variant = "consistent" if fim_variant is None else arg.choice("fim_variant", fim_variant, FIM_VARIANTS)
    arg.choice("ordering", ordering, ORDERINGS)
    graph, times, runs = arg.load_graph_timed(source, data_dir, repeat=repeat)
    idx = graph.anchor_index(ids[0] if ids else None)
    given = arg.resolve_estimate(graph, estimate) if arg.is_pose_object(estimate) else None
    spec = "none" if given is not None else arg.estimate_spec(estimate, allow_none=True)
    settings = EvaluationSettings(anchor=idx, rotation_weight=rotation_weight, fim_variant=variant, repeat=repeat,
                                  estimate=spec, solver={"anchor": idx} if spec == "solve" else {},
                                  ordering=ordering)
    m = evaluate(graph, settings, estimate=given)
    return _bounds_result(m, times, runs, ordering)


def _bounds_result(m: DatasetMetrics, times: dict[str, float], runs: dict[str, int],
                   ordering: str) -> BoundsResult:
    from ..models.paper.fim import trace_fim  # noqa: PLC0415 -- lazy: start-up time
    from .results import BoundsResult  # noqa: PLC0415 -- lazy: start-up time

    g, b = m.graph, m.bounds
    est = m.estimate
    extra: dict[str, Any] = {}
    all_times = {**times, **b.times}
    all_runs: dict[str, int] = {**runs, **b.runs}
    if est is not None and m.fim is not None:
        extra = {"fim_logdet": m.fim_logdet, "fim_logdet_status": m.fim_logdet_status,
                 "trace_fim": trace_fim(m.fim), "fim_variant": m.fim.variant, "estimate": est}
        all_times.update(fim_build=m.times["fim_build"], fim_logdet=m.times["fim_logdet"],
                         logdet_accuracy=m.times["logdet_accuracy"])
        all_runs.update(fim_build=m.runs["fim_build"], fim_logdet=m.runs["fim_logdet"],
                        logdet_accuracy=m.runs["logdet_accuracy"])
        if est.solve_time is not None:
            all_times["solve"] = est.solve_time
            all_runs["solve"] = 1
    return BoundsResult(
        dataset=g.name, path=g.path, sha256=g.sha256, dim=g.dim, poses=g.n, edges=g.m, components=g.n_components,
        anchor=b.anchor_id, rotation_weight=b.rotation_weight, lb=b.lb, ub=b.ub, ub_status=b.ub_status,
        ub_lambda=b.ub_lambda, lambda_inf=b.lambda_inf, lambda_min_rot=b.lambda_min_rot,
        lambda_min_rot_status=b.lambda_min_rot_status, lambda_min_rot_lower=b.lambda_min_rot_lower,
        gap_bound=b.gap_bound, gap_bound_status=b.gap_bound_status, t_opt_graph=b.t_opt_graph,
        t_opt_approx=b.t_opt_approx, total_degree=b.total_degree, times=all_times, runs=all_runs,
        ordering={"requested": ordering, **m.ordering}, **extra)


def fim(source: Source, *, model: str = "paper", estimate: EstimateSpec = "solve", anchor: int | None = None,
        rotation_weight: str = "eq59", fim_variant: str | None = None, frame: str | None = None,
        ordering: str = "auto", save: str | os.PathLike[str] | None = None,
        data_dir: str | os.PathLike[str] | None = None) -> FimResult:
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
    save : str or os.PathLike, optional
        Also write the result with the matrix (``FimResult.save``; ``.npz`` appended unless
        present; ``scipy.sparse.load_npz`` reads the matrix), checked before the work.
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.

    Returns
    -------
    FimResult
        Size, nnz, log-det (natural log; translations in the file's length units), trace, rank,
        nullity, and the matrix.

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
    from ..linalg.ordering import ORDERINGS  # noqa: PLC0415 -- lazy: start-up time
    from ..models import model_fim  # noqa: PLC0415 -- lazy: start-up time

    model = arg.choice("model", model, MODELS)
    variant, frame_ = _model_settings(model, fim_variant, frame)
    arg.choice("rotation_weight", rotation_weight, ROTATION_WEIGHTS)
    arg.choice("ordering", ordering, ORDERINGS)
    ids = _one_anchor(anchor)
    target = None
    if save is not None:
        inputs = () if isinstance(source, PoseGraph) else (arg.resolve_source(source, data_dir),)
        est_input = (os.fspath(estimate),) if isinstance(estimate, (str, os.PathLike)) and \
            os.fspath(estimate) not in ("solve", "vertices", "none") else ()
        target = check_output_argument("save", _npz(save), inputs + est_input, extensions=(".npz",))
    graph, times = arg.load_graph(source, data_dir)
    if ids:
        arg.check_anchors(graph, ids)
    est = arg.resolve_estimate(graph, estimate)
    if est is None:  # pragma: no cover - resolve_estimate refuses None here
        raise ArgumentError("estimate", estimate, "is required")
    res = model_fim(graph, est, model=model, anchor=ids[0] if ids else None, rotation_weight=rotation_weight,
                    fim_variant=variant, frame=frame_ if model == "sed" else "world", ordering=ordering)
    res = replace(res, times={**times, **arg.estimate_times(est), **res.times}, saved=target)
    if target is not None:
        res.save(target)
    return res


def crlb(source: Source, *, model: str = "paper", quotient: bool = False, anchor: int | Sequence[int] | None = None,
         poses: bool | str | Sequence[int] | None = None, estimate: EstimateSpec = "solve",
         rotation_weight: str = "eq59", fim_variant: str | None = None, frame: str | None = None,
         ordering: str = "auto", data_dir: str | os.PathLike[str] | None = None) -> CrlbResult:
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
    poses : "all", sequence of int or str, optional
        Also compute the per-pose blocks of these pose ids (a text such as ``"0,5,10-12"`` too).
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
    from ..linalg.ordering import ORDERINGS  # noqa: PLC0415 -- lazy: start-up time
    from ..models import model_crlb  # noqa: PLC0415 -- lazy: start-up time

    model = arg.choice("model", model, MODELS)
    variant, frame_ = _model_settings(model, fim_variant, frame)
    arg.choice("rotation_weight", rotation_weight, ROTATION_WEIGHTS)
    arg.choice("ordering", ordering, ORDERINGS)
    quotient = arg.flag("quotient", quotient)
    ids = arg.anchor_ids(anchor)
    want = arg.pose_request(poses)
    graph, times = arg.load_graph(source, data_dir)
    arg.check_anchors(graph, ids)
    est = arg.resolve_estimate(graph, estimate)
    if est is None:  # pragma: no cover - resolve_estimate refuses None here
        raise ArgumentError("estimate", estimate, "is required")
    res = model_crlb(graph, est, model=model, anchor=ids, quotient=quotient, poses=want,
                     rotation_weight=rotation_weight, fim_variant=variant, frame=frame_, ordering=ordering)
    return replace(res, times={**times, **arg.estimate_times(est), **res.times})


def select(source: Source, *, budget: int | str, objective: str = "tree", method: str = "greedy",
           fixed: str | os.PathLike[str] = "odometry", certify: bool = False, max_iter: int | None = None,
           tol: float = 1e-3, lazy: bool = False, jl: bool = False, exact: bool = False,
           estimate: EstimateSpec = "solve", seed: int = 0, out: str | os.PathLike[str] | None = None,
           anchor: int | None = None, data_dir: str | os.PathLike[str] | None = None) -> SelectResult:
    """Measurement selection: keep ``budget`` candidate edges maximising a D-optimality
    objective, with an upper bound on the best choice (a certificate).

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    budget : int or str
        Number K of candidate edges to keep, or ``"P%"`` of the candidates (rounded down).
    objective : {"tree", "fim", "fiedler"}
        ``"tree"``: ``d logdet L_tau + d_r logdet L_w`` (eq. 75); ``"fim"``: log-det of the
        anchored paper FIM at ``estimate``; ``"fiedler"``: algebraic connectivity of the
        rotation-weighted Laplacian.
    method : {"greedy", "relax", "random", "naive"}
        Exact greedy, Frank-Wolfe on the convex relaxation with rounding, seeded random, or the
        heaviest rotation weights.
    fixed : "odometry" or path
        Edges always kept: the odometry chain, or a file of pose-id pairs ``i j``.
    certify : bool
        Also run the relaxation for an upper bound (greedy, random, naive).
    max_iter : int, optional
        Frank-Wolfe iterations (default 100; 20 for fiedler).
    tol : float
        Stop Frank-Wolfe when the duality gap is below ``tol`` x (bound - base value); in (0, 1].
    lazy, jl, exact : bool
        Lazy greedy; random-projection gains seeding it (implies ``lazy``); never random
        projections (``jl`` and ``exact`` exclude each other).
    estimate : "solve", "vertices", path, SolveResult or Estimate
        ``objective="fim"``: where the poses come from.
    seed : int
        Seed of random, Madow rounding and random projections (>= 0).
    out : str or os.PathLike, optional
        Write the pruned graph (fixed + selected edges, every vertex) as g2o.
    anchor : int, optional
        The anchored pose id; default the smallest id.
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.

    Returns
    -------
    SelectResult
        The selected edges (pose ids and file positions), the objective's values and the
        certificate.

    Raises
    ------
    ArgumentError
        An argument out of range (``tol=nan``), an anchor that is not a pose id.
    UsageError
        A budget larger than the candidates or malformed.

    Examples
    --------
    >>> import posecrb
    >>> s = posecrb.select("intel", budget="1%", method="naive", certify=True)
    >>> s.budget, s.method, s.upper_bound >= s.value
    (7, 'naive', True)
    """
    from ..selection.budget import FIXED_RULES  # noqa: PLC0415 -- lazy: start-up time
    from ..selection.objectives import OBJECTIVES  # noqa: PLC0415 -- lazy: start-up time
    from ..selection.select import METHODS, select_edges, write_pruned  # noqa: PLC0415 -- lazy: start-up time
    from .results import selection_from_driver  # noqa: PLC0415 -- lazy: start-up time

    if isinstance(budget, bool) or not isinstance(budget, (int, str)):
        raise ArgumentError("budget", budget, "is not a number of edges K (int) or a percentage 'P%' (str)")
    arg.choice("objective", objective, OBJECTIVES)
    arg.choice("method", method, METHODS)
    fixed_rule = arg.path_or_none("fixed", fixed) or "odometry"
    certify = arg.flag("certify", certify)
    max_iter = None if max_iter is None else arg.integer("max_iter", max_iter, 1, 100000)
    tol = arg.finite("tol", tol, 0.0, 1.0, low_open=True)
    lazy, jl, exact = arg.flag("lazy", lazy), arg.flag("jl", jl), arg.flag("exact", exact)
    if jl and exact:
        raise ArgumentError("exact", exact, "excludes jl=True (random projections)")
    seed = arg.integer("seed", seed, 0)
    ids = _one_anchor(anchor)
    target = None
    if out is not None:
        inputs = () if isinstance(source, PoseGraph) else (arg.resolve_source(source, data_dir),)
        extra = () if fixed_rule in FIXED_RULES else (fixed_rule,)
        target = check_output_argument("out", out, inputs + extra, extensions=GRAPH_EXTENSIONS)
    graph, _ = arg.load_graph(source, data_dir)
    idx = graph.anchor_index(ids[0] if ids else None)
    reference = None
    spec = "solve"
    if arg.is_pose_object(estimate):
        reference = arg.resolve_estimate(graph, estimate) if objective == "fim" else None
    else:
        spec = arg.estimate_spec(estimate)
    res = select_edges(graph, budget, objective=objective, method=method, fixed=fixed_rule, certify=certify,
                       seed=seed, anchor=idx, estimate=spec, reference=reference,
                       gains="jl" if jl else ("exact" if exact else "auto"), max_iter=max_iter, tol=tol,
                       strategy="lazy" if (lazy or jl) else "auto")
    if target is not None:
        write_pruned(graph, res, target)
    return selection_from_driver(res.to_dict(), target)


# ---- helpers ----------------------------------------------------------------------------
def _one_anchor(anchor: Any) -> tuple[int, ...]:
    ids = arg.anchor_ids(anchor)
    if len(ids) > 1:
        raise ArgumentError("anchor", anchor, "is several pose ids; this call takes one")
    return ids


def _model_settings(model: str, fim_variant: str | None, frame: str | None) -> tuple[str, str]:
    """(fim_variant, frame) of ``model``: ``fim_variant`` applies to the paper model (default
    ``"consistent"``), ``frame`` to the sed model (default ``"world"``; the paper model's is
    ``"mixed"``)."""
    if fim_variant is not None and model != "paper":
        raise ArgumentError("fim_variant", fim_variant, "applies to the paper model (model='paper')")
    if frame is not None and model != "sed":
        raise ArgumentError("frame", frame, "applies to the sed model (the paper model's coordinates are "
                            "translation in the world frame, rotation in the body frame)")
    from ..models.paper.fim import FIM_VARIANTS  # noqa: PLC0415 -- lazy: start-up time

    variant = "consistent" if fim_variant is None else arg.choice("fim_variant", fim_variant, FIM_VARIANTS)
    if model != "sed":
        return variant, "mixed"
    return variant, "world" if frame is None else arg.choice("frame", frame, FRAMES)


def _npz(path: str | os.PathLike[str]) -> str | os.PathLike[str]:
    """``save``'s target: ``.npz`` appended unless present (numpy's rule)."""
    if isinstance(path, (str, os.PathLike)) and os.fspath(path) and not os.fspath(path).endswith(".npz"):
        return os.fspath(path) + ".npz"
    return path
