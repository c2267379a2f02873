"""Graph-only bounds on the D-optimality metric and T-optimality (paper sections VII-A, VII-B).

With d = 2|3, d_r = 1|3 and the reduced weighted Laplacians L_tau (translation
weights tau) and L_w (rotation weights w, DESIGN.md section 3):

* ``lb = d logdet(L_tau) + d_r logdet(L_w)`` (eq. 75 left, Algorithm 1: one
  fill-reducing ordering shared by both factorizations);
* ``ub = d logdet(L_tau) + logdet(L_w (x) I_dr + blkdiag(Psi_i))`` (eq. 75 middle
  with eq. 71: the measured p_ij replace x_j - x_i; the paper's Table I "Upper bound");
* ``ub_lambda = d logdet(L_tau) + d_r logdet(L_w + lambda_inf I)`` (eq. 75 right,
  eq. 77), one more factorization with the same ordering;
* Lemma 4: ``0 <= logdet F - lb <= d_r n_p log(1 + xi / lambda_min(L_w))``;
* T-optimality: graph-only eq. (73) and eq. (72) with p_ij; total node degree
  ``sum_{i != anchor} |V_i|`` (the paper's sum over i = 1..n_p).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .graph import PoseGraph
from .laplacian import kron_identity, reduced_index, reduced_laplacian
from .linalg import SymbolicCholesky, lambda_min
from .noise import isotropic_precisions, rotation_weight
from .timing import timed


@dataclass(frozen=True)
class WeightedLaplacians:
    """Reduced weighted Laplacians of the translation and rotation graphs (same pattern)."""
    anchor: int
    l_tau: sp.csc_matrix
    l_w: sp.csc_matrix
    tau: np.ndarray
    w: np.ndarray


def weighted_laplacians(graph: PoseGraph, anchor: int = 0, rotation_model: str = "eq59") -> WeightedLaplacians:
    """Build L_tau and L_w from the information matrices (weights computed here, vectorised)."""
    tau, kappa = isotropic_precisions(graph.info, graph.dim)
    w = rotation_weight(kappa, graph.dim, rotation_model)
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


def t_optimality(graph: PoseGraph, anchor: int = 0, rotation_model: str = "eq59") -> tuple[float, float]:
    """(eq. 73, eq. 72): graph-only T-optimality and its approximation with the measured p_ij.

    ``trace(L_tau (x) I_d) + trace(L_w (x) I_dr)`` over the non-anchor poses, straight from the edge
    arrays (each edge end that is not the anchor contributes ``d tau + d_r w``); eq. (72) adds
    ``sum_{i != anchor} sum_{j in V_i^+} tau_ij ||p_ij||^2`` (``trace(Psi_(i,j))`` in 3D too, Appendix D).
    """
    tau = graph.tau
    w = rotation_weight(graph.kappa, graph.dim, rotation_model)
    ends = (graph.src != anchor).astype(float) + (graph.dst != anchor)
    t_graph = float(graph.dim * np.dot(tau, ends) + graph.rot_dim * np.dot(w, ends))
    psi = tau * np.einsum("ma,ma->m", graph.trans, graph.trans) * (graph.src != anchor)
    return t_graph, t_graph + float(psi.sum())


def block_diagonal(blocks: np.ndarray) -> sp.csc_matrix:
    """Sparse block-diagonal matrix from (k, b, b) blocks."""
    k, b, _ = blocks.shape
    base = np.arange(k)[:, None, None] * b
    rows = np.broadcast_to(base + np.arange(b)[None, :, None], blocks.shape).ravel()
    cols = np.broadcast_to(base + np.arange(b)[None, None, :], blocks.shape).ravel()
    return sp.csc_matrix((blocks.ravel(), (rows, cols)), shape=(k * b, k * b))


@dataclass(frozen=True)
class BoundsResult:
    dim: int
    anchor: int                   # internal index
    anchor_id: int                # id as in the file
    rotation_model: str
    logdet_l_tau: float
    logdet_l_w: float
    lb: float
    ub: float                     # ub_psi, the paper's Table I/II upper bound
    ub_lambda: float
    lambda_inf: float
    lambda_min_rot: float         # lambda_min(L_w)
    gap_bound: float              # Lemma 4
    t_opt_graph: float            # eq. (73)
    t_opt_approx: float           # eq. (72)
    total_degree: int
    times: dict[str, float] = field(default_factory=dict)


def compute_bounds(graph: PoseGraph, anchor: int | None = None, rotation_model: str = "eq59",
                   repeat: int = 1) -> BoundsResult:
    """All graph-only metrics; ``anchor`` is an internal index (default 0 = smallest id).

    Timed regions (median of ``repeat`` after one warm-up): ``laplacians`` = weights from the
    information matrices + both reduced Laplacians; ``lb`` = one symbolic analysis + two numeric
    factorizations (Algorithm 1); ``ub`` = Psi blocks + the augmented rotation matrix + its
    analysis and factorization; ``ub_lambda`` = lambda_inf + one factorization of L_w + lambda_inf I
    reusing lb's ordering. ``d logdet(L_tau)`` is shared by all three and timed in ``lb`` only.
    """
    graph.require_connected()
    anchor = 0 if anchor is None else int(anchor)
    d, dr = graph.dim, graph.rot_dim
    lap, t_lap = timed(lambda: weighted_laplacians(graph, anchor, rotation_model), repeat)

    def lower():
        sym = SymbolicCholesky(lap.l_tau)
        _, ld_tau = sym.factor_logdet(lap.l_tau, "reduced translation Laplacian L_tau")
        f_w, ld_w = sym.factor_logdet(lap.l_w, "reduced rotation Laplacian L_w")
        return sym, f_w, ld_tau, ld_w

    (sym, f_w, ld_tau, ld_w), t_lb = timed(lower, repeat)

    def upper():
        psi, _ = source_terms(graph, lap.tau, anchor)
        m = kron_identity(lap.l_w, dr) + block_diagonal(psi)
        return SymbolicCholesky(m).factor_logdet(m, "L_w (x) I + blkdiag(Psi)")[1]

    ld_psi, t_ub = timed(upper, repeat)

    def upper_lambda():
        _, xi = source_terms(graph, lap.tau, anchor)
        lam = float(xi.max()) if xi.size else 0.0
        return lam, sym.factor_logdet(lap.l_w, "L_w + lambda_inf I", beta=lam)[1]

    (lam_inf, ld_w_lam), t_ubl = timed(upper_lambda, repeat)

    lam_min = lambda_min(lap.l_w, factor=f_w, name="reduced rotation Laplacian L_w")
    n_p = graph.n - 1
    gap = dr * n_p * float(np.log1p(lam_inf / lam_min)) if lam_min > 0 else float("inf")
    t_graph, t_approx = t_optimality(graph, anchor, rotation_model)
    total_degree = int(graph.degree.sum() - graph.degree[anchor])
    return BoundsResult(
        dim=d, anchor=anchor, anchor_id=int(graph.ids[anchor]), rotation_model=rotation_model,
        logdet_l_tau=float(ld_tau), logdet_l_w=float(ld_w),
        lb=d * float(ld_tau) + dr * float(ld_w), ub=d * float(ld_tau) + float(ld_psi),
        ub_lambda=d * float(ld_tau) + dr * float(ld_w_lam), lambda_inf=lam_inf,
        lambda_min_rot=lam_min, gap_bound=gap, t_opt_graph=t_graph, t_opt_approx=t_approx,
        total_degree=total_degree,
        times={"laplacians": t_lap, "lb": t_lb, "ub": t_ub, "ub_lambda": t_ubl},
    )
