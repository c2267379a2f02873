"""Cramér-Rao lower bounds of the paper's model (Chen et al., section VI).

2D (eq. 67): the parameter space (R^2 x SO(2))^{n_p} is flat, ``C >= F^{-1}``.
3D (eq. 68): ``C >= F^{-1} - (1/12) (ddiag(L~) F^{-1} + F^{-1} ddiag(L~))`` with
``L~ = blkdiag(0, (I^{SO(3)})^{-1})``, ``I^{SO(3)} = L_w^{SO(3)} + diag(Psi)`` the
rotation-rotation block of F (eq. 63-65), and ddiag keeping the 3 x 3 diagonal blocks.
F is eq. (64) as printed (``variant="eq64"``) or the frame-consistent Fisher information
of the same model (``variant="consistent"``, see ``posecrb.fim``); the curvature term
uses the rotation-rotation block of whichever F is chosen. 2D: both variants coincide.

Everything is exact and sparse: the per-pose diagonal blocks of ``F^{-1}`` and the
3 x 3 diagonal blocks of ``(I^{SO(3)})^{-1}`` come from selected inversion on the
Cholesky factors (posecrb.selinv). Because ``ddiag(L~)`` is block diagonal,

    trace(eq. 68) = trace(F^{-1}) - (1/6) sum_i trace(D_i [F^{-1}]_{phi_i phi_i}),
    block_i(eq. 68) = C_i - (1/12) (D~_i C_i + C_i D~_i),   D~_i = blkdiag(0_3, D_i),

with ``C_i`` the i-th q x q diagonal block of ``F^{-1}`` and ``D_i`` that of
``(I^{SO(3)})^{-1}``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .fim import PaperFim, coordinate_names, paper_fim
from .graph import PoseGraph
from .selinv import inverse_block_diagonal


@dataclass(frozen=True, eq=False)
class CrlbResult:
    """CRLB of the paper model at one estimate.

    ``trace_crlb = trace(F^{-1})`` (the whole bound in 2D, the flat leading term in 3D) and
    ``mse_bound = trace_crlb / n_p`` (Fig. 6-7); in 3D ``trace_crlb_curvature`` /
    ``mse_bound_curvature`` are the same for the curvature-corrected bound eq. (68).
    ``per_pose`` maps a pose id to its q x q block of ``F^{-1}`` and ``per_pose_curvature``
    (3D) to its block of eq. (68); coordinates per pose are ``coordinates`` (translation
    first, then rotation; the anchor's block is zero). ``fim_variant`` is the FIM variant
    the bound was computed from (``posecrb.fim.FIM_VARIANTS``).
    """

    model: str
    dim: int
    poses: int                    # n
    n_free: int                   # n_p = n - 1
    anchor_id: int
    trace_crlb: float
    mse_bound: float
    trace_translation: float      # part of trace(F^{-1}) on translations
    trace_rotation: float         # part on rotations
    trace_crlb_curvature: float | None
    mse_bound_curvature: float | None
    coordinates: list[str]
    per_pose: dict[int, np.ndarray] | None = None
    per_pose_curvature: dict[int, np.ndarray] | None = None
    times: dict[str, float] = field(default_factory=dict)
    fim_variant: str = "eq64"


def _requested_ids(graph: PoseGraph, per_pose: bool | Sequence[int]) -> np.ndarray | None:
    if per_pose is False or per_pose is None:
        return None
    if per_pose is True:
        return graph.ids
    ids = np.asarray(list(per_pose), dtype=np.int64)
    for i in ids:  # validation only, over the requested ids (raises UsageError naming the id)
        graph.index_of(int(i))
    return ids


def crlb_from_fim(fim: PaperFim, graph: PoseGraph, per_pose: bool | Sequence[int] = False) -> CrlbResult:
    """CRLB (eq. 67 / 68) from an already built paper FIM of ``graph``."""
    times: dict[str, float] = {}
    d, dr, q = fim.dim, fim.rot_dim, fim.q
    npf = fim.n_free
    t0 = time.perf_counter()
    fp = fim.to_layout("poses")
    blocks = inverse_block_diagonal(fp.matrix, q, name="paper FIM")         # (n_p, q, q) of F^{-1}
    times["crlb_blocks"] = time.perf_counter() - t0
    diag = np.einsum("kii->ki", blocks)
    tr_t, tr_r = float(diag[:, :d].sum()), float(diag[:, d:].sum())
    trace = tr_t + tr_r
    curv_blocks = None
    trace_curv = mse_curv = None
    if d == 3:
        t1 = time.perf_counter()
        dblk = inverse_block_diagonal(fim.rotation_block(), dr, name="rotation block of the paper FIM")
        # D~_i C_i + C_i D~_i with D~_i = blkdiag(0_3, D_i)
        dfull = np.zeros((npf, q, q))
        dfull[:, d:, d:] = dblk
        corr = dfull @ blocks
        corr = corr + corr.transpose(0, 2, 1)
        curv_blocks = blocks - corr / 12.0
        trace_curv = trace - float(np.einsum("kij,kji->", dblk, blocks[:, d:, d:])) / 6.0
        mse_curv = trace_curv / npf if npf else 0.0
        times["curvature"] = time.perf_counter() - t1

    ids = _requested_ids(graph, per_pose)
    pp = ppc = None
    if ids is not None:
        row = np.searchsorted(fim.pose_ids, ids)
        row = np.minimum(row, npf - 1)
        free = fim.pose_ids[row] == ids
        zero = np.zeros((q, q))
        pp = {int(i): (blocks[r] if f else zero) for i, r, f in zip(ids, row, free)}
        if curv_blocks is not None:
            ppc = {int(i): (curv_blocks[r] if f else zero) for i, r, f in zip(ids, row, free)}
    return CrlbResult("paper", d, graph.n, npf, fim.anchor_id, trace, trace / npf if npf else 0.0, tr_t, tr_r,
                      trace_curv, mse_curv, coordinate_names(d), pp, ppc, times, fim_variant=fim.variant)


def paper_crlb(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0,
               per_pose: bool | Sequence[int] = False, rotation_model: str = "eq59",
               variant: str = "eq64") -> CrlbResult:
    """CRLB of the paper model at the estimate ``(rot, trans)`` with pose ``anchor``
    (internal index) fixed: 2D eq. (67), 3D eq. (68). ``per_pose``: True for every pose,
    or a sequence of pose ids (as in the file). ``variant``: the FIM it inverts,
    ``"eq64"`` (as printed, the default) or ``"consistent"`` (the Fisher information of the
    model, the bound the Monte Carlo MSE reaches in 3D); see ``posecrb.fim.paper_fim``.
    Raises DisconnectedGraph / NotPositiveDefinite."""
    t0 = time.perf_counter()
    fim = paper_fim(graph, rot, trans, anchor=anchor, rotation_model=rotation_model, layout="blocks",
                    variant=variant)
    t_build = time.perf_counter() - t0
    res = crlb_from_fim(fim, graph, per_pose)
    res.times["fim_build"] = t_build
    return res
