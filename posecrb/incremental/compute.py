"""The information timeline: lb, ub, T-optimality and the FIM log-det of every prefix of a pose
graph, computed incrementally (paper section VII; docs/design.md#timeline).

Step t (t = 1..n-1) is the graph on the t + 1 poses with the smallest ids and the edges among
them, anchored at pose 0 (the smallest id), with the quantities ``posecrb bounds`` reports:
``lb = d logdet(L_tau) + d_r logdet(L_w)`` (eq. 75 left), ``ub = d logdet(L_tau) +
logdet(L_w (x) I_dr + blkdiag(Psi))`` (eq. 75 middle with eq. 71), ``t_opt_graph`` (eq. 73) and
the FIM log-det at an estimate (eq. 42 / 64, the estimate restricted to the prefix).

**The full-size matrices.** Each matrix is kept at the size of the whole graph. Besides the
prefix's edges it holds every *bridge* still to come (``posecrb.incremental.schedule``): the future
poses then hang off the prefix as trees, each joined to it by one edge. Eliminating such a tree
leaf by leaf leaves the prefix's matrix unchanged and multiplies the determinant by a closed form
per edge, because the edge's Jacobian in its newer pose is invertible with determinant +-1:
``tau`` (L_tau), ``w`` (L_w), ``w^d_r`` (the ub matrix, whose Psi terms enter with their edge)
and ``tau^d w^d_r`` (the FIM). So

    logdet(prefix after step t) = logdet(full-size matrix after step t) - sum of the closed forms
                                  of the bridges after step t,

and the prefix's value never needs a factorization of its own. The matrix grows only by the
loop closures (and the ub matrix by every edge's Psi): positive semidefinite low-rank terms,
applied as rank-one updates of one fixed-pattern factor whose log-det increments are the matrix
determinant lemma (``posecrb.incremental.tracker``, ``posecrb.incremental._kernels``); a step without
loop closures costs nothing beyond its closed form, for all steps at once. Components of the whole
graph other than pose 0's are joined to pose 0 by a virtual unit edge (never added, closed form
log 1 = 0), so the matrices stay positive definite; prefixes that are disconnected have no value.

**Gains.** A loop closure's gain is its sequential increase of lb: ``d log(1 + tau r_tau) + d_r
log(1 + w r_w)``, with ``r`` its effective resistance in the graph just before it (the prefix of
its step with its attaching edge and the loop closures before it in file order). A step's gain is
the sum over its loop closures: the increase of lb beyond what the new pose's own edge brings.
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from ..core.choices import ESTIMATE_SOURCES_OR_NONE
from ..core.errors import ArgumentError, UsageError
from ..core.graph import PoseGraph
from ..core.noise import rotation_weights
from ..core.status import OK, Status, worst
from ..models.inputs import input_files
from .parts import ClosureTable, TimelineRows, monotonicity
from .result import TimelineResult
from .schedule import Schedule, schedule
from .tracker import Family, Group, Parts, Tracked

if TYPE_CHECKING:
    from ..solver.estimate import Estimate

ESTIMATES = ESTIMATE_SOURCES_OR_NONE
# Keys of ``TimelineResult.checks``: the matrices tracked.
_CHECK_NAMES = {"tau": "L_tau", "w": "L_w", "ub": "ub", "fim": "fim"}
_SQRT_HALF = np.sqrt(0.5)


# ---------------------------------------------------------------------------- families
def _enter(sch: Schedule) -> tuple[np.ndarray, np.ndarray]:
    """Per edge: the step at which its Laplacian/FIM term enters (-1 for bridges: present from the
    start) and its processing rank."""
    rank = np.empty(sch.order.size, dtype=np.int64)
    rank[sch.order] = np.arange(sch.order.size)
    return np.where(sch.bridge, -1, sch.step), rank


def _closed(sch: Schedule, values: np.ndarray) -> np.ndarray:
    """(n,) per step: the sum of ``values`` over the bridges of that step."""
    return np.bincount(sch.step[sch.bridge], weights=values[sch.bridge], minlength=sch.n)


def _virtual(sch: Schedule, k: int) -> Parts:
    """Unit terms ``I_k`` on the rows of every root of another component (``Schedule.roots``)."""
    r = sch.roots.size
    rows = (sch.roots[:, None] - 1) * k + np.arange(k)[None, :]
    return Parts(rows=rows, U=np.broadcast_to(np.eye(k), (r, k, k)).copy(),
                 enter=np.full(r, -1, dtype=np.int64), rank=np.zeros(r, dtype=np.int64))


def laplacian_family(name: str, graph: PoseGraph, sch: Schedule, weights: np.ndarray, k: int = 1) -> Family:
    """``L (x) I_k`` (reduced at pose 0) with edge weights ``weights``: per edge k terms
    ``sqrt(w) (e_i - e_j) (x) e_a``; closed form of a bridge: ``k log w``."""
    enter, rank = _enter(sch)
    ri, rj = graph.src.astype(np.int64) - 1, graph.dst.astype(np.int64) - 1
    a = np.arange(k)
    rows = np.concatenate([np.where(ri[:, None] >= 0, ri[:, None] * k + a, -1),
                           np.where(rj[:, None] >= 0, rj[:, None] * k + a, -1)], axis=1)
    s = np.sqrt(weights)
    u = np.zeros((graph.m, 2 * k, k))
    u[:, a, a] = s[:, None]
    u[:, k + a, a] = -s[:, None]
    parts = [Parts(rows=rows, U=u, enter=enter, rank=rank), _virtual(sch, k)]
    return Family(name, parts, _closed(sch, k * np.log(weights)))


def psi_parts(graph: PoseGraph, sch: Schedule, tau: np.ndarray) -> Parts:
    """Psi of every edge at its source (eq. 41 / 63 with the measured p_ij, eq. 71), entering with
    its edge: 2D ``tau |p|^2``; 3D ``tau/2 (|p|^2 I - p p^T) = sum_k u_k u_k^T`` with
    ``u_k = sqrt(tau/2) |p| b_k``, (b_1, b_2) an orthonormal basis of the plane orthogonal to p."""
    _, rank = _enter(sch)
    rs = graph.src.astype(np.int64) - 1
    p = graph.trans
    sq = np.einsum("ma,ma->m", p, p)
    if graph.dim == 2:
        u = np.sqrt(tau * sq)[:, None, None]
        rows = rs[:, None]
    else:
        norm = np.sqrt(sq)
        unit = np.divide(p, norm[:, None], out=np.zeros_like(p), where=norm[:, None] > 0)
        # b1: the coordinate axis least aligned with p, made orthogonal to it; b2 = unit x b1
        axis = np.eye(3)[np.argmin(np.abs(unit), axis=1)]
        b1 = axis - np.einsum("ma,ma->m", axis, unit)[:, None] * unit
        b1 /= np.linalg.norm(b1, axis=1)[:, None]
        b2 = np.cross(unit, b1)
        u = (np.sqrt(0.5 * tau) * norm)[:, None, None] * np.stack([b1, b2], axis=2)
        rows = np.where(rs[:, None] >= 0, rs[:, None] * 3 + np.arange(3), -1)
    rows = np.where(rs[:, None] >= 0, rows, -1)
    return Parts(rows=rows, U=u, enter=sch.step.astype(np.int64), rank=rank)


def fim_family(graph: PoseGraph, sch: Schedule, tau: np.ndarray, w: np.ndarray, rot: np.ndarray,
               trans: np.ndarray, variant: str) -> Family:
    """The anchored paper FIM at ``(rot, trans)`` (posecrb.models.paper.fim, pose-major: q rows per
    pose, translation first) as per-edge terms ``J^T diag(tau I_d, w I_dr) J``: rows of
    ``sqrt(tau) J_t`` (translation residual, columns x_i, x_j, theta_i) and ``sqrt(w) J_r``
    (rotation, columns theta_i, theta_j: ``[-R_ij^T, I]`` for the consistent variant, ``[-I, I]``
    for eq64 and in 2D). Closed form of a bridge: ``d log tau + d_r log w``."""
    from ..models.paper.fim import rotation_jacobians  # noqa: PLC0415 -- lazy: start-up time

    d, dr, q, m = graph.dim, graph.rot_dim, graph.q, graph.m
    enter, rank = _enter(sch)
    ri, rj = graph.src.astype(np.int64) - 1, graph.dst.astype(np.int64) - 1
    a = np.arange(q)
    rows = np.concatenate([np.where(ri[:, None] >= 0, ri[:, None] * q + a, -1),
                           np.where(rj[:, None] >= 0, rj[:, None] * q + a, -1)], axis=1)
    rit, dmat = rotation_jacobians(graph, rot, trans)
    rit = np.transpose(rit, (0, 2, 1))                                  # R_i^T
    st, sw = np.sqrt(tau)[:, None, None], np.sqrt(w)[:, None, None]
    u = np.zeros((m, 2 * q, q))
    # translation columns: J_t rows -> U columns 0..d-1 (U = J^T sqrt(Omega))
    u[:, 0:d, 0:d] = -np.transpose(rit, (0, 2, 1)) * st                  # x_i: (-R_i^T)^T
    u[:, q:q + d, 0:d] = np.transpose(rit, (0, 2, 1)) * st               # x_j
    u[:, d:q, 0:d] = np.transpose(dmat, (0, 2, 1)) * st                  # theta_i
    eye = np.eye(dr)
    if variant == "consistent" and d == 3:
        rel = np.einsum("mba,mbc->mac", rot[graph.src], rot[graph.dst])   # R_ij = R_i^T R_j
        u[:, d:q, d:q] = -rel * sw                                       # (-R_ij^T)^T
    else:
        u[:, d:q, d:q] = -eye * sw
    u[:, q + d:2 * q, d:q] = eye * sw
    parts = [Parts(rows=rows, U=u, enter=enter, rank=rank), _virtual(sch, q)]
    return Family("paper FIM", parts, _closed(sch, d * np.log(tau) + dr * np.log(w)))


# ---------------------------------------------------------------------------- the timeline
def _resolve_estimate(graph: PoseGraph, estimate: str | Estimate | None) -> Estimate | None:
    if estimate is None or (isinstance(estimate, str) and estimate == "none"):
        return None
    from ..solver.estimate import Estimate, get_estimate  # noqa: PLC0415 -- lazy: the solver

    if isinstance(estimate, Estimate):
        return estimate
    if not isinstance(estimate, str) or not estimate:
        raise UsageError("estimate must be solve, vertices, none, a file or an Estimate")
    return get_estimate(graph, estimate, **({"anchor": 0} if estimate == "solve" else {}))


def _step_range(n: int, start: int | None, stop: int | None, every: int) -> tuple[int, int]:
    """(first, last) step indices from ``start``/``stop`` given as numbers of poses (2..n)."""
    if n < 2:
        raise UsageError(f"a timeline needs at least 2 poses (the graph has {n})")
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise ArgumentError("every", every, "is not a positive integer")
    k0 = 2 if start is None else start
    k1 = n if stop is None else stop
    for name, k in (("start", k0), ("stop", k1)):
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 2 <= k <= n:
            raise ArgumentError(name, k, f"is not a number of poses from 2 to {n}")
    if k0 > k1:
        raise ArgumentError("start", k0, f"is after the last step asked for ({k1} poses)")
    return int(k0) - 1, int(k1) - 1


def timeline(graph: PoseGraph, *, estimate: str | Estimate | None = "solve", every: int = 1,
             start: int | None = None, stop: int | None = None, rotation_weight: str = "eq59",
             fim_variant: str = "consistent") -> TimelineResult:
    """D- and T-optimality of every prefix of ``graph`` as it grows pose by pose (module docstring).

    Parameters
    ----------
    graph : PoseGraph
        The whole graph; poses are added in id order.
    estimate : {"solve", "vertices", "none"}, str path, Estimate or None
        Where the FIM is evaluated: ``"solve"`` (default) the certified optimum of the whole graph
        (the final map, restricted to each prefix), ``"vertices"`` the file's own poses, a path to
        a g2o/TORO file with the same ids, an ``Estimate``, or ``"none"``/None for graph-only rows.
    every : int
        Keep every ``every``-th row from ``start`` on, and the last one (the computation still
        steps through all).
    start, stop : int, optional
        The range, in numbers of poses (2..n); default the whole graph.
    rotation_weight : {"eq59", "table2"}
        3D rotation weight, as for ``posecrb bounds``.
    fim_variant : {"consistent", "eq64"}
        The FIM's rotation Laplacian (posecrb.models.paper.fim); the same in 2D.

    Returns
    -------
    TimelineResult
        One row per kept step, the monotonicity of every metric, each loop closure's gain.

    Raises
    ------
    UsageError
        A bad range, ``every`` or estimate name, or fewer than 2 poses.
    SolverError, ParseError
        From the estimate (an uncertified solve is reported, not raised: see ``estimate``).

    Examples
    --------
    >>> from posecrb.sim.generators import grid
    >>> res = timeline(grid(2, 3), estimate="none")          # a 3 x 3 grid walked row by row
    >>> res.poses.tolist()
    [2, 3, 4, 5, 6, 7, 8, 9]
    >>> res.loop_closures.tolist()                           # the second and third rows close loops
    [0, 0, 0, 1, 1, 0, 1, 1]
    >>> [(c.pose, c.source, round(c.gain, 3)) for c in res.top_closures(2)]
    [(4, 1, 4.159), (5, 0, 3.965)]
    """
    from ..models.paper.fim import FIM_VARIANTS  # noqa: PLC0415 -- lazy: start-up time

    t0 = time.perf_counter()
    if fim_variant not in FIM_VARIANTS:
        raise UsageError(f"fim_variant must be one of {FIM_VARIANTS}, got {fim_variant!r}")
    first, last = _step_range(graph.n, start, stop, every)
    tau = graph.tau
    w = rotation_weights(graph.kappa, graph.dim, rotation_weight)
    est = _resolve_estimate(graph, estimate)
    t_est = time.perf_counter() - t0
    sch = schedule(graph)
    d, dr, n = graph.dim, graph.rot_dim, graph.n

    # L_w = c L_tau when every edge has the same ratio w / tau (uniform noise, as in city10000 and
    # the synthetic grids): then logdet L_w = (t) log c + logdet L_tau after step t (t free poses)
    # and the increments agree, so L_w is not tracked.
    ratio = w / tau
    proportional = bool(np.all(np.abs(ratio - ratio[0]) <= 4.0 * np.finfo(float).eps * ratio[0]))
    fam_tau = laplacian_family("reduced translation Laplacian L_tau", graph, sch, tau)
    lap_ub = laplacian_family("L_w (x) I + blkdiag(Psi)", graph, sch, w, dr)
    fam_ub = Family(lap_ub.name, [*lap_ub.parts, psi_parts(graph, sch, tau)], lap_ub.closed)
    names = ["tau"] + ([] if proportional else ["w"])
    scalar = [fam_tau] + ([] if proportional else [laplacian_family("reduced rotation Laplacian L_w", graph, sch, w)])
    if d == 2:
        groups = [Group([*scalar, fam_ub], n - 1, np.arange(n - 1), n - 1, n)]
    else:
        groups = [Group(scalar, n - 1, np.arange(n - 1), n - 1, n),
                  Group([fam_ub], dr * (n - 1), np.repeat(np.arange(n - 1), dr), n - 1, n)]
    names.append("ub")
    if est is not None:
        rot, trans = graph.check_estimate(est.rot, est.trans)
        fam_fim = fim_family(graph, sch, tau, w, rot, trans, fim_variant)
        groups.append(Group([fam_fim], graph.q * (n - 1), np.repeat(np.arange(n - 1), graph.q), n - 1, n))
        names.append("fim")
    flat = [t for g in groups for t in g.track(first, last)]
    tracked: dict[str, Tracked] = dict(zip(names, flat, strict=True))
    if proportional:
        t_tau = tracked["tau"]
        tracked["w"] = Tracked(values=t_tau.values + np.log(ratio[0]) * np.arange(n), increments=t_tau.increments,
                               status=t_tau.status, checkpoints=t_tau.checkpoints, max_drift=t_tau.max_drift,
                               tolerance=t_tau.tolerance)

    # ---- rows
    steps = np.arange(first, last + 1)
    keep = steps[((steps - first) % every == 0) | (steps == last)]
    connected = sch.components[keep] == 1
    lb = d * tracked["tau"].values + dr * tracked["w"].values
    ub = d * tracked["tau"].values + tracked["ub"].values
    ends = (graph.src != 0).astype(float) + (graph.dst != 0)
    t_opt = np.cumsum(np.bincount(sch.step, weights=(d * tau + dr * w) * ends, minlength=n))

    # loop closures and gains
    lc = sch.closure_edges
    lc = lc[(sch.step[lc] >= first) & (sch.step[lc] <= last)]
    inc_tau, inc_w = tracked["tau"].increments[0], tracked["w"].increments[0]
    gain_lc = d * inc_tau[lc] + dr * inc_w[lc]
    # the graph just before a loop closure: the previous prefix, the new pose with its attaching
    # edge and the step's earlier loop closures, of which the bridges each join two components
    lc_step = sch.step[lc]
    bridges = sch.bridge[lc].astype(np.int64)
    first_of_step = np.searchsorted(lc_step, lc_step)
    earlier = np.cumsum(bridges) - bridges
    earlier -= earlier[first_of_step]
    before_ok = (sch.components[lc_step - 1] - earlier == 1) & ~sch.bridge[lc]
    gain_step = np.bincount(sch.step[lc], weights=gain_lc, minlength=n)
    gain_ok = np.zeros(n, dtype=bool)
    gain_ok[1:] = sch.components[:-1] == 1

    lines = graph.edge_lines
    table = ClosureTable(poses=sch.step[lc] + 1, pose=graph.ids[sch.step[lc]].astype(np.int64),
                         source=graph.ids[graph.src[lc]].astype(np.int64),
                         target=graph.ids[graph.dst[lc]].astype(np.int64),
                         line=np.full(lc.size, -1, dtype=np.int64) if lines is None else lines[lc].astype(np.int64),
                         gain=np.where(before_ok, gain_lc, np.nan))

    lb_status = worst(tracked["tau"].status, tracked["w"].status)
    ub_status = worst(tracked["tau"].status, tracked["ub"].status)
    fim_vals = tracked["fim"].values if est is not None else None

    all_steps = np.arange(first, last + 1)
    all_conn = sch.components[all_steps] == 1
    mono = monotonicity({"lb": lb[all_steps], "ub": ub[all_steps], "t_opt_graph": t_opt[all_steps],
                         **({"fim_logdet": fim_vals[all_steps]} if fim_vals is not None else {})},
                        all_conn, all_steps + 1, graph.ids[all_steps], graph.q)
    checks = {_CHECK_NAMES[name]: {"checkpoints": len(t.checkpoints) - 1, "max_drift": t.max_drift,
                                   "tolerance": t.tolerance}
              for name, t in tracked.items() if not (proportional and name == "w")}
    fim_status = tracked["fim"].status if est is not None else OK
    if not all_conn.any():    # a range without values is not a clean one
        empty = Status.unavailable(f"every prefix from {first + 1} to {last + 1} poses is disconnected: the range "
                                   "has no values", "start the range where the prefixes are connected")
        lb_status, ub_status, fim_status = empty, empty, empty if est is not None else OK
    rows = TimelineRows(poses=keep + 1, pose=graph.ids[keep].astype(np.int64), edges=sch.edges[keep],
                        loop_closures=sch.closures[keep], components=sch.components[keep],
                        lb=np.where(connected, lb[keep], np.nan), ub=np.where(connected, ub[keep], np.nan),
                        t_opt_graph=np.where(connected, t_opt[keep], np.nan),
                        fim_logdet=None if fim_vals is None else np.where(connected, fim_vals[keep], np.nan),
                        gain=np.where(connected & gain_ok[keep], gain_step[keep], np.nan))
    return TimelineResult(
        dataset=graph.name, path=graph.path, sha256=graph.sha256, dim=d, poses=n, edges=graph.m,
        anchor=int(graph.ids[0]), rotation_weight=rotation_weight,
        fim_variant=fim_variant if est is not None else None, estimate=est,
        every=every, first=first + 1, last=last + 1, rows=rows,
        lb_status=lb_status, ub_status=ub_status, fim_status=fim_status,
        monotonicity=mono, closure_table=table, checks=checks,
        times={"estimate": t_est, "timeline": time.perf_counter() - t0 - t_est},
        inputs=input_files(graph, est),
    )

