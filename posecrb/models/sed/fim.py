"""The sed model (the thesis's, on SE(d)^n): right-invariant Fisher information, gauge, anchored and quotient CRLBs.

Bertini, "On Intrinsic Cramér-Rao Bounds on the Lie Group SE(d)^n" (the thesis), chapters 4-5;
docs/design.md#thesis-fim.

Model and coordinates
---------------------
* Poses ``T_i = X_i^{-1}`` where ``X_i = (R_i, t_i)`` is the estimate in the file's convention
  (g2o vertices), so that ``T_i T_j^{-1} = X_i^{-1} X_j`` is the file's measurement ``z_ij``.
* Lie algebra coordinates put the rotation first (``posecrb.lie.se``); a pose's tangent vector
  is the ``delta`` of the right perturbation ``T_i Exp(delta)`` (thesis 4.5-4.6). The FIM is
  pose-major: rows ``i*q .. i*q + q - 1`` belong to pose ``i``, rotation first.
* Meaning of the coordinates: ``T_i Exp(delta) = X_i^{-1} Exp(delta)`` is ``X_i -> Exp(-delta) X_i``, a
  perturbation of pose i expressed in the world frame about the world origin. Per-pose
  blocks and traces of the bounds therefore carry lever-arm terms (rotation uncertainty
  times the distance of the pose from the origin) and are not comparable with the paper
  model's body-frame coordinates (docs/design.md#frames); they are the thesis' quantities.
* Left-multiplicative noise ``H_ij = Exp(xi_ij) T_i T_j^{-1}`` (4.3), ``xi_ij ~ N(0, Omega_ij^{-1})``;
  residual ``r_ij = Log(H_ij T_j T_i^{-1})`` (Prop. 4.3.2); Jacobian blocks (4.7)
  ``J_i = -Jr^{-1}(r_ij) Ad_{T_i}``, ``J_j = +Jr^{-1}(r_ij) Ad_{T_i}``;
  ``F = sum_ij J^T Omega_ij J`` (4.6), i.e. a block Laplacian with edge weight
  ``W_ij = A^T Omega_ij A``, ``A = Jr^{-1}(r_ij) Ad_{T_i}`` (Th. 4.6.4).

Information matrices from g2o
-----------------------------
A g2o information matrix ``I`` is ordered translation first and describes the
right-multiplicative error ``e = z^{-1} X_i^{-1} X_j``, i.e. ``X_i^{-1} X_j = z Exp(e)``. Since
``z Exp(e) = Exp(Ad_z e) z``, the left noise is ``xi = Ad_z e`` to first order (the estimate's
relative pose equals ``z`` up to the noise), hence, after reordering ``I`` rotation-first
(``Omega_right = P I P^T``)::

    Omega_left = Ad_z^{-T} Omega_right Ad_z^{-1} = Ad_{z^{-1}}^T Omega_right Ad_{z^{-1}}.

The file's rotation information is read as information on the rotation vector (as SE-Sync
does in 3D and as g2o's SE2 angle is). Note that g2o's ``EdgeSE3`` error uses the quaternion's
vector part, which is half the rotation vector to first order; posecrb does not rescale.

Indefinite information matrices (``indefinite=``): some real files (cubicle.g2o) carry full
6x6 information matrices whose translation and rotation blocks are positive definite but
whose cross terms make the whole matrix indefinite, which no Gaussian can have. Policies:

* ``"blocks"`` (default): for those edges only, drop the translation-rotation cross terms and
  keep the two diagonal blocks, i.e. the information the isotropic model of
  docs/design.md#noise-model also uses; positive definite by the reader's checks, and it adds no information
  along directions the file's diagonal calls weak.
* ``"project"``: nearest positive semidefinite matrix in Frobenius norm (negative eigenvalues
  clipped to zero, Higham 1988). Can leave ``Omega`` singular, hence a larger nullity.
* ``"raise"``: ``NotPositiveDefinite`` naming the count and the first offending edge.

Every repair is logged once as a warning with the edge count and recorded in
``SedFim.indefinite_edges``.

Gauge and bounds
----------------
``ker F`` contains ``[delta; ...; delta]`` on each connected component (the global right action
``T_k G``, Prop. 4.3.1), so ``nullity >= q c``; equality (Th. 4.8.1) is certified by a
successful Cholesky factorization of ``F`` restricted to the poses left after removing one
anchor per component. Anchored CRB (5.1): ``(Pi F Pi)^+`` is the inverse of ``F`` restricted to
the free poses, zero on anchors. Quotient CRB (5.5): ``F^+ = P G P`` with ``P = I - N N^T``
(``N`` the orthonormal kernel basis) for any generalised inverse ``G`` of ``F``; the anchored
one with exactly one anchor per component is used (more anchors give no generalised inverse:
``F G F != F``), so ``trace F^+ = trace G - trace(N^T G N)`` and the per-pose blocks follow from
``G``'s diagonal blocks and ``G N``, which needs only ``q`` solves whatever the number of
components (``G`` is block diagonal across components). Curvature terms are neglected, as in
Th. 5.2.2 / 5.3.1.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from ...core.errors import NotPositiveDefinite, UsageError
from ...core.graph import PoseGraph
from ...core.status import OK, Status
from ...lie.se import se_adjoint, se_inverse, se_jr_inv, se_log
from ...linalg.cholesky import Factor
from ...linalg.ordering import block_cholesky

log = logging.getLogger("posecrb")

INDEFINITE_POLICIES = ("blocks", "project", "raise")

# Above this many unknowns per failing component, the dense eigenvalue fallback for the rank
# is not attempted (it costs O((n q)^3)).
_DENSE_RANK_LIMIT = 3000
# A Cholesky pivot this small relative to its matrix's diagonal entry means the matrix is
# numerically singular even though the factorization ran through.
_PIVOT_RTOL = 1e-12


@dataclass(frozen=True, eq=False)
class SedFim:
    """Right-invariant FIM on SE(d)^n at an estimate (thesis 4.6, 4.8)."""

    matrix: sp.csc_matrix          # (n q, n q), pose-major, rotation first per pose
    dim: int
    q: int
    n: int
    m: int
    rank: int
    nullity: int                   # == q * components when the model is identifiable (Th. 4.8.1)
    components: int
    component_labels: np.ndarray   # (n,) component of each pose
    anchors: list[int]             # anchors used for the rank check: smallest index per component
    logdet_anchored: float | None  # log det of F restricted to the free poses (None if singular)
    rank_method: str               # "cholesky" | "dense-eig"
    indefinite_edges: int          # edges whose information matrix was repaired (see module doc)
    indefinite_policy: str
    max_residual_angle: float      # max rotation angle of r_ij: the linearisation point's quality
    times: dict[str, float]
    factor: Any = field(default=None, repr=False)  # CHOLMOD factor of F on the free poses
    free_matrix: Any = field(default=None, repr=False)  # F on the free poses (what ``factor`` factors)
    logdet_status: Status = OK     # unavailable when F on the free poses is numerically singular

    @property
    def trace(self) -> float:
        return float(self.matrix.diagonal().sum())


# ------------------------------------------------------------------ information matrices
def _rotation_first(q: int) -> np.ndarray:
    """Permutation taking g2o order (translation, rotation) to rotation first."""
    d = 2 if q == 3 else 3
    return np.r_[d:q, 0:d]


def _repair_indefinite(om: np.ndarray, graph: PoseGraph, policy: str) -> tuple[np.ndarray, int]:
    """Apply the ``indefinite`` policy to rotation-first information matrices (m, q, q)."""
    if policy not in INDEFINITE_POLICIES:
        raise UsageError(f"indefinite policy must be one of {', '.join(INDEFINITE_POLICIES)}, got {policy!r}")
    lam, vec = np.linalg.eigh(om)
    bad = np.flatnonzero(lam[:, 0] <= 0)
    if bad.size == 0:
        return om, 0
    k = int(bad[0])
    line = f" (line {int(graph.edge_lines[k])})" if graph.edge_lines is not None else ""
    first = f"first: edge {graph.ids[graph.src[k]]} -> {graph.ids[graph.dst[k]]}{line}"
    if policy == "raise":
        raise NotPositiveDefinite(
            f"information matrix of {bad.size} of {graph.m} edges",
            f"indefinite ({first}); use indefinite='blocks' or 'project'")
    om = om.copy()
    if policy == "blocks":
        r = graph.rot_dim
        om[bad, :r, r:] = 0.0
        om[bad, r:, :r] = 0.0
        still = np.flatnonzero(np.linalg.eigvalsh(om[bad])[:, 0] <= 0)
        if still.size:
            k2 = int(bad[still[0]])
            raise NotPositiveDefinite(
                f"information matrix of edge {graph.ids[graph.src[k2]]} -> {graph.ids[graph.dst[k2]]}",
                "its translation or rotation block is not positive definite")
        what = "dropped their translation-rotation cross terms"
    else:
        lb = np.maximum(lam[bad], 0.0)
        om[bad] = np.einsum("eij,ej,ekj->eik", vec[bad], lb, vec[bad])
        what = "projected them to the nearest positive semidefinite matrix"
    log.warning("%s: %d of %d information matrices are not positive definite (%s); SE(d) model %s",
                graph.name, bad.size, graph.m, first, what)
    return om, int(bad.size)


def left_information(graph: PoseGraph, indefinite: str = "blocks") -> tuple[np.ndarray, int]:
    """(m, q, q) information of the left-multiplicative noise xi_ij (4.3), rotation first.

    ``Omega_left = Ad_{z^{-1}}^T Omega_right Ad_{z^{-1}}`` with ``Omega_right`` the file's matrix
    reordered rotation first (module docstring). Returns the matrices and the number of
    indefinite ones repaired under ``indefinite``.
    """
    p = _rotation_first(graph.q)
    om = np.asarray(graph.info, float)[:, p][:, :, p]
    om = 0.5 * (om + np.swapaxes(om, 1, 2))
    om, n_bad = _repair_indefinite(om, graph, indefinite)
    ad_zinv = se_adjoint(*se_inverse(graph.rot, graph.trans))
    return np.swapaxes(ad_zinv, 1, 2) @ om @ ad_zinv, n_bad


def right_information_from_left(rot: np.ndarray, trans: np.ndarray, omega_left: np.ndarray) -> np.ndarray:
    """Inverse of ``left_information``'s conversion for measurements ``z = (rot, trans)``, g2o order.

    ``I = P^T (Ad_z^T Omega_left Ad_z) P``: what a g2o file must contain for the SE(d) model to
    see ``omega_left`` (used to write synthetic examples such as the thesis' chapter 6).
    """
    q = omega_left.shape[-1]
    ad_z = se_adjoint(rot, trans)
    om_r = np.swapaxes(ad_z, -1, -2) @ omega_left @ ad_z
    inv = np.argsort(_rotation_first(q))
    return om_r[..., inv, :][..., :, inv]


# ------------------------------------------------------------------ residuals and Jacobians

def edge_residuals(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """(m, q) residuals ``r_ij = Log(z_ij T_j T_i^{-1})`` with ``T = X^{-1}`` (Prop. 4.3.2)."""
    rot, trans = graph.check_estimate(rot, trans)
    ri, rj = rot[graph.src], rot[graph.dst]
    ti, tj = trans[graph.src], trans[graph.dst]
    rjt = np.swapaxes(rj, 1, 2)
    # T_j T_i^{-1} = X_j^{-1} X_i = (R_j^T R_i, R_j^T (t_i - t_j))
    r_d = rjt @ ri
    t_d = np.einsum("eij,ej->ei", rjt, ti - tj)
    r_z = graph.rot @ r_d
    t_z = np.einsum("eij,ej->ei", graph.rot, t_d) + graph.trans
    return se_log(r_z, t_z)


def edge_kinematics(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residuals (m, q) and ``A_ij = Jr^{-1}(r_ij) Ad_{T_i}`` (m, q, q): ``J_i = -A``, ``J_j = A`` (4.7)."""
    rot, trans = graph.check_estimate(rot, trans)
    res = edge_residuals(graph, rot, trans)
    ad_ti = se_adjoint(*se_inverse(rot[graph.src], trans[graph.src]))
    return res, se_jr_inv(res) @ ad_ti


def _block_laplacian(n: int, q: int, src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> sp.csc_matrix:
    """``sum_e (e_i - e_j)(e_i - e_j)^T (x) W_e`` from (m, q, q) blocks, one COO, no loop."""
    k = np.arange(q)
    a = np.concatenate([src, dst, src, dst])
    b = np.concatenate([src, dst, dst, src])
    vals = np.concatenate([w, w, -w, -w])
    rows = np.broadcast_to((a * q)[:, None, None] + k[None, :, None], vals.shape)
    cols = np.broadcast_to((b * q)[:, None, None] + k[None, None, :], vals.shape)
    return sp.coo_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(n * q, n * q)).tocsc()


def _dofs(poses: np.ndarray, q: int) -> np.ndarray:
    return (np.asarray(poses)[:, None] * q + np.arange(q)).ravel()


def default_anchors(graph: PoseGraph) -> list[int]:
    """The smallest internal index of every connected component, in component order."""
    _, first = np.unique(graph.component_labels, return_index=True)
    return [int(i) for i in first]


def _resolve_anchors(graph: PoseGraph, anchors: Sequence[int] | None) -> list[int]:
    if anchors is None:
        return default_anchors(graph)
    a = np.unique(np.asarray(list(anchors), dtype=np.int64))
    if a.size and (a[0] < 0 or a[-1] >= graph.n):
        raise UsageError(f"anchor index out of range 0..{graph.n - 1}: {list(anchors)}")
    labels = graph.component_labels
    missing = np.setdiff1d(np.arange(graph.n_components), labels[a])
    if missing.size:
        first = np.unique(labels, return_index=True)[1]
        sizes = np.bincount(labels, minlength=graph.n_components)
        parts = "; ".join(f"component #{c} ({sizes[c]} poses, smallest id {graph.ids[first[c]]})"
                          for c in missing[:6])
        more = f"; ... {missing.size - 6} more" if missing.size > 6 else ""
        raise UsageError(f"every connected component needs an anchor; {missing.size} without one: {parts}{more}")
    return [int(x) for x in a]


def _free_matrix(f: sp.csc_matrix, n: int, q: int, anchors: Sequence[int]) -> tuple[sp.csc_matrix, np.ndarray]:
    free = np.setdiff1d(np.arange(n), np.asarray(anchors, dtype=np.int64))
    dofs = _dofs(free, q)
    return f[dofs][:, dofs].tocsc(), free


def _factor_free(ff: sp.csc_matrix, name: str, graph: PoseGraph, ordering: str = "auto") -> Factor | None:
    """Cholesky of F on the free poses (``ordering``: posecrb.linalg.ordering), or None if it is
    (numerically) singular."""
    try:
        fac = block_cholesky(ff, ordering, dim=graph.dim, poses=graph.n, matrix="fim", block=graph.q, name=name)
    except NotPositiveDefinite:
        return None
    piv = fac.D()
    diag = ff.diagonal()[fac.P()]
    if np.any(piv <= _PIVOT_RTOL * diag):
        return None
    return fac


def _dense_rank(f: sp.csc_matrix, labels: np.ndarray, q: int, graph: PoseGraph) -> int:
    """Rank of F summed over components, each by dense eigenvalues (fallback only)."""
    rank = 0
    for c in range(int(labels.max()) + 1):
        poses = np.flatnonzero(labels == c)
        if poses.size * q > _DENSE_RANK_LIMIT:
            raise NotPositiveDefinite(
                f"SE(d) FIM of component #{c} ({poses.size} poses, smallest id {graph.ids[poses[0]]})",
                "its nullity exceeds q (Th. 4.7.1): singular or extremely ill-conditioned information "
                "matrices; too large for a dense rank computation")
        dofs = _dofs(poses, q)
        ev = np.linalg.eigvalsh(f[dofs][:, dofs].toarray())
        tol = max(abs(ev[-1]), 0.0) * dofs.size * np.finfo(float).eps
        rank += int(np.sum(ev > tol))
    return rank


# ------------------------------------------------------------------ public API
def sed_fim(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, *, indefinite: str = "blocks",
            information: np.ndarray | None = None, ordering: str = "auto") -> SedFim:
    """Right-invariant FIM ``F = sum J^T Omega J`` (4.6) at the estimate ``X_i = (rot[i], trans[i])``.

    ``rot`` (n, d, d), ``trans`` (n, d) are vertex poses in the file's convention; the thesis'
    poses are their inverses (module docstring). ``information`` optionally replaces the
    converted file matrices by (m, q, q) left-noise information, rotation first. Works on
    disconnected graphs: rank and nullity are certified by one Cholesky factorization of F on
    the poses left after removing the smallest index of each component (reused by ``sed_crlb``;
    its log-determinant is ``logdet_anchored``). If that factorization fails (nullity above
    ``q c``: singular or extremely ill-conditioned information), the rank is computed per
    component from dense eigenvalues (``rank_method="dense-eig"``, components of at most 3000
    unknowns); a larger rank-deficient component raises ``NotPositiveDefinite``. ``ordering``: the
    factorization's fill-reducing ordering (posecrb.linalg.ordering; cost only).
    """
    t0 = time.perf_counter()
    q = graph.q
    if information is None:
        omega, n_bad = left_information(graph, indefinite)
    else:
        omega = np.asarray(information, float)
        if omega.shape != (graph.m, q, q):
            raise UsageError(f"information must have shape {(graph.m, q, q)}, got {omega.shape}")
        n_bad = 0
    res, a = edge_kinematics(graph, rot, trans)
    w = np.swapaxes(a, 1, 2) @ omega @ a
    w = 0.5 * (w + np.swapaxes(w, 1, 2))
    mat = _block_laplacian(graph.n, q, graph.src, graph.dst, w)
    t1 = time.perf_counter()

    c = graph.n_components
    labels = graph.component_labels
    anchors = default_anchors(graph)
    ff, _ = _free_matrix(mat, graph.n, q, anchors)
    fac = _factor_free(ff, "SE(d) FIM on the free poses", graph, ordering) if ff.shape[0] else None
    status = OK
    if fac is not None or ff.shape[0] == 0:
        rank, method = ff.shape[0], "cholesky"
        logdet = float(fac.logdet()) if fac is not None else 0.0
    else:
        rank, method, logdet = _dense_rank(mat, labels, q, graph), "dense-eig", None
        status = _singular_status(graph, graph.n * q - rank, q * c)
    t2 = time.perf_counter()
    ang = np.linalg.norm(res[:, : graph.rot_dim], axis=1)
    return SedFim(
        matrix=mat, dim=graph.dim, q=q, n=graph.n, m=graph.m, rank=rank, nullity=graph.n * q - rank,
        components=c, component_labels=labels, anchors=anchors, logdet_anchored=logdet,
        rank_method=method, indefinite_edges=n_bad, indefinite_policy=indefinite,
        max_residual_angle=float(ang.max()) if ang.size else 0.0,
        times={"fim_build": t1 - t0, "fim_rank": t2 - t1}, factor=fac, free_matrix=ff, logdet_status=status)


def _singular_status(graph: PoseGraph, nullity: int, expected: int) -> Status:
    """Why the FIM on the free poses is numerically singular, naming the weakest edge of the file."""
    lam = np.linalg.eigvalsh(np.asarray(graph.info, float))
    weakest = int(np.argmin(lam[:, 0]))
    line = f", line {int(graph.edge_lines[weakest])}" if graph.edge_lines is not None else ""
    edge = f"edge {graph.ids[graph.src[weakest]]} -> {graph.ids[graph.dst[weakest]]}{line}"
    return Status.unavailable(
        f"numerically singular: numerical nullity {nullity} where q x components = {expected} is expected "
        f"(Th. 4.8.1), i.e. some directions carry information below double precision relative to the rest "
        f"(smallest information eigenvalue {lam[weakest, 0]:.3g} at {edge}; largest {lam[:, -1].max():.3g}); "
        "no log-det or inverse", "check that edge's information matrix, or drop it (the graph then splits "
        "and each component gets its own anchor)")


def kernel_basis(graph: PoseGraph, rot: np.ndarray | None = None, trans: np.ndarray | None = None,
                 *, sparse: bool = False) -> np.ndarray | sp.csc_matrix:
    """(n q, q c) orthonormal basis of ker F (Th. 4.8.1): ``[delta; ...; delta] / sqrt(n_c)`` per component.

    In right-perturbation coordinates the gauge directions do not depend on the estimate (the
    global right action ``T_k Exp(delta)`` perturbs every pose by the same ``delta``), so
    ``rot``/``trans`` are accepted for symmetry with ``sed_fim`` but unused. Column ``c q + k``
    is direction ``k`` of component ``c``.
    """
    q = graph.q
    labels = graph.component_labels
    sizes = np.bincount(labels, minlength=graph.n_components)
    k = np.arange(q)
    rows = (np.arange(graph.n)[:, None] * q + k).ravel()
    cols = (labels[:, None] * q + k).ravel()
    vals = np.repeat(1.0 / np.sqrt(sizes[labels]), q)
    n_mat = sp.csc_matrix((vals, (rows, cols)), shape=(graph.n * q, graph.n_components * q))
    return n_mat if sparse else n_mat.toarray()


