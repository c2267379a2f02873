"""Graph-only bounds on the D-optimality metric and T-optimality (paper sections VII-A, VII-B).

With d = 2|3, d_r = 1|3 and the reduced weighted Laplacians L_tau (translation
weights tau) and L_w (rotation weights w, docs/design.md#noise-model):

* ``lb = d logdet(L_tau) + d_r logdet(L_w)`` (eq. 75 left, Algorithm 1: one
  fill-reducing ordering shared by both factorizations);
* ``ub = d logdet(L_tau) + logdet(L_w (x) I_dr + blkdiag(Psi_i))`` (eq. 75 middle
  with eq. 71: the measured p_ij replace x_j - x_i; the paper's Table I "Upper bound");
* ``ub_lambda = d logdet(L_tau) + d_r logdet(L_w + lambda_inf I)`` (eq. 75 right,
  eq. 77), one more factorization with the same ordering;
* Lemma 4: ``0 <= logdet F - lb <= d_r n_p log(1 + xi / lambda_min(L_w))``, evaluated with a
  certified lower bound of ``lambda_min(L_w)`` (``rotation_lambda_min``) so that it stays an
  upper bound of the gap whatever the rounding; when ``lambda_min(L_w)`` is below what double
  precision resolves, ``lambda_min_rot`` is unavailable (a ``Status``, never a negative number)
  and the gap uses the graph lower bound ``lambda_min >= 1 / sum_i R_T(anchor, i)`` (tree
  resistances, ``tree_lambda_min_bound``), with a warning;
* T-optimality: graph-only eq. (73) and eq. (72) with p_ij; total node degree
  ``sum_{i != anchor} |V_i|`` (the paper's sum over i = 1..n_p).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...core.errors import NotPositiveDefinite
from ...core.graph import PoseGraph
from ...core.noise import rotation_weights
from ...core.result import Result, internal_field, status_field
from ...core.status import OK, Status
from ...core.timing import Repeat, measure
from ...linalg.cholesky import Factor, SymbolicCholesky
from ...linalg.lanczos import largest_eigenpair
from ...linalg.laplacian import kron_identity, reduced_index, reduced_laplacian
from ...linalg.ordering import ordered_symbolic
from ...linalg.threads import python_blas

# lambda_min(L_w) is reported with a warning when its certified interval is wider than this
# (relative to the estimate).
LAMBDA_INTERVAL_WARN = 1e-3
# Rounding level of the sparse products and of the Cholesky check, in units of
# eps ||L_w||_1 per stored entry of a column (a bound with a margin of 4).
_ROUNDING_MARGIN = 4.0
# tree_bound_may_exceed's relative margin: far above the rounding of the tree's path sums and of
# the trace's lower bound (a few hundred ulps at most), far below any gap between the two bounds
_TREE_MARGIN = 1e-6


@dataclass(frozen=True)
class WeightedLaplacians:
    """Reduced weighted Laplacians of the translation and rotation graphs (same pattern)."""
    anchor: int
    l_tau: sp.csc_matrix
    l_w: sp.csc_matrix
    tau: np.ndarray
    w: np.ndarray


def weighted_laplacians(graph: PoseGraph, anchor: int = 0, rotation_weight: str = "eq59") -> WeightedLaplacians:
    """Build L_tau and L_w from the information matrices (weights computed here, vectorised)."""
    # the graph's cached precisions and eq. 59's weights (in 3D an evaluation takes Bessel functions)
    tau, kappa = graph.tau, graph.kappa
    w = graph.rotation_weights if rotation_weight == "eq59" else rotation_weights(kappa, graph.dim, rotation_weight)
    l_tau = reduced_laplacian(graph.n, graph.src, graph.dst, tau, anchor)
    l_w = reduced_laplacian(graph.n, graph.src, graph.dst, w, anchor)
    return WeightedLaplacians(anchor, l_tau, l_w, tau, w)


def source_terms(graph: PoseGraph, tau: np.ndarray, anchor: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Per non-anchor pose i (reduced order): Psi_i (n-1, d_r, d_r) and xi_i (n-1,).

    Sums run over the edges whose SOURCE is i (eq. 41, 63, Appendix D), with the
    measured p_ij in place of R_i^T (x_j - x_i) (eq. 71). 2D: ``psi_i = sum tau ||p||^2``,
    ``xi_i = psi_i``; 3D: ``Psi_i = sum tau/2 (||p||^2 I - p p^T)``, ``xi_i = sum tau/2 ||p||^2`` (eq. 76-77).
    """
    red = reduced_index(graph.n, anchor)[graph.src]
    keep = red >= 0
    p, t, r = graph.trans[keep], tau[keep], red[keep]
    sq = np.einsum("ij,ij->i", p, p)
    n1 = graph.n - 1
    if graph.dim == 2:
        psi = np.bincount(r, weights=t * sq, minlength=n1)
        return psi[:, None, None], psi
    blocks = 0.5 * t[:, None, None] * (sq[:, None, None] * np.eye(3) - p[:, :, None] * p[:, None, :])
    flat = np.stack([np.bincount(r, weights=blocks[:, a, b], minlength=n1)
                     for a in range(3) for b in range(3)], axis=1)
    xi = np.bincount(r, weights=0.5 * t * sq, minlength=n1)
    return flat.reshape(n1, 3, 3), xi


def t_optimality(graph: PoseGraph, anchor: int = 0, rotation_weight: str = "eq59") -> tuple[float, float]:
    """(eq. 73, eq. 72): graph-only T-optimality and its approximation with the measured p_ij.

    ``trace(L_tau (x) I_d) + trace(L_w (x) I_dr)`` over the non-anchor poses, straight from the edge
    arrays (each edge end that is not the anchor contributes ``d tau + d_r w``); eq. (72) adds
    ``sum_{i != anchor} sum_{j in V_i^+} tau_ij ||p_ij||^2`` (``trace(Psi_(i,j))`` in 3D too, Appendix D).
    """
    tau = graph.tau
    w = graph.rotation_weights_by(rotation_weight)
    ends = (graph.src != anchor).astype(float) + (graph.dst != anchor)
    t_graph = float(graph.dim * np.dot(tau, ends) + graph.rot_dim * np.dot(w, ends))
    psi = tau * np.einsum("ma,ma->m", graph.trans, graph.trans) * (graph.src != anchor)
    return t_graph, t_graph + float(psi.sum())


@dataclass(frozen=True)
class EigenEstimate:
    """``lambda_min`` of a reduced Laplacian: ``value`` is the Rayleigh quotient of the computed
    eigenvector (an upper bound of lambda_min, accurate to a few ulps because it is summed edge
    by edge from non-negative terms), ``lower`` a certified lower bound, both None when
    ``status`` is unavailable."""

    value: float | None
    lower: float | None
    status: Status = OK


def tree_lambda_min_bound(n: int, src: np.ndarray, dst: np.ndarray, w: np.ndarray, anchor: int) -> float:
    """Graph lower bound ``lambda_min(L_w) >= 1 / trace(L_w^{-1}) >= 1 / sum_i R_T(anchor, i)``.

    ``trace(L_w^{-1})`` (anchor removed) is the sum of the effective resistances between the
    anchor and every pose (conductances w); by Rayleigh's monotonicity each is at most the
    resistance of the path in a spanning tree T (here the maximum-weight one). Only sums of
    positive numbers: no cancellation, valid at any conditioning. 0.0 when a weight is not
    positive and finite.
    """
    from scipy.sparse.csgraph import minimum_spanning_tree, shortest_path  # noqa: PLC0415 -- lazy: start-up time

    w = np.asarray(w, dtype=float)
    if not (np.all(np.isfinite(w)) and np.all(w > 0)):
        return 0.0
    cond = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([src, dst]), np.concatenate([dst, src]))),
                         shape=(n, n)).tocsr()          # parallel edges: conductances add
    cond.sum_duplicates()
    res = cond.copy()
    with np.errstate(divide="ignore", over="ignore"):
        res.data = 1.0 / res.data
    tree = minimum_spanning_tree(res)
    dist = shortest_path(tree, directed=False, indices=anchor)
    total = float(np.sum(dist[np.arange(n) != anchor]))
    return 1.0 / total if np.isfinite(total) and total > 0 else 0.0


def tree_bound_may_exceed(eig: EigenEstimate, l_w: sp.spmatrix) -> bool:
    """Whether ``tree_lambda_min_bound`` could exceed the certified ``eig.lower``; where it cannot,
    it changes neither the gap bound nor its status, and is not computed (a spanning tree, and
    scipy.sparse.csgraph's import with scipy.linalg's: a large part of a small file's process,
    docs/decisions/fixed-costs.md).

    The tree bound is at most ``1 / trace(L_w^{-1})`` (each tree path's resistance is at least the
    effective resistance, and those sum to the trace), and ``trace(L_w^{-1}) >= 1 / rho + (n - 1) /
    ||L_w||_1`` (``rho = eig.value >= lambda_min``, every other eigenvalue at most ``lambda_max <=
    ||L_w||_1``); the margin covers the rounding of both sides."""
    if eig.lower is None or eig.value is None or not eig.status.available:
        return True
    n = l_w.shape[0]
    norm = float(abs(l_w).sum(axis=0).max())
    if not (np.isfinite(norm) and norm > 0 and eig.value > 0):
        return True
    return 1.0 / (1.0 / eig.value + (n - 1) / norm) > eig.lower * (1.0 - _TREE_MARGIN)


def rotation_lambda_min(lap: WeightedLaplacians, graph: PoseGraph, symbolic: SymbolicCholesky,
                        factor: Factor | None = None, name: str = "reduced rotation Laplacian L_w") -> EigenEstimate:
    """Smallest eigenvalue of the reduced L_w with a certified interval, or a status.

    1. eigenvector of the smallest eigenvalue: dense ``eigh`` up to 200 rows, otherwise
       Lanczos on the inverse (posecrb.linalg.lanczos) applied through the Cholesky ``factor``;
    2. ``rho`` = its Rayleigh quotient summed edge by edge, ``r = ||L v - rho v||``;
       some eigenvalue lies in ``rho -+ (r + delta)``, ``delta`` the rounding level of the
       products (``_ROUNDING_MARGIN`` x eps x ||L_w||_1 x entries per column);
    3. inertia check: the Cholesky factorization of ``L_w - s I`` with ``s = rho - r - 2 delta``
       must succeed (no eigenvalue below s, up to its own backward error ``delta``), so
       ``lower = s - delta`` is a lower bound of lambda_min. When ``lower <= 0`` the eigenvalue is
       below what double precision resolves for this matrix: unavailable, with the reason.
    """
    a = sp.csc_matrix(lap.l_w)
    n = a.shape[0]
    if n == 0:
        return EigenEstimate(None, None, Status.unavailable("L_w is empty (a single pose)"))
    eps = float(np.finfo(float).eps)
    try:
        if n <= 200:
            # numpy's BLAS at one thread: its threads spin against each other on so small a matrix,
            # worst under load (docs/decisions/fixed-costs.md)
            with python_blas().limit(limits=1):
                _, vecs = np.linalg.eigh(a.toarray())
            v = vecs[:, 0]
        else:
            if factor is None:
                factor = symbolic.factor(a, name=name)
            # tol near the rounding level: the interval below is as narrow as the vector is accurate
            ritz = largest_eigenpair(factor, np.ones(n), tol=1e-14, max_restarts=300)
            if not ritz.converged:
                return EigenEstimate(None, None, Status.unavailable(
                    f"the eigenvalue solver did not converge on {name} (residual {ritz.residual:.2g} after "
                    f"{ritz.matvecs} products)"))
            v = ritz.vector
    except np.linalg.LinAlgError as exc:
        return EigenEstimate(None, None, Status.unavailable(
            f"the eigenvalue solver did not converge on {name} ({exc})"))
    v = v / np.linalg.norm(v)
    red = reduced_index(graph.n, lap.anchor)
    va = np.append(v, 0.0)                                       # index -1: the anchor, fixed at 0
    diff = va[red[graph.src]] - va[red[graph.dst]]
    rho = float(np.dot(lap.w, diff * diff))
    r = float(np.linalg.norm(a @ v - rho * v))
    per_col = int(np.diff(a.indptr).max())
    anorm = float(abs(a).sum(axis=0).max())
    delta = _ROUNDING_MARGIN * eps * anorm * per_col
    span = f"rotation weights from {lap.w.min():.3g} to {lap.w.max():.3g}"
    s = rho - r - 2.0 * delta
    lower = s - delta
    if not (np.isfinite(rho) and lower > 0):
        return EigenEstimate(None, None, Status.unavailable(
            f"lambda_min(L_w) (about {rho:.3g}) is below what double precision resolves for this matrix "
            f"(rounding level {delta:.2g} with ||L_w||_1 = {anorm:.3g}; {span})",
            "the gap bound falls back on a graph lower bound of lambda_min; rescale or check the "
            "rotation information of the weakest edges"))
    try:
        symbolic.factor(a, name=name, beta=-s)
    except NotPositiveDefinite:
        return EigenEstimate(None, None, Status.unavailable(
            f"the eigenvalue solver's lambda_min(L_w) = {rho:.6g} is contradicted by the inertia check "
            f"(L_w - {s:.6g} I is not positive definite)", "report this file to the developers"))
    status = OK
    if rho - lower > LAMBDA_INTERVAL_WARN * rho:
        status = Status.warning(f"lambda_min(L_w) is only known to lie in [{lower:.6g}, {rho:.6g}] "
                                f"({span})", "the gap bound uses the lower end")
    return EigenEstimate(rho, lower, status)


def block_diagonal(blocks: np.ndarray) -> sp.csc_matrix:
    """Sparse block-diagonal matrix from (k, b, b) blocks."""
    k, b, _ = blocks.shape
    base = np.arange(k)[:, None, None] * b
    rows = np.broadcast_to(base + np.arange(b)[None, :, None], blocks.shape).ravel()
    cols = np.broadcast_to(base + np.arange(b)[None, None, :], blocks.shape).ravel()
    return sp.csc_matrix((blocks.ravel(), (rows, cols)), shape=(k * b, k * b))


@dataclass(frozen=True, kw_only=True)
class GraphBounds(Result):
    """The graph-only bounds of the paper model at one anchor (the part of a ``BoundsResult``
    that follows from the graph alone; ``compute_bounds``).

    ``to_dict()`` is its keys of the ``bounds`` JSON object, from ``anchor`` to ``total_degree``;
    a number that is not ok carries ``<key>_status``. The log-dets of the two Laplacians, the
    times, their run counts and the orderings used are kept here too, outside the JSON (the
    ``BoundsResult`` shows the times and the orderings with the rest of its own).

    Attributes
    ----------
    anchor : int
        The anchored pose id (``anchor_index``: its internal index).
    rotation_weight : str
        ``"eq59"`` or ``"table2"``.
    lb, ub, ub_lambda : float or None
        eq. (75) left, middle (the paper's Table I/II upper bound) and right with lambda_inf
        (eq. 77); ``ub`` None when unavailable (``ub_status``).
    lambda_inf : float
        eq. (77)'s lambda_inf.
    lambda_min_rot, lambda_min_rot_lower : float or None
        lambda_min(L_w) (an upper estimate) and a certified lower bound of it.
    gap_bound : float or None
        Lemma 4: ``0 <= logdet F - lb <= gap_bound``.
    t_opt_graph, t_opt_approx : float
        T-optimality, eq. (73) and eq. (72).
    total_degree : int
        Sum of the degrees of the free poses.

    Examples
    --------
    >>> import posecrb
    >>> b = posecrb.bounds("intel", estimate=None).bounds
    >>> round(b.lb, 3), b.anchor, b.status.ok
    (30155.231, 0, True)
    """

    anchor: int
    rotation_weight: str
    lb: float
    ub: float | None              # ub_psi, the paper's Table I/II upper bound (None: see ub_status)
    ub_status: Status = status_field("ub")
    ub_lambda: float
    lambda_inf: float
    lambda_min_rot: float | None  # lambda_min(L_w) (estimate, an upper bound); None if unavailable
    lambda_min_rot_status: Status = status_field("lambda_min(L_w)")
    lambda_min_rot_lower: float | None = None   # certified lower bound used by gap_bound
    gap_bound: float | None       # Lemma 4, with a certified lower bound of lambda_min(L_w)
    gap_bound_status: Status = status_field("Lemma 4 gap bound")
    t_opt_graph: float            # eq. (73)
    t_opt_approx: float           # eq. (72)
    total_degree: int
    dim: int = internal_field(0)
    anchor_index: int = internal_field(0)
    logdet_l_tau: float = internal_field(math.nan)
    logdet_l_w: float = internal_field(math.nan)
    times: dict[str, float] = internal_field(factory=dict)
    runs: dict[str, int] = internal_field(factory=dict)        # per key of times: how many runs its median is of
    ordering: dict[str, str] = internal_field(factory=dict)    # {"lb": ..., "ub": ...}: the orderings used


def compute_bounds(graph: PoseGraph, anchor: int | None = None, rotation_weight: str = "eq59",
                   repeat: Repeat = 1, *, ordering: str = "auto") -> GraphBounds:
    """All graph-only metrics; ``anchor`` is an internal index (default 0 = smallest id).

    Timed regions (``posecrb.core.timing.measure`` with ``repeat``: 1 = one run, k = median of k
    after a warm-up, "auto" = adaptive; ``runs`` says how many runs each time is the median of):
    ``laplacians`` = weights from the information matrices + both reduced Laplacians; ``lb`` = one
    symbolic analysis + two numeric factorizations (Algorithm 1); ``ub`` = Psi blocks + the augmented
    rotation matrix + its analysis and factorization; ``ub_lambda`` = lambda_inf + one factorization
    of L_w + lambda_inf I reusing lb's ordering. ``d logdet(L_tau)`` is shared by all three and timed in ``lb`` only.
    ``ordering``: the fill-reducing ordering (``posecrb.linalg.ordering.ORDERINGS``) of lb's
    Laplacians and of ub's matrix, whose pose graph is L_w's (d_r rows per pose); the choices made
    are in ``ordering`` of the result.
    """
    graph.require_connected()
    anchor = 0 if anchor is None else int(anchor)
    d, dr = graph.dim, graph.rot_dim
    m_lap = measure(lambda: weighted_laplacians(graph, anchor, rotation_weight), repeat)
    lap = m_lap.value

    n_p = graph.n - 1

    def lower_terms():
        sym, choice = ordered_symbolic(lap.l_tau, ordering, dim=d, poses=graph.n, matrix="lb")
        used["lb"] = str(choice)
        _, ld_tau = sym.factor_logdet(lap.l_tau, "reduced translation Laplacian L_tau")
        f_w, ld_w = sym.factor_logdet(lap.l_w, "reduced rotation Laplacian L_w")
        return sym, f_w, ld_tau, ld_w

    used: dict[str, str] = {}
    m_lb = measure(lower_terms, repeat)
    sym, f_w, ld_tau, ld_w = m_lb.value

    def upper():
        psi, _ = source_terms(graph, lap.tau, anchor)
        m = kron_identity(lap.l_w, dr) + block_diagonal(psi)
        try:
            sym_m, choice = ordered_symbolic(m, ordering, dim=d, poses=graph.n, matrix="ub",
                                             pose_of_row=np.repeat(np.arange(n_p), dr), n_poses=n_p,
                                             pose_adjacency=lap.l_w)
            used["ub"] = str(choice)
            return sym_m.factor_logdet(m, "L_w (x) I + blkdiag(Psi)")[1]
        except NotPositiveDefinite as exc:
            return exc

    m_ub = measure(upper, repeat)
    ld_psi = m_ub.value
    ub_status = OK
    if isinstance(ld_psi, NotPositiveDefinite):
        # L_w is positive definite (its factorization succeeded) and every Psi_i is positive
        # semidefinite, so the matrix is positive definite in exact arithmetic: a breakdown is
        # rounding, the weights spanning too many orders of magnitude.
        ub_status = Status.unavailable(
            f"the Cholesky factorization of L_w (x) I + blkdiag(Psi) breaks down in double precision "
            f"({ld_psi.reason}) although the matrix is positive definite in exact arithmetic (rotation "
            f"weights from {lap.w.min():.3g} to {lap.w.max():.3g})", "ub_lambda is a looser upper bound")
        ld_psi = None

    def upper_lambda():
        _, xi = source_terms(graph, lap.tau, anchor)
        lam = float(xi.max()) if xi.size else 0.0
        return lam, sym.factor_logdet(lap.l_w, "L_w + lambda_inf I", beta=lam)[1]

    m_ubl = measure(upper_lambda, repeat)
    lam_inf, ld_w_lam = m_ubl.value

    eig = rotation_lambda_min(lap, graph, sym, f_w)
    tree = tree_lambda_min_bound(graph.n, graph.src, graph.dst, lap.w, anchor) \
        if tree_bound_may_exceed(eig, lap.l_w) else 0.0
    lower = max(eig.lower or 0.0, tree)
    if eig.status.available and eig.lower is not None and eig.lower >= tree:
        gap_status = eig.status if not eig.status.ok else OK
    elif lower > 0:
        gap_status = Status.warning(
            f"computed with the graph lower bound lambda_min(L_w) >= {tree:.3g} (tree resistances), "
            "because lambda_min(L_w) itself is not resolved: a valid but looser bound")
    else:
        gap_status = Status.unavailable("no positive lower bound of lambda_min(L_w) (a rotation weight is "
                                        "zero or not finite)")
    gap = dr * n_p * float(np.log1p(lam_inf / lower)) if lower > 0 else None
    if gap is not None and not np.isfinite(gap):
        gap, gap_status = None, Status.unavailable(f"log(1 + lambda_inf / lambda_min) overflows "
                                                   f"(lambda_inf {lam_inf:.3g}, lower bound {lower:.3g})")
    t_graph, t_approx = t_optimality(graph, anchor, rotation_weight)
    total_degree = int(graph.degree.sum() - graph.degree[anchor])
    return GraphBounds(
        dim=d, anchor_index=anchor, anchor=int(graph.ids[anchor]), rotation_weight=rotation_weight,
        logdet_l_tau=float(ld_tau), logdet_l_w=float(ld_w),
        lb=d * float(ld_tau) + dr * float(ld_w), ub=None if ld_psi is None else d * float(ld_tau) + float(ld_psi),
        ub_lambda=d * float(ld_tau) + dr * float(ld_w_lam), lambda_inf=lam_inf,
        lambda_min_rot=eig.value, gap_bound=gap, t_opt_graph=t_graph, t_opt_approx=t_approx,
        total_degree=total_degree,
        times={"laplacians": m_lap.seconds, "lb": m_lb.seconds, "ub": m_ub.seconds, "ub_lambda": m_ubl.seconds},
        runs={"laplacians": m_lap.runs, "lb": m_lb.runs, "ub": m_ub.runs, "ub_lambda": m_ubl.runs},
        lambda_min_rot_lower=lower if lower > 0 else None, lambda_min_rot_status=eig.status,
        gap_bound_status=gap_status, ub_status=ub_status, ordering=used,
    )
