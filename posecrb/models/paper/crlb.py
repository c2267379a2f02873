"""Cramér-Rao lower bounds of the paper's model (Chen et al., section VI).

2D (eq. 67): the parameter space (R^2 x SO(2))^{n_p} is flat, ``C >= F^{-1}``.
3D (eq. 68): ``C >= F^{-1} - (1/12) (ddiag(L~) F^{-1} + F^{-1} ddiag(L~))`` with
``L~ = blkdiag(0, (I^{SO(3)})^{-1})``, ``I^{SO(3)} = L_w^{SO(3)} + diag(Psi)`` the
rotation-rotation block of F (eq. 63-65), and ddiag keeping the 3 x 3 diagonal blocks.
F is the Fisher information of the model (``variant="consistent"``, the default) or
eq. (64) as printed (``variant="eq64"``), see ``posecrb.models.paper.fim``; the curvature term uses the
rotation-rotation block of whichever F is chosen. 2D: both variants coincide.

Everything is exact and sparse: the per-pose diagonal blocks of ``F^{-1}`` and the
3 x 3 diagonal blocks of ``(I^{SO(3)})^{-1}`` come from selected inversion on the
Cholesky factors (posecrb.linalg.selinv). Because ``ddiag(L~)`` is block diagonal,

    trace(eq. 68) = trace(F^{-1}) - (1/6) sum_i trace(D_i [F^{-1}]_{phi_i phi_i}),
    block_i(eq. 68) = C_i - (1/12) (D~_i C_i + C_i D~_i),   D~_i = blkdiag(0_3, D_i),

with ``C_i`` the i-th q x q diagonal block of ``F^{-1}`` and ``D_i`` that of
``(I^{SO(3)})^{-1}``.

Statuses (``posecrb.core.status``), never a silent number:

* eq. (68) is a second-order expansion in the rotation errors. Its correction
  ``(1/6) trace(D_i [C_i]_phi)`` is non-negative (trace of a product of two positive
  semidefinite matrices); where it reaches the first-order term ``trace(C_i)`` of some pose,
  the expansion does not hold (the corrected bound would be zero or negative) and the
  curvature-corrected values are *unavailable*; above ``CURVATURE_WARN`` of it they carry a
  *warning*.
* ``accuracy`` (``InverseAccuracy``): the normwise backward error of ``F x = e_k`` on a few
  sampled columns (fixed seed) and an estimate of the condition number of the diagonally
  scaled F, which governs the accuracy of a Cholesky-based inverse (van der Sluis): the
  relative error of the computed ``F^{-1}`` is at most about ``cond * eps``. Above
  ``ACCURACY_WARN`` the bound carries a warning; at 1 or more (no correct digit) or with a
  backward error far above round-off it is unavailable.
"""
from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from ...core.errors import ArgumentError
from ...core.graph import PoseGraph
from ...core.jsontypes import conform, is_status_json
from ...core.result import Result, plain
from ...core.status import OK, Status
from ...linalg.accuracy import onenorm_inverse
from ...linalg.cholesky import Factor
from ...linalg.ordering import block_cholesky, threaded_matrix
from ...linalg.selinv import _block_pattern_padded, inverse_block_diagonal
from ...linalg.threads import cholmod_single_threaded, load_aware_threads
from .fim import PaperFim, coordinate_names, paper_fim

# eq. (68): warn when the curvature correction exceeds this fraction of the first-order term
# at some pose (the neglected higher-order terms are then of the order of its square).
CURVATURE_WARN = 0.1
# Warn when the estimated relative error of the computed inverse exceeds this (fewer than
# six significant digits guaranteed in the largest entries of F^{-1}).
ACCURACY_WARN = 1e-6
# A Cholesky solve is backward stable: a normwise backward error above this means the
# factorization did not solve the system to working precision.
RESIDUAL_FAIL = 1e-10
ACCURACY_SEED = 0
ACCURACY_COLUMNS = 4


@dataclass(frozen=True)
class InverseAccuracy(Result):
    """How far the computed inverse of a sparse SPD matrix can be trusted.

    ``residual``: max over ``columns`` sampled unit vectors e_k (``numpy.random.default_rng(seed)``)
    of the normwise backward error ``||A x - e_k||_1 / (||A||_1 ||x||_1 + 1)`` of the solve with
    the Cholesky factor. ``condition_estimate``: 1-norm condition number of the diagonally scaled
    ``H = D^{-1/2} A D^{-1/2}`` (``D = diag A``; Hager-Higham estimate of ``||H^{-1}||_1``), which
    governs the accuracy of Cholesky-based inverses. ``error_bound = condition_estimate * eps``:
    estimated relative error of the computed inverse (normwise, in the scaled coordinates).
    ``condition_unscaled``: the same for A itself (what other tools print). ``status`` is a
    warning above an estimated relative error of 1e-6 and unavailable when no digit is
    guaranteed; ``to_dict()`` is the ``accuracy`` object of the ``crlb`` JSON.

    Examples
    --------
    >>> import posecrb
    >>> acc = posecrb.crlb("intel").accuracy
    >>> acc.status.ok, acc.columns, acc.error_bound < 1e-6
    (True, 4, True)
    """

    residual: float
    condition_estimate: float
    condition_unscaled: float
    error_bound: float
    columns: int
    status: Status = OK

    def to_dict(self) -> dict[str, Any]:
        """The ``accuracy`` object of the ``crlb`` JSON: the numbers, then the status flattened
        in (``status``, ``reason``[, ``hint``])."""
        out: dict[str, Any] = plain({
            "residual": self.residual, "condition_estimate": self.condition_estimate,
            "condition_unscaled": self.condition_unscaled, "error_bound": self.error_bound,
            "columns": self.columns, **self.status.as_json()})
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> InverseAccuracy:
        """The inverse of ``to_dict``, each value checked (``ArgumentError`` otherwise)."""
        if not isinstance(d, Mapping):
            raise ArgumentError("d", type(d).__name__, "is not a mapping (an InverseAccuracy dict)", sep=": ")
        numbers = {k: d.get(k) for k in ("residual", "condition_estimate", "condition_unscaled", "error_bound")}
        status = {k: v for k, v in d.items() if k not in (*numbers, "columns")}
        ok_status = status == {"status": "ok", "reason": None}
        if not (set(d) >= {*numbers, "columns"} and (ok_status or is_status_json(status))
                and isinstance(d["columns"], int) and not isinstance(d["columns"], bool)
                and all(conform(v, float)[0] for v in numbers.values())):
            raise ArgumentError("d", f"{{... {len(d)} keys}}", "is not an InverseAccuracy (residual, "
                                "condition_estimate, condition_unscaled, error_bound: numbers; columns: an integer; "
                                "a status)", sep=": ")
        value = {k: float(conform(v, float)[1]) for k, v in numbers.items()}
        return cls(value["residual"], value["condition_estimate"], value["condition_unscaled"], value["error_bound"],
                   d["columns"], OK if ok_status else Status.from_json(status))

    def statuses(self) -> dict[str, Status]:
        return {"CRLB": self.status}


def inverse_accuracy(a: sp.spmatrix, factor: Factor, name: str = "matrix", columns: int = ACCURACY_COLUMNS,
                     seed: int = ACCURACY_SEED, *, threaded: bool = False) -> InverseAccuracy:
    """Accuracy estimate of ``a^{-1}`` computed from ``factor`` (a CHOLMOD factor of ``a``).

    ``threaded``: ``a`` is a matrix whose factorization takes CHOLMOD's BLAS threads
    (``posecrb.linalg.ordering.threaded_matrix``); its solves here do too. Otherwise they run it at
    one thread: the estimate's dozen solves with one or a few right-hand sides go through small
    supernodes, where OpenBLAS's threads make them several times slower (posecrb.linalg.threads)."""
    with load_aware_threads() if threaded else cholmod_single_threaded():
        return _inverse_accuracy(a, factor, name, columns, seed)


def _inverse_accuracy(a: sp.spmatrix, factor: Factor, name: str, columns: int, seed: int) -> InverseAccuracy:
    a = sp.csc_matrix(a)
    n = a.shape[0]
    if n == 0:
        return InverseAccuracy(0.0, 1.0, 1.0, float(np.finfo(float).eps), 0)
    eps = float(np.finfo(float).eps)
    k = min(columns, n)
    cols = np.sort(np.random.default_rng(seed).choice(n, size=k, replace=False))
    e = np.zeros((n, k))
    e[cols, np.arange(k)] = 1.0
    with np.errstate(all="ignore"):
        x = np.asarray(factor(e)).reshape(n, k)
        anorm = float(abs(a).sum(axis=0).max())
        r = a @ x - e
        eta = float(np.max(np.abs(r).sum(axis=0) / (anorm * np.abs(x).sum(axis=0) + 1.0)))
        diag = a.diagonal()
        s = 1.0 / np.sqrt(diag)
        hnorm = float(abs(sp.diags(s) @ a @ sp.diags(s)).sum(axis=0).max())
        cond_s = hnorm * onenorm_inverse(lambda v: np.asarray(factor(v / s)).ravel() / s, n)
        cond = anorm * onenorm_inverse(lambda v: np.asarray(factor(v)).ravel(), n)
    bound = cond_s * eps
    if not (np.isfinite(eta) and np.isfinite(cond_s)) or eta > RESIDUAL_FAIL:
        status = Status.unavailable(
            f"the Cholesky factor of the {name} does not solve F x = e to working precision "
            f"(backward error {eta:.2g})", "check the information matrices for extreme values")
    elif bound >= 1.0:
        status = Status.unavailable(
            f"the {name} is numerically singular: scaled condition number about {cond_s:.2g}, so the "
            "computed inverse has no correct digit", "some poses are (nearly) unobservable; check the "
            "information matrices or the graph's connectivity")
    elif bound > ACCURACY_WARN:
        status = Status.warning(
            f"the {name} is ill-conditioned (scaled condition number about {cond_s:.2g}): entries of "
            f"its inverse may carry relative errors up to about {bound:.1g}",
            "treat the last digits of the bound as uncertain")
    else:
        status = OK
    return InverseAccuracy(eta, cond_s, cond, bound, k, status)


@dataclass(frozen=True, eq=False, kw_only=True)
class PaperCrlb:
    """CRLB of the paper model at one estimate.

    ``trace_crlb = trace(F^{-1})`` (the whole bound in 2D, the flat leading term in 3D) and
    ``mse_bound = trace_crlb / n_p`` (Fig. 6-7); in 3D ``trace_crlb_curvature`` /
    ``mse_bound_curvature`` are the same for the curvature-corrected bound eq. (68), None when
    ``curvature_status`` says it is unavailable. ``per_pose`` maps a pose id to its q x q block of
    ``F^{-1}`` and ``per_pose_curvature`` (3D) to its block of eq. (68); coordinates per pose are
    ``coordinates`` (translation first, then rotation; the anchor's block is zero).
    ``fim_variant`` is the FIM variant the bound was computed from (``posecrb.models.paper.fim.FIM_VARIANTS``);
    ``accuracy`` says how far the computed inverse can be trusted (``InverseAccuracy``).
    ``curvature_correction_max``: the largest ratio, over poses, of the eq. (68) correction to
    the first-order term of that pose (3D).
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
    fim_variant: str = "consistent"
    accuracy: InverseAccuracy | None = None
    curvature_status: Status = OK
    curvature_correction_max: float | None = None


def curvature_status(correction: np.ndarray, first_order: np.ndarray, pose_ids: np.ndarray) -> Status:
    """Validity of eq. (68) from the per-pose correction ``(1/6) trace(D_i [C_i]_phi)`` and the
    first-order term ``trace(C_i)`` (module docstring)."""
    with np.errstate(all="ignore"):
        rel = np.where(first_order > 0, correction / first_order, np.inf)
    if rel.size == 0:
        return OK
    worst = int(np.argmax(rel))
    bad = int(np.count_nonzero(~(rel < 1.0)))
    if bad:
        return Status.unavailable(
            f"the second-order curvature correction of eq. (68) reaches the first-order term at {bad} of "
            f"{rel.size} poses (pose {int(pose_ids[worst])}: {rel[worst]:.3g} times it), so the expansion "
            "does not hold at this noise level",
            "the rotation information is too small for an asymptotic bound; trace_crlb is the "
            "first-order bound")
    if rel[worst] > CURVATURE_WARN:
        return Status.warning(
            f"the curvature correction of eq. (68) is {rel[worst]:.2g} times the first-order term at pose "
            f"{int(pose_ids[worst])} (more than {CURVATURE_WARN:g}): the neglected higher-order terms "
            "may matter", "compare with trace_crlb")
    return OK


def _requested_ids(graph: PoseGraph, per_pose: bool | Sequence[int]) -> np.ndarray | None:
    if per_pose is False or per_pose is None:
        return None
    if per_pose is True:
        return graph.ids
    ids = np.asarray(list(per_pose), dtype=np.int64)
    for i in ids:  # validation only, over the requested ids (raises UsageError naming the id)
        graph.index_of(int(i))
    return ids


def crlb_blocks(fim: PaperFim, graph: PoseGraph, *, ordering: str = "auto"
                ) -> tuple[np.ndarray, InverseAccuracy | None, dict[str, float]]:
    """The first-order CRLB's marginal blocks (eq. 67; in 3D the leading term of eq. 68): the q x q
    diagonal blocks of F^{-1}, one per free pose in the order of ``fim.pose_ids``, by selected
    inversion; the inverse's accuracy estimate (None without free poses); and the stages' times
    (``crlb_blocks``, ``accuracy``). ``crlb_from_fim`` adds the traces and the curvature term;
    ``posecrb verify``'s per-pose distances need only these."""
    times: dict[str, float] = {}
    d, q = fim.dim, fim.q
    npf = fim.n_free
    t0 = time.perf_counter()
    fp = fim.to_layout("poses")
    factor = block_cholesky(_block_pattern_padded(fp.matrix, q), ordering, dim=d, poses=graph.n, matrix="crlb",
                            block=q, name="paper FIM") if npf else None
    blocks = inverse_block_diagonal(fp.matrix, q, name="paper FIM", factor=factor)   # (n_p, q, q) of F^{-1}
    times["crlb_blocks"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    accuracy = inverse_accuracy(fp.matrix, factor, "paper FIM", threaded=threaded_matrix(d, graph.n, "crlb")) \
        if npf else None
    times["accuracy"] = time.perf_counter() - t0
    return blocks, accuracy, times


def crlb_from_fim(fim: PaperFim, graph: PoseGraph, per_pose: bool | Sequence[int] = False, *,
                  ordering: str = "auto") -> PaperCrlb:
    """CRLB (eq. 67 / 68) from an already built paper FIM of ``graph``, with its accuracy
    estimate and the validity of the curvature term (module docstring). ``ordering``: the FIM
    factorization's fill-reducing ordering (posecrb.linalg.ordering; cost only)."""

    d, dr, q = fim.dim, fim.rot_dim, fim.q
    npf = fim.n_free
    blocks, accuracy, times = crlb_blocks(fim, graph, ordering=ordering)
    diag = np.einsum("kii->ki", blocks)
    tr_t, tr_r = float(diag[:, :d].sum()), float(diag[:, d:].sum())
    trace = tr_t + tr_r
    curv_blocks = None
    trace_curv = mse_curv = None
    status, worst = OK, None
    if d == 3:
        t1 = time.perf_counter()
        dblk = inverse_block_diagonal(fim.rotation_block(), dr, name="rotation block of the paper FIM")
        # D~_i C_i + C_i D~_i with D~_i = blkdiag(0_3, D_i)
        dfull = np.zeros((npf, q, q))
        dfull[:, d:, d:] = dblk
        corr = dfull @ blocks
        corr = corr + corr.transpose(0, 2, 1)
        correction = np.einsum("kij,kji->k", dblk, blocks[:, d:, d:]) / 6.0     # per pose, >= 0
        first = np.einsum("kii->k", blocks)
        status = curvature_status(correction, first, fim.pose_ids)
        with np.errstate(all="ignore"):
            rel = correction / first
        worst = float(np.max(rel)) if rel.size else 0.0
        if status.available:
            curv_blocks = blocks - corr / 12.0
            trace_curv = trace - float(correction.sum())
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
    return PaperCrlb(model="paper", dim=d, poses=graph.n, n_free=npf, anchor_id=fim.anchor_id, trace_crlb=trace,
                      mse_bound=trace / npf if npf else 0.0, trace_translation=tr_t, trace_rotation=tr_r,
                      trace_crlb_curvature=trace_curv, mse_bound_curvature=mse_curv,
                      coordinates=coordinate_names(d), per_pose=pp, per_pose_curvature=ppc, times=times,
                      fim_variant=fim.variant, accuracy=accuracy, curvature_status=status,
                      curvature_correction_max=worst)


def paper_crlb(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0,
               per_pose: bool | Sequence[int] = False, rotation_weight: str = "eq59",
               variant: str = "consistent", *, ordering: str = "auto") -> PaperCrlb:
    """CRLB of the paper model at the estimate ``(rot, trans)`` with pose ``anchor``
    (internal index) fixed: 2D eq. (67), 3D eq. (68). ``per_pose``: True for every pose,
    or a sequence of pose ids (as in the file). ``variant``: the FIM it inverts,
    ``"consistent"`` (the Fisher information of the model, the default: the bound the Monte
    Carlo MSE reaches in 3D) or ``"eq64"`` (as printed); see ``posecrb.models.paper.fim.paper_fim``.
    Raises DisconnectedGraph / NotPositiveDefinite."""
    t0 = time.perf_counter()
    fim = paper_fim(graph, rot, trans, anchor=anchor, rotation_weight=rotation_weight, layout="blocks",
                    variant=variant)
    t_build = time.perf_counter() - t0
    res = crlb_from_fim(fim, graph, per_pose, ordering=ordering)
    res.times["fim_build"] = t_build
    return res
