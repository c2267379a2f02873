"""``solve``: SE-Sync's certifiably correct maximum-likelihood pose-graph estimator (docs/design.md#solver).

Pipeline (Rosen et al., IJRR 2019, Algorithms 1-2): build the sparse data
(problem.py), chordal initialisation (chordal.py), Riemannian staircase with a
preconditioned truncated-Newton trust region at each rank (trust_region.py,
staircase.py), verification of ``Q - Lambda >= 0`` by sparse Cholesky, rounding
to SO(d)^n and translation recovery (rounding.py).
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ..core.errors import ArgumentError, NotPositiveDefinite, PosecrbError, UsageError
from ..core.graph import PoseGraph
from ..core.result import Result, array_field, optional_field, status_field
from ..core.status import OK, Status
from ..io.rotations import rot_to_quat
from ..linalg.cholesky import Factor
from ..linalg.ordering import threaded_matrix
from ..linalg.threads import cholmod_threads, solver_threads
from .chordal import chordal_rotations
from .poses import checked_poses
from .problem import Problem, RotationBlockFactor
from .rounding import anchor_estimate, recover_translations, round_rotations, se_objective
from .staircase import PRECONDITIONERS, RelaxedModel, escape, verify
from .tangent import TangentSystem
from .trust_region import TROptions, trust_region

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
        ``(C + delta I)^{-1}``), whichever is the base one (``SolverOptions.base_precond``);
        ``adaptive`` (``(Q - Lambda + s I)^{-1}``, refactored at an iterate); ``tangent`` (the
        tangent space's inverse Hessian); ``split`` (after an escape). Empty without a
        preconditioner (``precondition=False``).
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


# On 3D graphs (tangent_precond=None) the first level switches to the tangent space's preconditioner
# after a truncated-CG run of more than this many products: its factorizations cost 2-2.5 times
# M_red's there, which pays only where products are many (parking-garage's first run: 26; the other
# SE-Sync files' stay below 15).
TANGENT_SWITCH_HVPS = 20

# The base preconditioner (SolverOptions.base_precond): "schur", SE-Sync's (Q + delta I)^{-1} through a
# factor of M_red(delta); "rotation", (C + delta I)^{-1} through a factor of the rotation block C alone
# (posecrb.solver.problem.RotationBlockFactor); "auto", the rotation block on the 3D graphs whose
# factorizations are threaded (threaded_matrix: from 10,000 poses, dense separators), where its factor
# takes (3/4)^3 of M_red's flops and truncated CG needed fewer products on three of the four graphs
# measured (3D grid of 21,952 poses: 17 instead of 25) and one more on the fourth (docs/performance.md);
# SE-Sync's elsewhere, where factorizations are cheap and
# the products decide, and the rotation block needed more of them on some graphs (cubicle: 79 instead of 32).
BASE_PRECONDITIONERS = ("auto", "schur", "rotation")

# TROptions fields a caller may set through SolverOptions.trust_region (max_iterations is a
# SolverOptions field of its own).
_TR_TUNING = frozenset(f.name for f in fields(TROptions)) - {"max_iterations"}


@dataclass(frozen=True, kw_only=True)
class SolverOptions:
    """Options of :func:`solve` (docs/design.md#solver); the defaults are SE-Sync's settings.

    ``r0`` / ``rmax``: first (default d + 1) and last rank of the Riemannian staircase (the
    start's zero padding is filled by escapes before the rank grows past r0); ``init``:
    "chordal", "vertices" (the file's own estimate) or an (n, d, d) array of rotations;
    ``anchor``: internal index of the pose put at the identity (default 0); ``max_iterations``:
    trust-region iterations per staircase level; ``certificate_tol``: accept
    lambda_min(Q - Lambda) >= -tol; ``seed``: of the verification's random start (the solver is
    deterministic); ``precondition`` / ``precond_max_cond``: the regularised base preconditioner
    and the cap on its condition number; ``base_precond``: which one (``BASE_PRECONDITIONERS``:
    "schur", SE-Sync's (Q + delta I)^{-1}; "rotation", (C + delta I)^{-1} of the rotation block C
    without the translations' coupling; "auto", the default: "rotation" on 3D graphs of at least
    10,000 poses, "schur" elsewhere, :func:`base_preconditioner_kind`); ``adaptive_precond``: relative shift of
    the (Q - Lambda + s I)^{-1} preconditioner (None: off), refactored when the last truncated-CG
    run needed more than ``refactor_hvps`` Hessian-vector products (None: at every accepted
    iterate); ``tangent_precond``: precondition the first staircase level with the exact inverse
    Hessian on the tangent space (``posecrb.solver.tangent``), refactored at accepted iterates
    (True: from the start; False: never; None, the default: from the start on 2D graphs, where its
    sparse system has as many rows per pose as M_red, and on 3D graphs, where it has half as many
    again, only after a truncated-CG run of more than ``TANGENT_SWITCH_HVPS`` products,
    docs/performance.md); ``split_precond``: after an escape from the first level, precondition
    with that level's factor of K on the in-plane directions and (Q - Lambda + sigma I)^{-1} on the
    new column's (the inverse Hessian at the padded point; False: ``Proj (Q - Lambda + s I)^{-1}
    Proj`` there too); ``trust_region``: other :class:`TROptions` fields (e.g. ``theta``,
    ``decrement_tol``, ``exact_decrement_tol``).
    """

    r0: int | None = None
    rmax: int = 10
    init: str | np.ndarray = "chordal"
    anchor: int | None = None
    max_iterations: int = 500
    certificate_tol: float = 1e-3
    verbose: bool = False
    seed: int = 0
    precondition: bool = True
    precond_max_cond: float = 1e6
    base_precond: str = "auto"
    adaptive_precond: float | None = 1e-10
    refactor_hvps: int | None = 30
    tangent_precond: bool | None = None
    split_precond: bool = True
    trust_region: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_base_precond(self.base_precond)
        unknown = set(self.trust_region) - _TR_TUNING
        if unknown:
            raise UsageError(f"unknown trust-region option(s) {', '.join(sorted(unknown))}; "
                             f"choose from {', '.join(sorted(_TR_TUNING))}")

    @classmethod
    def from_keywords(cls, base: SolverOptions | None = None, **keywords: Any) -> SolverOptions:
        """``base`` (default: the defaults) with ``keywords`` applied: SolverOptions fields by name,
        TROptions fields into ``trust_region``; any other name is a UsageError."""
        base = cls() if base is None else base
        own = {f.name for f in fields(cls)} - {"trust_region"}
        tuning = {k: v for k, v in keywords.items() if k not in own}
        unknown = set(tuning) - _TR_TUNING
        if unknown:
            raise UsageError(f"unknown solver option(s) {', '.join(sorted(unknown))}")
        return replace(base, **{k: v for k, v in keywords.items() if k in own},
                       trust_region={**base.trust_region, **tuning})



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
    large = threaded_matrix(graph.dim, graph.n, "solver")
    with solver_threads(cholmod_threads() if large else 1):
        return _solve(graph, options)


def _solve(graph: PoseGraph, options: SolverOptions) -> SolveResult:
    """Certifiably correct maximum-likelihood estimate of a pose graph (``solve``; the options
    are documented on :class:`SolverOptions`). Raises DisconnectedGraph for a disconnected
    graph, UsageError for bad ranks, anchor or init."""
    t_start = time.perf_counter()
    graph.require_connected()
    d, n = graph.dim, graph.n
    anchor = 0 if options.anchor is None else int(options.anchor)
    if not 0 <= anchor < n:
        raise UsageError(f"anchor index {anchor} out of range 0..{n - 1}")
    r0 = d + 1 if options.r0 is None else int(options.r0)
    rmax, init, certificate_tol = options.rmax, options.init, options.certificate_tol
    if r0 < d or rmax < r0:
        raise UsageError(f"need d <= r0 <= rmax (d={d}, r0={r0}, rmax={rmax})")
    if options.verbose:
        log.setLevel(min(log.level or logging.INFO, logging.INFO))
    rng = np.random.default_rng(options.seed)
    opts = TROptions(max_iterations=options.max_iterations, **options.trust_region)

    # ---- initialisation --------------------------------------------------
    t0 = time.perf_counter()
    problem = Problem.from_graph(graph)
    if isinstance(init, np.ndarray):
        rot0 = np.asarray(init, float)
    elif init == "chordal":
        rot0 = chordal_rotations(problem)
    elif init == "vertices":
        if not graph.has_vertices:
            raise PosecrbError(f"{graph.path}: the file has no VERTEX lines to initialise the solver from")
        rot0 = np.asarray(graph.vertex_rot, float)
    else:
        raise ArgumentError("init", init, "is not 'chordal', 'vertices' or an (n, d, d) array of rotations")
    precond = None
    tangent = None
    delta = 0.0
    base_kind = base_preconditioner_kind(options.base_precond, d, n)
    if options.precondition:
        # Regularised base preconditioner ((Q + delta I)^{-1} or (C + delta I)^{-1}); delta caps the
        # condition number near precond_max_cond (SE-Sync's regularised Cholesky, section 4.3).
        delta = problem.gershgorin_max() / options.precond_max_cond
        if options.tangent_precond or (options.tangent_precond is None and d == 2):
            if options.adaptive_precond is not None:
                tangent = TangentSystem.build(problem)
        if tangent is None:
            precond = _base_preconditioner(problem, delta, base_kind)
    # 3D by default: the tangent system only after a truncated-CG run of more than
    # TANGENT_SWITCH_HVPS products at the first level (docs/performance.md)
    switch = (options.precondition and options.tangent_precond is None and d != 2
              and options.adaptive_precond is not None)
    model = RelaxedModel(problem, precond,
                         None if options.adaptive_precond is None
                         else options.adaptive_precond * problem.gershgorin_max(),
                         refactor_hvps=options.refactor_hvps, tangent=tangent, tangent_fallback_shift=delta,
                         base_factory=(None if tangent is None
                                       else (lambda: _base_preconditioner(problem, delta, base_kind))),
                         tangent_factory=(lambda: TangentSystem.build(problem)) if switch else None,
                         tangent_switch_hvps=TANGENT_SWITCH_HVPS if switch else None,
                         split_escape=options.split_precond)
    model.certificate_tol = certificate_tol
    # The rank-r0 starting point is the rotations padded with r0 - d zero columns. Every step of the
    # trust region acts on the columns linearly or through d x d block products with Z_i, so the
    # padding stays exactly zero: the level is the rank-d problem, computed here at width d (a
    # third fewer right-hand sides in 2D, a quarter in 3D). An escape fills one zero column at a time
    # and raises the rank only once none is left: the rank is max(r0, width).
    Z = np.ascontiguousarray(np.swapaxes(rot0, 1, 2))
    times = {"init": time.perf_counter() - t0, "optimize": 0.0, "verify": 0.0, "round": 0.0}
    rounded: list[tuple[int, int, float, np.ndarray, np.ndarray]] = []   # (level, r, F, rot, trans)

    # ---- Riemannian staircase ---------------------------------------------
    iterations = 0
    state = None
    cert = None
    reason = ""
    r = r0
    level = 1
    while True:
        t0 = time.perf_counter()
        res = trust_region(model, Z, opts, state=state)
        times["optimize"] += time.perf_counter() - t0
        state = res.state
        iterations += res.iterations
        log.info("staircase level %d, r=%d%s: f=%.12g after %d TR iterations (%s), %d HVPs", level, r,
                 _width_note(state.Z, r), state.f, res.iterations, res.status, model.hvps)
        t0 = time.perf_counter()
        try:
            # A preconditioner factored at this point with a shift <= eta already decides the test.
            cert = verify(problem, state, certificate_tol, rng,
                          factor=model.certificate_factor(state, certificate_tol))
        except NotPositiveDefinite as exc:
            times["verify"] += time.perf_counter() - t0
            reason = f"verification failed: {exc}"
            break
        times["verify"] += time.perf_counter() - t0
        log.info("staircase level %d, r=%d: lambda_min(Q - Lambda) = %.3e (%s)", level, r, cert.lambda_min,
                 "certified" if cert.certified else "saddle")
        if cert.certified:
            reason = f"lambda_min(Q - Lambda) = {cert.lambda_min:.3e} >= -{certificate_tol:g} at rank {r}"
            break
        if state.Z.shape[2] >= rmax:
            reason = (f"not certified: lambda_min(Q - Lambda) = {cert.lambda_min:.3e} < -{certificate_tol:g} "
                      f"at the maximum rank rmax = {rmax}")
            break
        # Round this level's point before leaving it: where the relaxation is not exact, the next
        # levels' roundings can be worse than this one (the first level, started from rotations,
        # never leaves SO(d)^n: its point is a local optimum of F itself).
        t0 = time.perf_counter()
        rounded.append((level, r, *_rounded_estimate(problem, state.Z)))
        times["round"] += time.perf_counter() - t0
        # The next level starts near a saddle: rebuild the preconditioner there at once, shifted
        # past the negative curvature just found (RelaxedModel.prepare).
        model.lambda_hint = min(cert.lambda_min, 0.0)
        model.refactor_next = True
        model.saddle_factor = cert.shifted_factor
        t0 = time.perf_counter()
        state = escape(model, state, cert)
        times["optimize"] += time.perf_counter() - t0
        Z = state.Z
        r = max(r0, Z.shape[2])
        level += 1

    # ---- rounding: the final level's, or an earlier level's when that one is lower ----------
    t0 = time.perf_counter()
    rounded.append((level, r, *_rounded_estimate(problem, state.Z)))
    final = rounded[-1]
    best = min(rounded, key=lambda point: point[2])
    if best[2] < final[2]:
        log.info("estimate: the rounding of level %d's point (r=%d), F = %.12g, is below the final level's "
                 "(r=%d), F = %.12g; kept", best[0], best[1], best[2], r, final[2])
    else:
        best = final
    _, _, objective, rot, trans = best
    rot, trans = anchor_estimate(rot, trans, anchor)
    times["round"] += time.perf_counter() - t0
    certified = bool(cert is not None and cert.certified)
    gap = objective - state.f
    gap_status = OK
    if certified and cert is not None:
        shift = model.adaptive_shift
        if (cert.proven_shift is not None and shift is not None and 0.0 <= shift < cert.proven_shift
                and n * d * cert.proven_shift + max(gap, 0.0) >= abs(objective)):
            # The certificate's bound n d s is not below the objective at s = eta: a Cholesky of
            # Q - Lambda + s I at the preconditioner's small shift proves the tighter bound (the
            # M_red preconditioner's last factorization often does so on its own; the tangent one
            # never does).
            t0 = time.perf_counter()
            try:
                problem.factor_full(state.lam, shift, name="certificate matrix Q - Lambda + s I")
                cert.proven_shift = float(shift)
            except NotPositiveDefinite:
                pass
            times["verify"] += time.perf_counter() - t0
    times["total"] = time.perf_counter() - t_start
    if certified and cert is not None:
        if cert.proven_shift is not None:
            _warn_if_certificate_is_vacuous(graph, n * d * cert.proven_shift + max(gap, 0.0),
                                            objective, trans, certificate_tol, cert.proven_shift)
        gap_status = _duality_gap_status(graph, gap, objective, trans)
    return SolveResult(
        dataset=graph.name, dim=d, poses=n, edges=graph.m, anchor=int(graph.ids[anchor]),
        objective=float(objective), relaxation_value=float(state.f), duality_gap=float(gap),
        duality_gap_status=gap_status,
        lambda_min=float(cert.lambda_min) if cert is not None else None, certified=certified, reason=reason,
        rank=r, iterations=iterations, hessian_vector_products=model.hvps,
        preconditioner_solves={name: model.preconditioned[name] for name in PRECONDITIONERS
                               if model.preconditioned[name]},
        quaternions=graph.quaternions, times=times, rot=rot, trans=trans, ids=graph.ids.copy())


def _check_base_precond(name: str) -> None:
    if name not in BASE_PRECONDITIONERS:
        raise UsageError(f"unknown base preconditioner {name!r}; choose from {', '.join(BASE_PRECONDITIONERS)}")


def base_preconditioner_kind(requested: str, dim: int, poses: int) -> str:
    """The base preconditioner ``requested`` (``BASE_PRECONDITIONERS``) stands for on a graph of
    ``poses`` poses in dimension ``dim``: ``auto`` is "rotation" on the 3D graphs whose
    factorizations are threaded (``posecrb.linalg.ordering.threaded_matrix``), "schur" otherwise."""
    _check_base_precond(requested)
    if requested != "auto":
        return requested
    return "rotation" if dim == 3 and threaded_matrix(dim, poses, "solver") else "schur"


def _base_preconditioner(problem: Problem, delta: float, kind: str) -> Factor | RotationBlockFactor:
    """The regularised base preconditioner (``base_preconditioner_kind``): "schur", (Q + delta I)^{-1}
    through a factor of M_red(delta) (SE-Sync's); "rotation", (C + delta I)^{-1} through a factor of
    the rotation block alone."""
    if kind == "rotation":
        log.debug("base preconditioner: the rotation block's (C + %.3e I)^-1", delta)
        return problem.factor_rotation_block(delta, name="preconditioner C + delta I")
    return problem.factor_full(None, delta, name="preconditioner M_red(delta)")


def _width_note(Z: np.ndarray, r: int) -> str:
    width = int(Z.shape[2])
    return "" if width == r else f" (a rank-{width} point: its other columns stay zero)"


def _rounded_estimate(problem: Problem, Z: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(F, rotations, translations) of the rounding of a relaxed point (rounding.py)."""
    rot = round_rotations(Z)
    trans = recover_translations(problem, rot)
    return se_objective(problem, rot, trans), rot, trans


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
