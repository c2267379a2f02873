"""``solve``: SE-Sync's certifiably correct maximum-likelihood pose-graph estimator (docs/design.md#solver).

Pipeline (Rosen et al., IJRR 2019, Algorithms 1-2), one function per stage: the initialisation
(:func:`_initialise`: the sparse data of problem.py, the chordal rotations of chordal.py, the
preconditioners of policy.py), the Riemannian staircase (staircase.py: the trust region of
trust_region.py on the relaxation of relaxed.py at each rank, the certificate of certificate.py),
and the rounding to SO(d)^n with its certificate (:func:`_round_and_certify`, rounding.py).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..core.errors import ArgumentError, NotPositiveDefinite, PosecrbError, UsageError
from ..core.graph import PoseGraph
from ..core.result import Result, array_field, optional_field, status_field
from ..core.status import OK, Status
from ..io.rotations import rot_to_quat
from ..linalg.ordering import threaded_matrix
from ..linalg.threads import cholmod_threads, solver_threads
from .certificate import Certificate
from .chordal import chordal_rotations
from .options import BASE_PRECONDITIONERS, PreconditionerSettings, SolverOptions
from .policy import PreconditionerPolicy, build_policy
from .poses import checked_poses
from .preconditioners import base_preconditioner_kind
from .problem import Problem
from .relaxed import RelaxedProblem
from .rounding import Rounding, anchor_estimate, round_point
from .staircase import StaircaseOutcome, run_staircase, timed_phase
from .trust_region import TROptions

__all__ = ["BASE_PRECONDITIONERS", "PreconditionerSettings", "SolveResult", "SolverOptions",
           "base_preconditioner_kind", "solve"]

log = logging.getLogger("posecrb")


@dataclass(frozen=True, kw_only=True)
class SolveResult(Result):
    """The certified maximum-likelihood estimate of a pose graph: what ``posecrb solve`` prints.

    ``to_dict()`` is the command's ``--format json`` object; the estimate itself (``rot``,
    ``trans``, row k the pose with id ``ids[k]``) is left out of it and kept by ``save``.
    ``to_frame()`` has one row per pose: its id, translation and rotation (2D: ``theta`` in
    radians; 3D: the unit quaternion ``qx, qy, qz, qw`` with ``qw >= 0``), translations in the
    file's length units. Pass the result as ``estimate=`` to ``posecrb.bounds``, ``fim``,
    ``crlb`` or ``select`` to evaluate them there.

    Attributes
    ----------
    dataset : str
        The graph's name (its file name without the extension).
    dim, poses, edges : int
        d (2 or 3), n and m.
    anchor : int
        The pose id put at the identity (rotation I, translation 0).
    objective : float
        SE-Sync's objective ``F = sum kappa ||R_j - R_i R~||_F^2 + tau ||t_j - t_i - R_i t~||^2``
        at the estimate (no factor 1/2): the lowest of the roundings of every staircase level's
        point, so never above the first level's local optimum.
    relaxation_value : float
        The rank-r relaxation's value, a lower bound on the optimum when certified.
    duality_gap : float
        ``objective - relaxation_value``: when certified, the estimate is at most this above the
        global optimum (plus the certificate's ``n d s``, see ``--certificate-tol``).
    duality_gap_status : Status
        A warning when the certified gap is above its rounding level (relative 1e-8): the
        relaxation is not exact on this graph, so the estimate is the best one found, within
        ``duality_gap`` of the optimum, not proven optimal.
    lambda_min : float or None
        lambda_min(Q - Lambda) at the final relaxed point (None when the verification failed).
    certified : bool
        Whether ``lambda_min >= -certificate_tol``: the relaxation is then solved globally, and the
        estimate is a global optimum up to ``duality_gap`` (``duality_gap_status`` says when that
        gap is more than rounding).
    reason : str
        Why it is (or is not) certified.
    rank, iterations, hessian_vector_products : int
        The staircase's last rank, trust-region iterations and Hessian-vector products.
    preconditioner_solves : dict of str to int
        How many times each preconditioner was applied (a solve with its factor: one per
        truncated-CG residual and one per Newton decrement), by name: ``schur`` (SE-Sync's
        ``(Q + delta I)^{-1}`` through a factor of M_red) or ``rotation`` (the rotation block's
        ``(C + delta I)^{-1}``), whichever is the base one (``PreconditionerSettings.base``);
        ``adaptive`` (``(Q - Lambda + s I)^{-1}``, refactored at an iterate); ``tangent`` (the
        tangent space's inverse Hessian); ``split`` (after an escape). Empty without a
        preconditioner (``preconditioner="none"``).
    quaternions : str
        How the file's 3D quaternions were read (``"normalize"``, or ``"raw"`` as SE-Sync).
    saved : str or None
        The g2o file written by ``out=`` (absent from the JSON without it).
    times : dict of str to float
        Seconds: ``parse`` (when the call read the file), ``init``, ``optimize``, ``verify``,
        ``round`` and ``total``.
    rot, trans, ids : numpy.ndarray
        The estimate, (n, d, d) rotations and (n, d) translations, and the pose ids of the rows;
        empty after ``from_dict`` (``load`` keeps them).

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.solve("intel")
    >>> res.certified, res.poses, res.anchor
    (True, 1728, 0)
    >>> round(res.objective, 6)
    52.348227
    >>> res.to_frame().columns.tolist()
    ['id', 'x', 'y', 'theta']
    """

    dataset: str
    dim: int
    poses: int
    edges: int
    anchor: int
    objective: float
    relaxation_value: float
    duality_gap: float
    duality_gap_status: Status = status_field("duality gap")
    lambda_min: float | None
    certified: bool
    reason: str
    rank: int
    iterations: int
    hessian_vector_products: int
    preconditioner_solves: dict[str, int] = field(default_factory=dict)
    quaternions: str = "normalize"
    saved: str | None = optional_field()
    times: dict[str, float] = field(default_factory=dict)
    rot: np.ndarray = array_field()
    trans: np.ndarray = array_field()
    ids: np.ndarray = array_field()

    def __post_init__(self) -> None:
        # the one check of poses entering the library, also when ``load`` reads them from a file
        rot, trans = checked_poses(self.rot, self.trans)
        object.__setattr__(self, "rot", rot)
        object.__setattr__(self, "trans", trans)

    def statuses(self) -> dict[str, Status]:
        """``{"certificate": ..., "duality gap": ...}``: a warning when the estimate is not certified,
        and ``duality_gap_status`` (a warning when certified with a gap above rounding)."""
        cert = OK if self.certified else Status.warning(
            f"the estimate is NOT certified globally optimal ({self.reason})")
        return {"certificate": cert, "duality gap": self.duality_gap_status}

    def to_frame(self) -> Any:
        """One row per pose: ``id``, the translation (``x, y[, z]``) and the rotation (2D
        ``theta``, 3D ``qx, qy, qz, qw``). Raises ``UsageError`` when the estimate is absent
        (a result rebuilt by ``from_dict``; ``load`` keeps it)."""
        import pandas as pd  # noqa: PLC0415 -- lazy: start-up time (pandas only for frames)

        if self.rot.size == 0:
            raise UsageError("this SolveResult carries no estimate (rebuilt from a dict); "
                             "SolveResult.load(path) of a saved result has it")
        cols: dict[str, Any] = {"id": np.asarray(self.ids, dtype=np.int64)}
        for k, name in enumerate("xyz"[: self.dim]):
            cols[name] = self.trans[:, k]
        if self.dim == 2:
            cols["theta"] = np.arctan2(self.rot[:, 1, 0], self.rot[:, 0, 0])
        else:
            q = rot_to_quat(self.rot)
            for k, name in enumerate(("qx", "qy", "qz", "qw")):
                cols[name] = q[:, k]
        return pd.DataFrame(cols)


def solve(graph: PoseGraph, options: SolverOptions | None = None, **keywords: Any) -> SolveResult:
    """Certifiably correct maximum-likelihood estimate of a pose graph (see :func:`_solve`).

    ``solve(graph, SolverOptions(anchor=3, rmax=8))``; the keyword form ``solve(graph, anchor=3)``
    is the same call (``SolverOptions.from_keywords``: an unknown name is a UsageError) and may
    refine ``options``. BLAS runs single-threaded inside: the work is many small dense products
    and triangular solves, for which OpenBLAS's threads cost more than they save. The exception
    is the factorizations of M_red of large graphs (``posecrb.linalg.ordering.threaded_matrix``),
    whose dense separators take CHOLMOD's BLAS threads as they were at the call, on the cores no
    other process keeps busy (posecrb.linalg.threads).
    """
    if keywords or options is None:
        options = SolverOptions.from_keywords(options, **keywords)
    with solver_thread_policy(graph):
        return _solve(graph, options)


def solver_thread_policy(graph: PoseGraph) -> Any:
    """The solver's thread policy for ``graph`` (a context manager): every BLAS at one thread,
    except CHOLMOD's in the factorizations of M_red of large graphs (``solve``). Every caller of the
    solver's linear algebra (the certificate, the refinement) runs inside it: outside it, the
    certificate's Lanczos solves take CHOLMOD's BLAS threads, which make a solve through small
    supernodes several times slower (docs/decisions/blas-threads.md)."""
    large = threaded_matrix(graph.dim, graph.n, "solver")
    return solver_threads(cholmod_threads() if large else 1)


def _solve(graph: PoseGraph, options: SolverOptions) -> SolveResult:
    """Certifiably correct maximum-likelihood estimate of a pose graph (``solve``; the options
    are documented on :class:`SolverOptions`). Raises DisconnectedGraph for a disconnected
    graph, UsageError for bad ranks, anchor or init."""
    t_start = time.perf_counter()
    start = _initialise(graph, options)
    outcome = run_staircase(start.relaxed, start.policy, start.Z, r0=start.r0, rmax=options.rmax,
                            certificate_tol=options.certificate_tol, rng=start.rng, options=start.tr_options,
                            times=start.times)
    return _round_and_certify(graph, start, outcome, options.certificate_tol, t_start)


@dataclass
class _Start:
    """What the staircase starts from: the problem, its relaxation and preconditioners, the rank-r0
    point Z (rotations, at width d), and the settings the later stages need."""

    problem: Problem
    relaxed: RelaxedProblem
    policy: PreconditionerPolicy
    Z: np.ndarray
    r0: int
    anchor: int
    small_shift: float | None      # the adaptive preconditioner's shift s (absolute), or None
    rng: np.random.Generator
    tr_options: TROptions
    times: dict[str, float] = field(default_factory=dict)


def _initialise(graph: PoseGraph, options: SolverOptions) -> _Start:
    """Check the ranks and anchor, build the problem, the initial rotations and the preconditioners
    (timed as ``init``)."""
    graph.require_connected()
    d, n = graph.dim, graph.n
    anchor = 0 if options.anchor is None else int(options.anchor)
    if not 0 <= anchor < n:
        raise UsageError(f"anchor index {anchor} out of range 0..{n - 1}")
    r0 = d + 1 if options.r0 is None else int(options.r0)
    if r0 < d or options.rmax < r0:
        raise UsageError(f"need d <= r0 <= rmax (d={d}, r0={r0}, rmax={options.rmax})")
    if options.verbose:
        log.setLevel(min(log.level or logging.INFO, logging.INFO))
    tr_options = TROptions(max_iterations=options.max_iterations, **options.trust_region)
    times = {"init": 0.0, "optimize": 0.0, "verify": 0.0, "round": 0.0}
    with timed_phase(times, "init"):
        problem = Problem.from_graph(graph)
        rot0 = _initial_rotations(graph, problem, options.init)
        settings = options.preconditioner_settings
        policy = build_policy(problem, options.preconditioner, settings, options.certificate_tol)
        # The rank-r0 starting point is the rotations padded with r0 - d zero columns. Every step of
        # the trust region acts on the columns linearly or through d x d block products with Z_i, so
        # the padding stays exactly zero: the level is the rank-d problem, computed here at width d
        # (a third fewer right-hand sides in 2D, a quarter in 3D). An escape fills one zero column at
        # a time and raises the rank only once none is left: the rank is max(r0, width).
        Z = np.ascontiguousarray(np.swapaxes(rot0, 1, 2))
    small_shift = None if settings.adaptive_shift is None else settings.adaptive_shift * problem.gershgorin_max()
    return _Start(problem, RelaxedProblem(problem), policy, Z, r0, anchor, small_shift,
                  np.random.default_rng(options.seed), tr_options, times)


def _initial_rotations(graph: PoseGraph, problem: Problem, init: str | np.ndarray) -> np.ndarray:
    """(n, d, d) rotations to start from: ``init`` as an array, the chordal relaxation's, or the
    file's vertices."""
    if isinstance(init, np.ndarray):
        return np.asarray(init, float)
    if init == "chordal":
        return chordal_rotations(problem)
    if init == "vertices":
        if not graph.has_vertices:
            raise PosecrbError(f"{graph.path}: the file has no VERTEX lines to initialise the solver from")
        return np.asarray(graph.vertex_rot, float)
    raise ArgumentError("init", init, "is not 'chordal', 'vertices' or an (n, d, d) array of rotations")


def _round_and_certify(graph: PoseGraph, start: _Start, outcome: StaircaseOutcome, certificate_tol: float,
                       t_start: float) -> SolveResult:
    """The estimate (the lowest rounding of the levels' points, anchored), its certificate, duality
    gap and statuses."""
    problem, times, state = start.problem, start.times, outcome.state
    n, d = problem.n, problem.d
    with timed_phase(times, "round"):
        best = _best_rounding(outcome.saddle_roundings, round_point(problem, state.Z, outcome.level, outcome.rank))
        rot, trans = anchor_estimate(best.rot, best.trans, start.anchor)
    objective = best.objective
    cert = outcome.certificate
    certified = bool(cert is not None and cert.certified)
    gap = objective - state.f
    gap_status = OK
    if certified and cert is not None:
        with timed_phase(times, "verify"):
            cert = _prove_at_small_shift(problem, state.lam, cert, start.small_shift, n * d, objective, gap)
    times["total"] = time.perf_counter() - t_start
    if certified and cert is not None:
        if cert.proven_shift is not None:
            _warn_if_certificate_is_vacuous(graph, n * d * cert.proven_shift + max(gap, 0.0),
                                            objective, trans, certificate_tol, cert.proven_shift)
        gap_status = _duality_gap_status(graph, gap, objective, trans)
    return SolveResult(
        dataset=graph.name, dim=d, poses=n, edges=graph.m, anchor=int(graph.ids[start.anchor]),
        objective=float(objective), relaxation_value=float(state.f), duality_gap=float(gap),
        duality_gap_status=gap_status,
        lambda_min=float(cert.lambda_min) if cert is not None else None, certified=certified,
        reason=outcome.reason, rank=outcome.rank, iterations=outcome.iterations,
        hessian_vector_products=outcome.hessian_vector_products, preconditioner_solves=start.policy.solves(),
        quaternions=graph.quaternions, times=times, rot=rot, trans=trans, ids=graph.ids.copy())


def _best_rounding(saddles: list[Rounding], final: Rounding) -> Rounding:
    """The final level's rounding, or an earlier level's where that one is lower (where the
    relaxation is not exact, the last level's rounding can be worse)."""
    best = min([*saddles, final], key=lambda point: point.objective)
    if best.objective < final.objective:
        log.info("estimate: the rounding of level %d's point (r=%d), F = %.12g, is below the final level's "
                 "(r=%d), F = %.12g; kept", best.level, best.rank, best.objective, final.rank, final.objective)
        return best
    return final


def _prove_at_small_shift(problem: Problem, lam: np.ndarray, cert: Certificate, shift: float | None, nd: int,
                          objective: float, gap: float) -> Certificate:
    """``cert`` with the tighter bound ``n d s`` proven at the preconditioner's small shift s where
    its bound ``n d s'`` (s' the certifying Cholesky's shift) is not below the objective: one more
    Cholesky of ``Q - Lambda + s I`` (the adaptive factor often proves it on its own; the tangent
    one never does)."""
    proven = cert.proven_shift
    if (proven is None or shift is None or not 0.0 <= shift < proven
            or nd * proven + max(gap, 0.0) < abs(objective)):
        return cert
    try:
        problem.factor_full(lam, shift, name="certificate matrix Q - Lambda + s I")
    except NotPositiveDefinite:
        return cert
    return replace(cert, proven_shift=float(shift))


# A certified duality gap above this fraction of the objective is more than the solver's own
# accuracy: the trust region stops once a step lowers f by at most 1e-9 relatively (certified) or
# at a Newton decrement of 1e-11 (TROptions), past its quadratic phase, and the objective, a sum of
# m positive terms, carries a relative rounding error below m eps (2e-9 at 10^7 edges). Where the
# relaxation is exact the gap stays at that level (at most 2e-15 relative on the shared datasets).
EXACT_GAP_RTOL = 1e-8


def _rounding_level(graph: PoseGraph, trans: np.ndarray) -> float:
    """The objective of residuals that are rounding errors: 64 ulps of the largest coordinate
    per unit of information (tau, kappa) on every edge."""
    weight = float(np.sum(graph.tau) + np.sum(graph.kappa))
    ulps = 64.0 * np.finfo(float).eps * (1.0 + float(np.max(np.abs(trans), initial=0.0)))
    return weight * ulps * ulps


def _duality_gap_status(graph: PoseGraph, gap: float, objective: float, trans: np.ndarray) -> Status:
    """A warning when a certified gap exceeds ``EXACT_GAP_RTOL`` of the objective plus its rounding level."""
    if gap <= EXACT_GAP_RTOL * abs(objective) + _rounding_level(graph, trans):
        return OK
    return Status.warning(
        f"the relaxation is not exact on this graph: the estimate's objective is {gap:.3g} "
        f"({gap / abs(objective):.1e} relative) above the certified lower bound, so it is the best estimate "
        "found, within that of the global optimum, not proven optimal",
        hint="SE-Sync's relaxation is exact only below a graph-dependent noise level; the estimate is "
             "the lowest rounding of the staircase's levels")


def _warn_if_certificate_is_vacuous(graph: PoseGraph, bound: float, objective: float, trans: np.ndarray,
                                    certificate_tol: float, shift: float) -> None:
    """Warn where a certificate proves nothing about optimality.

    A successful Cholesky of Q - Lambda + s I proves lambda_min > -s, hence
    ``F* >= f - n d s - gap`` (module docstring of staircase.py); the objective is a sum of squares,
    so ``F* >= 0`` holds anyway. Where ``bound = n d s + gap`` reaches the objective the certificate
    adds nothing to that, which only a tolerance far above the default (or information scaled far
    down) brings about. Exception: an objective at its own rounding level (exact measurements, whose
    residuals are rounding errors of the positions) is optimal by ``F* >= 0`` itself.
    """
    if bound < abs(objective) or objective <= _rounding_level(graph, trans):
        return
    log.warning("%s: certified at tolerance %g, but the suboptimality bound it proves, n d s + gap = %.3g "
                "(s = %.3g, the shift of the certifying factorization), is not below the objective %.6g: "
                "the estimate is not shown to be optimal (a smaller tolerance: posecrb solve "
                "--certificate-tol, default 1e-3)", graph.name, certificate_tol, bound, shift, objective)
