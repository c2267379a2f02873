"""The thesis's intrinsic Cramér-Rao bounds on SE(d)^n: anchored (thesis 5.1) and quotient (5.5), from the
Fisher information of posecrb.models.sed.fim (docs/design.md#anchored-crb, #quotient-crb).
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...core.errors import NotPositiveDefinite, UsageError
from ...core.graph import PoseGraph
from ...linalg import selinv
from ...linalg.ordering import block_cholesky, threaded_matrix
from ..paper.crlb import inverse_accuracy
from .fim import SedFim, _free_matrix, _resolve_anchors, sed_fim


@dataclass(frozen=True, eq=False)
class SedCrlb:
    """Anchored (5.1) or quotient (5.5) intrinsic CRLB of the sed model, curvature neglected."""

    model: str                     # "sed"
    kind: str                      # "anchored" | "quotient"
    dim: int
    q: int
    n: int
    trace_crlb: float
    mse_bound: float               # trace / (n - #anchors) anchored; trace / (n - components) quotient
    nullity: int
    components: int
    anchors: list[int]             # internal indices; "quotient": the one per component used for G
    per_pose: dict[int, np.ndarray] | None  # internal index -> (q, q) covariance bound block
    times: dict[str, float]
    frame: str = "world"           # coordinates of trace and blocks (posecrb.models.sed.frames): "world" | "body"
    accuracy: Any = None           # posecrb.models.paper.crlb.InverseAccuracy of the anchored inverse G


def sed_crlb(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchors: Sequence[int] | None = None,
            quotient: bool = False, per_pose: bool | Sequence[int] = False, *,
            fim: SedFim | None = None, indefinite: str = "blocks",
            information: np.ndarray | None = None, ordering: str = "auto") -> SedCrlb:
    """Intrinsic CRB of the SE(d)^n model at an estimate, exact from one sparse factorization.

    * anchored (default): ``(Pi F Pi)^+`` (5.1), the inverse of F on the free poses, zero on
      anchors. ``anchors`` are internal indices (``graph.ids[k]`` is the file id), at least one
      per connected component; default: the smallest index of each component. A component
      without an anchor raises ``UsageError`` naming it.
    * ``quotient=True``: ``F^+`` (5.5), independent of the anchors, computed as ``P G P`` from
      the anchored generalised inverse ``G`` (module docstring) with one anchor per component
      (the smallest given one, or the default).

    ``trace_crlb`` is the trace of the bound; ``mse_bound`` divides it by the number of poses
    that carry error: ``n - #anchors`` (anchored) or ``n - components`` (quotient; the quotient
    has dimension ``(n - c) q``, Sec. 5.3). ``per_pose`` (True for all, or a sequence of internal
    indices) returns the (q, q) diagonal blocks of the bound; anchored poses get zero blocks in
    the anchored bound. ``fim`` reuses a ``sed_fim`` result for the same estimate. ``ordering``: the
    factorizations' fill-reducing ordering (posecrb.linalg.ordering; cost only).
    """
    times: dict[str, float] = {}
    if fim is None:
        fim = sed_fim(graph, rot, trans, indefinite=indefinite, information=information, ordering=ordering)
    times.update(fim.times)
    q, n = fim.q, fim.n
    anchors_ = _resolve_anchors(graph, anchors)
    if quotient:
        # G must be a generalised inverse (F G F = F), which needs rank(F_ff) = rank(F):
        # exactly one anchor per component. Keep the smallest given anchor of each.
        lab = fim.component_labels[anchors_]
        anchors_ = [int(x) for x in np.asarray(anchors_)[np.unique(lab, return_index=True)[1]]]

    t0 = time.perf_counter()
    ff, free = _free_matrix(fim.matrix, n, q, anchors_)
    name = "SE(d) FIM on the free poses"
    if anchors_ == fim.anchors and fim.factor is not None:
        fac = fim.factor
    elif anchors_ == fim.anchors and not fim.logdet_status.available:
        raise NotPositiveDefinite(name, f"{fim.logdet_status.reason}; {fim.logdet_status.hint}")
    elif ff.shape[0]:
        fac = block_cholesky(ff, ordering, dim=graph.dim, poses=graph.n, matrix="crlb", block=q, name=name)
    else:
        fac = None
    times["crlb_factor"] = time.perf_counter() - t0

    if per_pose is True:
        want = np.arange(n)
    elif per_pose is False or per_pose is None:
        want = None
    else:
        want = np.unique(np.asarray(list(per_pose), dtype=np.int64))
        if want.size and (want[0] < 0 or want[-1] >= n):
            raise UsageError(f"pose index out of range 0..{n - 1}")
    need_blocks = want is not None

    # Diagonal blocks of G = F_ff^{-1} (selected inversion) or just its trace.
    t0 = time.perf_counter()
    g_blocks = np.zeros((n, q, q))
    if fac is None:
        trace_g = 0.0
    elif need_blocks:
        blocks = np.asarray(selinv.inverse_block_diagonal(ff, q, name, factor=fac))
        g_blocks[free] = blocks.reshape(free.size, q, q)
        trace_g = float(np.trace(blocks, axis1=-2, axis2=-1).sum())
    else:
        trace_g = float(selinv.trace_inverse(ff, name, factor=fac))
    times["crlb_selinv"] = time.perf_counter() - t0
    t0 = time.perf_counter()

    accuracy = inverse_accuracy(ff, fac, "SE(d) FIM on the free poses",
                                threaded=threaded_matrix(graph.dim, graph.n, "crlb")) if fac is not None else None
    times["accuracy"] = time.perf_counter() - t0

    c = fim.components
    if not quotient:
        trace = trace_g
        n_err = n - len(anchors_)
        out = g_blocks
        kind = "anchored"
    else:
        t0 = time.perf_counter()
        labels = fim.component_labels
        sizes = np.bincount(labels, minlength=c).astype(float)
        s_inv = 1.0 / np.sqrt(sizes[labels])                       # (n,)
        # G N: G is block diagonal over components, so all components share q right-hand
        # sides B = [I_q / sqrt(n_c(i))]_i and (G N)_i = Y_i restricted to pose i's component.
        y = np.zeros((n, q, q))
        if fac is not None:
            rhs = (s_inv[free, None, None] * np.eye(q)).reshape(free.size * q, q)
            y[free] = np.asarray(fac(rhs)).reshape(free.size, q, q)
        m_c = np.zeros((c, q, q))                                  # N_c^T G N_c
        np.add.at(m_c, labels, s_inv[:, None, None] * y)
        trace = trace_g - float(np.trace(m_c, axis1=1, axis2=2).sum())
        n_err = n - c
        out = None
        if need_blocks:
            yy = s_inv[:, None, None] * (y + np.swapaxes(y, 1, 2))
            out = g_blocks - yy + m_c[labels] / sizes[labels][:, None, None]
        times["crlb_quotient"] = time.perf_counter() - t0
        kind = "quotient"

    per = None
    if want is not None and out is not None:  # need_blocks
        per = {int(i): out[i] for i in want}
    return SedCrlb(
        model="sed", kind=kind, dim=fim.dim, q=q, n=n, trace_crlb=trace,
        mse_bound=trace / n_err if n_err > 0 else float("nan"),
        nullity=fim.nullity, components=c, anchors=anchors_, per_pose=per, times=times, accuracy=accuracy)
