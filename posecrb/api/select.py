"""``posecrb.select``: measurement selection with a certificate (``posecrb.selection``)."""
from __future__ import annotations

import numbers
import os
from typing import TYPE_CHECKING

from ..core.arguments import choice, flag
from ..core.choices import FIXED_RULES, GAIN_MODES, GAINS, METHODS, OBJECTIVES, FixedRule, Gains, Method, Objective
from ..core.errors import ArgumentError
from . import arguments as arg
from .arguments import EstimateSpec, Source, public

if TYPE_CHECKING:
    from ..selection.result import SelectResult

_GAINS_NOW = "use gains='lazy' (lazy), 'jl' (jl, or lazy and jl), 'lazy-exact' (lazy and exact) or 'auto' (exact alone)"


@public(out="write the pruned graph with posecrb.io.write_g2o(res.pruned_graph(graph), path)", lazy=_GAINS_NOW,
        jl=_GAINS_NOW, exact=_GAINS_NOW)
def select(source: Source, *, budget: int | float, objective: Objective = "tree", method: Method = "greedy",
           fixed: FixedRule | str | os.PathLike[str] = "odometry", certify: bool = False, max_iter: int | None = None,
           tol: float = 1e-3, gains: Gains = "auto", estimate: EstimateSpec = "solve", seed: int = 0,
           anchor: int | None = None, data_dir: str | os.PathLike[str] | None = None) -> SelectResult:
    """Measurement selection: keep ``budget`` candidate edges maximising a D-optimality
    objective, with an upper bound on the best choice (a certificate).

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    budget : int or float
        Number K of candidate edges to keep (an integer), or a fraction of the candidates in
        (0, 1] (a float, rounded down: ``0.2`` is the command line's ``--budget 20%``).
    objective : {"tree", "fim", "fiedler"}
        ``"tree"``: ``d logdet L_tau + d_r logdet L_w`` (eq. 75); ``"fim"``: log-det of the
        anchored paper FIM at ``estimate``; ``"fiedler"``: algebraic connectivity of the
        rotation-weighted Laplacian.
    method : {"greedy", "relax", "random", "naive"}
        The greedy (see ``gains``), Frank-Wolfe on the convex relaxation with rounding, seeded
        random, or the heaviest rotation weights.
    fixed : "odometry" or path
        Edges always kept: the odometry chain, or a file of pose-id pairs ``i j``.
    certify : bool
        Also run the relaxation for an upper bound (greedy, random, naive).
    max_iter : int, optional
        Frank-Wolfe iterations (default 100; 20 for fiedler).
    tol : float
        Stop Frank-Wolfe when the duality gap is below ``tol`` x (bound - base value); in (0, 1].
    gains : {"auto", "exact", "rounds", "lazy", "lazy-exact", "jl"}
        How the log-det greedy evaluates gains: ``"auto"``, every gain exact at every step (the
        incremental greedy), and for more than 4096 steps on graphs of 20,000 poses or more the
        round greedy (exact gains and Minoux's bound once per round, each choice's effect on the
        others within a round from a local solve; ``stats.strategy`` says which ran, the
        certificate is a proven bound either way); ``"exact"``, the incremental greedy whatever the
        size; ``"rounds"``, the round greedy; the lazy greedy's priority queue (``"lazy"``: its
        first gains by random projections above 50,000 candidates; ``"lazy-exact"``: never random
        projections; ``"jl"``: always seeded by random projections). The command line's
        ``--gains``.
    estimate : "solve", "vertices", path, SolveResult or Estimate
        ``objective="fim"``: where the poses come from.
    seed : int
        Seed of random, Madow rounding and random projections (>= 0).
    anchor : int, optional
        The anchored pose id; default the smallest id.
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.

    Returns
    -------
    SelectResult
        The selected edges (pose ids and file positions), the objective's values and the
        certificate; ``res.pruned_graph(graph)`` is the graph of the fixed and the selected edges.

    Raises
    ------
    ArgumentError
        An argument out of range (``tol=nan``), a budget that is not a number of edges or a
        fraction, or larger than the candidates, an anchor that is not a pose id.

    Examples
    --------
    >>> import posecrb
    >>> s = posecrb.select("intel", budget=0.01, method="naive", certify=True)
    >>> s.budget, s.budget_spec, s.method, s.upper_bound >= s.value
    (7, '1%', 'naive', True)
    """
    from ..selection.select import select_edges  # noqa: PLC0415 -- lazy: start-up time

    if isinstance(budget, str):
        raise ArgumentError("budget", budget, "is text: pass a number of edges K (an int) or a fraction of the "
                            "candidates in (0, 1] (a float; the command line's 20% is 0.2)")
    if isinstance(budget, bool) or not isinstance(budget, numbers.Real):
        raise ArgumentError("budget", budget, "is not a number of edges K (an int) or a fraction of the candidates "
                            "in (0, 1] (a float)")
    choice("objective", objective, OBJECTIVES)
    choice("method", method, METHODS)
    fixed_rule = arg.path_or_none("fixed", fixed) or FIXED_RULES[0]
    certify = flag("certify", certify)
    max_iter = None if max_iter is None else arg.integer("max_iter", max_iter, 1, 100000)
    tol = arg.finite("tol", tol, 0.0, 1.0, low_open=True)
    strategy, mode = GAIN_MODES[choice("gains", gains, GAINS)]
    seed = arg.integer("seed", seed, 0)
    ids = arg.one_anchor(anchor)
    graph, _ = arg.load_graph(source, data_dir)
    idx = graph.anchor_index(ids[0] if ids else None)
    reference = None
    spec = "solve"
    if arg.is_pose_object(estimate):
        reference = arg.resolve_estimate(graph, estimate) if objective == "fim" else None
    else:
        spec = arg.estimate_spec(estimate)
    return select_edges(graph, budget, objective=objective, method=method, fixed=fixed_rule, certify=certify,
                        seed=seed, anchor=idx, estimate=spec, reference=reference, gains=mode, max_iter=max_iter,
                        tol=tol, strategy=strategy)
