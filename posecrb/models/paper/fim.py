"""The paper's anchored Fisher information matrix on (R^d x SO(d))^{n_p} at an estimate.

2D: eq. (42); 3D: eq. (64) (Chen et al., sections IV-V), in the coordinates of
docs/design.md#noise-model and #fim-variants. The FIM is the Gauss-Newton information of the translation
residuals

    r_ij = R_i^T (x_j - x_i) - p_ij,      weight tau_ij I_d,

plus a rotation Laplacian (eq. 41 / 58-63 without Psi), with the Jacobians (right,
body-frame perturbation ``R_i Exp(delta)`` along the paper's basis ``R_i E``)

    dr/dx_i = -R_i^T,   dr/dx_j = R_i^T,
    dr/dtheta_i = -E u                     (2D, E = [[0, -1], [1, 0]], u = R_i^T (x_j - x_i)),
    dr/dphi_i  = (1/sqrt 2) [u]_x          (3D, basis E_k = G_k / sqrt 2).

``J^T tau J`` reproduces the blocks of the paper: the translation block is
``L_tau (x) I_d`` (eq. 19/45), the cross block is Delta_w (eq. 33/52-54) and the rotation
diagonal gains ``psi_i = sum tau ||x_j - x_i||^2`` (eq. 41) or
``Psi_i = sum tau/2 (||u||^2 I - u u^T)`` (eq. 63), summed over edges whose SOURCE is i.
Sign of the cross block: eq. (54) as printed has ``(x_j - x_i)`` in its ``i = i_1`` case, the
opposite sign of its own derivation eq. (52) (``(x_i - x_j)``); built literally, eq. (64) is then
indefinite (tinyGrid3D has a negative eigenvalue of order -100). posecrb uses eq. (52)'s sign,
which is the one ``J^T tau J`` gives.

Two variants of the rotation Laplacian (``FIM_VARIANTS``), identical in 2D:

* ``"consistent"`` (default): the Fisher information of the measurement model that g2o /
  SE-Sync files and posecrb's simulator use (edge (i, j) measures ``X_i^{-1} X_j``, rotation
  ``R~_ij = R_i^T R_j Z_ij``), with every pose perturbed on the right, as in Delta
  (eq. 52-54) and Psi (eq. 56-60, 63). Under ``R_i Exp(a_i)``, ``R_j Exp(a_j)`` the relative
  rotation moves as ``R_ij Exp(a_j - R_ij^T a_i)`` with ``R_ij = R_i^T R_j`` (the estimate's),
  so the off-diagonal rotation block of edge (i, j) is ``-w R_i^T R_j`` (its transpose at
  (j, i)). Checked against a finite-difference expected Hessian of the log-likelihood and by
  Monte Carlo (``posecrb experiment crlb``: the MSE of the certified MLE reaches this bound).
* ``"eq64"``: eq. (64) exactly as printed, ``L_w (x) I_{d_r}``: the diagonal blocks
  ``sum w I`` (eq. 58) and the off-diagonal blocks ``-w I`` of eq. (61)-(62). Together with
  the body-frame Delta and Psi this is the body-frame Fisher information of the rotation
  model as literally printed in eq. (4), ``H_ij = Z_ij R_j R_i^T``, which is not invariant
  under a global rotation of all poses (a frame slip: eq. (61)-(62) pair the tangent noise of
  ``Z_ij`` and ``Z_ji`` as if both were expressed in the same frame). It reproduces the
  paper's printed Table II (with the empirical rotation weight ``table2``,
  ``posecrb tables --as-published``).

In 2D rotations commute, ``R_ij`` acts on the angle as 1 and both variants are the same
matrix. With ``T = blkdiag(R_i^T)`` on the rotations, ``T (L_w (x) I_3) T^T`` is the consistent
Laplacian, so the two have the same trace (T-optimality) and the same Laplacian-only
log det, but their inverses (the CRLB) and full log-dets differ once the poses are rotated
relative to each other (tinyGrid3D at its file's vertices: trace F^{-1} 7.60 for the model,
2.28 for eq. 64; the Monte Carlo MSE of the MLE reaches the former).

Everything is assembled vectorised from the edge arrays (COO), anchor removed.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from ...core.choices import FIM_VARIANTS
from ...core.errors import UsageError
from ...core.graph import PoseDimensions, PoseGraph
from ...linalg.accuracy import LogdetAccuracy, logdet_accuracy
from ...linalg.cholesky import SymbolicCholesky
from ...linalg.laplacian import reduced_index
from ...linalg.ordering import OrderingChoice, ordered_symbolic
from .tree_inverse import tree_inverse_diagonal

_E2 = np.array([[0.0, -1.0], [1.0, 0.0]])
LAYOUTS = ("blocks", "poses")


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperFim(PoseDimensions):
    """The anchored paper FIM.

    ``layout == "blocks"`` (eq. 42 / 64): rows ``[x_1; ...; x_np; theta_1; ...; theta_np]``,
    translations first (d per free pose, pose-major), then rotations (d_r per free pose).
    ``layout == "poses"``: pose-interleaved ``[x_1, theta_1, x_2, theta_2, ...]``, q = d + d_r
    rows per free pose, so that per-pose blocks are contiguous ``q x q`` diagonal blocks.
    Free poses are the graph's poses in increasing id order without the anchor
    (``pose_ids``); rotation coordinates are the angle (2D) or along ``E_k = G_k/sqrt 2`` (3D).
    ``variant`` is the rotation Laplacian used (``FIM_VARIANTS``, see the module docstring):
    ``"consistent"`` (the model's Fisher information) or ``"eq64"`` (as printed in the paper).
    """

    matrix: sp.csc_matrix
    dim: int
    anchor: int                  # internal index of the anchored pose
    anchor_id: int               # its id in the file
    pose_ids: np.ndarray         # (n_p,) ids of the free poses, in row order
    layout: str
    rotation_weight: str
    variant: str = "consistent"
    build_time: float = field(default=0.0)

    @property
    def n_free(self) -> int:
        return int(self.pose_ids.shape[0])

    @property
    def size(self) -> int:
        return int(self.matrix.shape[0])

    @property
    def nnz(self) -> int:
        return int(self.matrix.nnz)

    def coordinate_names(self) -> list[str]:
        return coordinate_names(self.dim)

    def index_map(self) -> tuple[np.ndarray, np.ndarray]:
        """For each row: (pose id, coordinate number within the pose, 0..q-1)."""
        d, dr, npf = self.dim, self.rot_dim, self.n_free
        if self.layout == "poses":
            return np.repeat(self.pose_ids, self.q), np.tile(np.arange(self.q), npf)
        ids = np.concatenate([np.repeat(self.pose_ids, d), np.repeat(self.pose_ids, dr)])
        coord = np.concatenate([np.tile(np.arange(d), npf), d + np.tile(np.arange(dr), npf)])
        return ids, coord

    def to_layout(self, layout: str) -> PaperFim:
        """The same FIM with rows and columns permuted to ``layout``."""
        if layout == self.layout:
            return self
        perm = _layout_permutation(self.n_free, self.dim, self.rot_dim, layout)
        mat = self.matrix[perm][:, perm].tocsc()
        mat.sort_indices()

        return replace(self, matrix=mat, layout=layout)

    def rotation_block(self) -> sp.csc_matrix:
        """``I^{SO(d)} = L_w (x) I_{d_r} + diag(Psi)``: the rotation-rotation block (eq. 41 / 63),
        rows ordered pose-major (d_r per free pose). With ``variant == "consistent"`` the
        Laplacian part has the off-diagonal blocks ``-w R_i^T R_j`` instead of ``-w I``."""
        f = self.to_layout("blocks").matrix
        k = self.n_free * self.dim
        return f[k:, k:].tocsc()


def coordinate_names(dim: int) -> list[str]:
    return ["x", "y", "theta"] if dim == 2 else ["x", "y", "z", "phi1", "phi2", "phi3"]


def _layout_permutation(n_free: int, d: int, dr: int, layout: str) -> np.ndarray:
    """Row k of the ``layout`` matrix is row perm[k] of the "blocks" matrix."""
    if layout == "blocks":
        return np.arange(n_free * (d + dr))
    if layout != "poses":
        raise UsageError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    pose = np.arange(n_free)[:, None]
    trans = pose * d + np.arange(d)[None, :]
    rot = n_free * d + pose * dr + np.arange(dr)[None, :]
    return np.hstack([trans, rot]).ravel()



def rotation_jacobians(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per edge: ``R_i`` (m, d, d) and ``D = dr_ij/dtheta_i`` (m, d, d_r) in the paper's coordinates."""
    ri = rot[graph.src]
    u = np.einsum("mba,mb->ma", ri, trans[graph.dst] - trans[graph.src])  # R_i^T (x_j - x_i)
    if graph.dim == 2:
        dmat = -(u @ _E2.T)[:, :, None]
    else:
        s = 1.0 / np.sqrt(2.0)
        z = np.zeros(u.shape[0])
        dmat = s * np.stack([
            np.stack([z, -u[:, 2], u[:, 1]], axis=1),
            np.stack([u[:, 2], z, -u[:, 0]], axis=1),
            np.stack([-u[:, 1], u[:, 0], z], axis=1),
        ], axis=1)  # [u]_x
    return ri, dmat


def paper_fim(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0,
              rotation_weight: str = "eq59", layout: str = "blocks", variant: str = "consistent") -> PaperFim:
    """Anchored paper FIM (eq. 42 in 2D, eq. 64 in 3D) at the estimate ``(rot, trans)``.

    ``rot`` (n, d, d) and ``trans`` (n, d) are world poses ``X_i = (R_i, x_i)`` in the graph's
    internal order; ``anchor`` is an internal index (``graph.anchor_index(id)``).
    ``rotation_weight`` picks the rotation weight: ``"eq59"`` (default, eq. 39-41 / 59) or
    ``"table2"`` (the empirical fit that reproduces Table II, see docs/design.md#fim-variants).
    ``variant`` picks the rotation Laplacian (module docstring): ``"consistent"`` (default) is
    the Fisher information of the model in the body-frame coordinates that eq. (52)-(54) and
    (63) use, off-diagonal blocks ``-w R_i^T R_j`` for an edge i -> j; ``"eq64"`` is eq. (64)
    as printed, off-diagonal rotation blocks ``-w I`` (eq. 61-62). Both give the same matrix
    in 2D. The cross block follows eq. (52)'s sign (eq. 54 as printed has the opposite one).
    Raises DisconnectedGraph when the graph is not connected (the anchored FIM is singular).
    """

    t0 = time.perf_counter()
    if variant not in FIM_VARIANTS:
        raise UsageError(f"variant must be one of {FIM_VARIANTS}, got {variant!r}")
    graph.require_connected()
    rot, trans = graph.check_estimate(rot, trans)
    if not 0 <= anchor < graph.n:
        raise UsageError(f"anchor index {anchor} out of range 0..{graph.n - 1}")
    d, dr, n = graph.dim, graph.rot_dim, graph.n
    npf = n - 1
    tau = graph.tau
    w = graph.rotation_weights_by(rotation_weight)
    red = reduced_index(n, anchor)
    ri, rj = red[graph.src], red[graph.dst]
    _, dmat = rotation_jacobians(graph, rot, trans)

    size = npf * (d + dr)
    # Jacobian rows of r_ij (d per edge) in "blocks" column numbering, int32; the anchor's columns go
    # to a dummy row and column ``size``, dropped after the assembly (a slice of the summed matrix
    # instead of a mask over every entry: this assembly's memory is most of its time on a fresh
    # process). Column blocks: x_i (d), x_j (d), theta_i (d_r).
    def cols(base, r, k):
        return np.where(r[:, None] >= 0, base + r[:, None] * k + np.arange(k)[None, :], size).astype(np.int32)

    cxi, cxj, cth = cols(0, ri, d), cols(0, rj, d), cols(npf * d, ri, dr)
    ctr = np.concatenate([cxi, cxj, cth], axis=1)                       # (m, 2d + dr)
    jac = np.concatenate([-np.transpose(rot[graph.src], (0, 2, 1)),       # -R_i^T
                          np.transpose(rot[graph.src], (0, 2, 1)), dmat], axis=2)   # (m, d, 2d+dr)
    local = tau[:, None, None] * np.einsum("mka,mkb->mab", jac, jac)      # J^T tau J per edge
    k = ctr.shape[1]

    # rotation Laplacian (eq. 41 / 58-63): diagonal blocks sum w I
    ci, cj = cols(npf * d, ri, dr), cols(npf * d, rj, dr)
    wr = np.repeat(w, dr)
    if variant == "eq64" or d == 2:
        # off-diagonal blocks -w I (eq. 61-62); in 2D also the consistent coupling
        lrows = [ci.ravel(), cj.ravel(), ci.ravel(), cj.ravel()]
        lcols = [ci.ravel(), cj.ravel(), cj.ravel(), ci.ravel()]
        lvals = [wr, wr, -wr, -wr]
    else:
        # body-frame coupling: block (i, j) = -w R_i^T R_j, block (j, i) its transpose
        rel = -w[:, None, None] * (np.transpose(rot[graph.src], (0, 2, 1)) @ rot[graph.dst])
        lrows = [ci.ravel(), cj.ravel(), np.repeat(ci, dr, axis=1).ravel(), np.repeat(cj, dr, axis=1).ravel()]
        lcols = [ci.ravel(), cj.ravel(), np.tile(cj, (1, dr)).ravel(), np.tile(ci, (1, dr)).ravel()]
        lvals = [wr, wr, rel.ravel(), np.transpose(rel, (0, 2, 1)).ravel()]

    rows = np.concatenate([np.repeat(ctr, k, axis=1).ravel(), *lrows])
    cols_ = np.concatenate([np.tile(ctr, (1, k)).ravel(), *lcols])
    vals = np.concatenate([local.ravel(), *lvals])
    padded = sp.csc_matrix((vals, (rows, cols_)), shape=(size + 1, size + 1))
    padded.sum_duplicates()
    mat = sp.csc_matrix(padded[:size, :size])
    mat.sort_indices()
    pose_ids = np.delete(graph.ids, anchor)
    fim = PaperFim(matrix=mat, dim=d, anchor=int(anchor), anchor_id=int(graph.ids[anchor]), pose_ids=pose_ids,
                   layout="blocks", rotation_weight=rotation_weight, variant=variant,
                   build_time=time.perf_counter() - t0)
    if layout != "blocks":
        fim = fim.to_layout(layout)
    return fim


def pose_of_row(fim: PaperFim) -> np.ndarray:
    """For each row of ``fim.matrix``: its free pose's number 0..n_p-1 (in ``pose_ids`` order)."""
    k = np.arange(fim.n_free)
    if fim.layout == "poses":
        return np.repeat(k, fim.q)
    return np.concatenate([np.repeat(k, fim.dim), np.repeat(k, fim.rot_dim)])


def fim_symbolic_choice(fim: PaperFim, ordering: str = "auto") -> tuple[SymbolicCholesky, OrderingChoice]:
    """One CHOLMOD analysis of the FIM's pattern with ``ordering`` (posecrb.linalg.ordering), reusable
    for every FIM of the same graph, anchor and layout (the pattern does not depend on the estimate),
    and the ordering it used; pose-level orderings use the pose graph read from the FIM's pattern."""
    return ordered_symbolic(fim.matrix, ordering, dim=fim.dim, poses=fim.n_free + 1, matrix="fim",
                            pose_of_row=pose_of_row(fim), n_poses=fim.n_free)


def fim_symbolic(fim: PaperFim, ordering: str = "auto") -> SymbolicCholesky:
    """``fim_symbolic_choice`` without the choice."""
    return fim_symbolic_choice(fim, ordering)[0]


def fim_logdet(fim: PaperFim, symbolic: SymbolicCholesky | None = None, *, ordering: str = "auto") -> float:
    """log det F by sparse Cholesky (CHOLMOD), reusing ``symbolic`` when given (otherwise analysed
    with ``ordering``). Raises NotPositiveDefinite when F is singular or indefinite."""
    symbolic = symbolic or fim_symbolic(fim, ordering)
    return symbolic.factor_logdet(fim.matrix, name="paper FIM")[1]


def fim_logdet_accuracy(fim: PaperFim, factor: Any, logdet: float, graph: PoseGraph, rot: np.ndarray,
                        trans: np.ndarray) -> LogdetAccuracy:
    """How many digits of the FIM's ``logdet`` (computed with ``factor``) to trust
    (``posecrb.linalg.accuracy.logdet_accuracy``), with the covariance of a spanning tree's FIM at
    the same estimate ``(rot, trans)`` as the upper bound of the inverse's diagonal of its
    ``spanning_tree`` tier (``posecrb.models.paper.tree_inverse``), computed only when that tier
    runs. The factor's values are overwritten when a later tier needs an inertia check."""

    def inverse_diagonal() -> np.ndarray | None:
        z = tree_inverse_diagonal(graph, rot, trans, fim.anchor, fim.rotation_weight, fim.variant)
        if z is not None and fim.layout != "blocks":
            z = z[_layout_permutation(fim.n_free, fim.dim, fim.rot_dim, fim.layout)]
        return z

    return logdet_accuracy(factor, logdet, "paper FIM", matrix=fim.matrix, overwrite_factor=True,
                           inverse_diagonal=inverse_diagonal)


def trace_fim(fim: PaperFim) -> float:
    """T-optimality: exact trace(F) (eq. 69 / 70)."""
    return float(fim.matrix.diagonal().sum())
