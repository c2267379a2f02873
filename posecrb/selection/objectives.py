"""The objectives of measurement selection as functions of edge weights ``x in [0, 1]^m``.

* ``tree``: the paper's lower bound ``d logdet L_tau + d_r logdet L_w`` (eq. 75, Algorithm 1),
  the weighted tree-connectivity of the translation and rotation graphs;
* ``fim``: ``logdet F`` of the anchored Fisher information (eq. 42 / 64, frame-consistent
  rotation coupling, docs/design.md#paper-fim) at a fixed estimate, by default the
  certified optimum of the full graph;
* ``fiedler``: the algebraic connectivity ``lambda_2`` of the rotation-weighted Laplacian
  (the objective of MAC, Doherty et al. 2022), for comparison.

Both log-det objectives have the form ``f(x) = sum_b c_b logdet(M_b0 + sum_e x_e U_e U_e^T)``
(``LogDetObjective``, one ``LogDetBlock`` per term): for ``tree`` ``U_e = sqrt(w_e) (e_i - e_j)``
(reduced incidence, one column) in L_tau (c = d) and in L_w (c = d_r); for ``fim`` ``U_e`` is the
edge's ``q`` columns of ``J^T Omega^{1/2}`` (translation residual and relative rotation,
anchored), so ``F = sum_e U_e U_e^T``. With ``H_e = U_e^T M^{-1} U_e`` (``w_e r_e`` for a
Laplacian, r_e the effective resistance) the marginal gain of e is ``logdet(I + H_e)`` and the
gradient of the relaxation ``trace(H_e)``. Every ``H_e`` for all candidates at once comes from one
selected inversion (Takahashi recurrences, ``posecrb.linalg.selinv``) of a factor whose pattern is
that of the FULL graph: the matrices are assembled with explicit zeros for unselected edges, so one
CHOLMOD analysis serves every subset and the pattern holds every candidate's (i, j) block.

``FiedlerObjective`` evaluates ``lambda_2`` by the Rayleigh quotient ``R(v)`` of the computed unit
Fiedler vector v orthogonal to 1, and its supergradient ``g_e = w_e (v_i - v_j)^2``:
``lambda_2(x') <= R(v) + g^T (x' - x)`` holds whatever the eigensolver's accuracy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp

from ..core.choices import OBJECTIVES
from ..core.errors import InternalError, NumericalError, UsageError
from ..core.graph import PoseGraph
from ..core.noise import isotropic_precisions, rotation_weights
from ..linalg.cholesky import Factor, SymbolicCholesky
from ..linalg.lanczos import largest_eigenpair
from ..linalg.laplacian import laplacian, reduced_index
from ..linalg.selinv import SelectedInverse
from ..models.paper.fim import rotation_jacobians
from ..solver.estimate import Estimate

# From this many rows on, the symbolic analysis uses METIS (less fill on pose graphs, as in selinv).
_METIS_FROM = 4000
# Dense eigensolver for lambda_2 up to this many poses.
_DENSE_EIG_UP_TO = 300
# lambda_2 beyond that: Lanczos on L^+ to this relative residual (ARPACK's criterion), at most this
# many bases of 20 vectors.
_EIG_TOL = 1e-10
_EIG_RESTARTS = 250
# H_e of many edges by whole-factor solves (``LogDetBlock.h_solve``) instead of a selected inversion
# when the block's rows times the edges' columns stay within this many entries: a solve with those
# right-hand sides then costs less than loading numba in a fresh process, which the selected
# inversion's compiled kernels would (posecrb.linalg.selinv, docs/decisions/selection-at-scale.md).
# Solved in batches of this many entries.
H_SOLVE_ENTRIES = 4_000_000


def logdet_eye_plus(h: np.ndarray) -> np.ndarray:
    """``logdet(I + H)`` for each symmetric positive semidefinite ``H`` of ``h`` (k, r, r): ``log1p`` for
    r = 1, else twice the log-diagonal of the Cholesky factor of ``I + (H + H^T) / 2`` (at least I,
    so the factorization exists), with numpy (no compiled kernel: no numba to load)."""
    if h.shape[1] == 1:
        return np.log1p(np.maximum(h[:, 0, 0], 0.0))
    eye = np.eye(h.shape[1])
    chol = np.linalg.cholesky(eye + 0.5 * (h + np.swapaxes(h, 1, 2)))
    return 2.0 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)


@dataclass(eq=False)
class LogDetBlock:
    """One term ``mult * logdet(sum_e x_e U_e U_e^T) + const`` with a fixed (full-graph) pattern."""

    name: str
    size: int
    mult: float
    const: float
    rows: np.ndarray       # (m, p) row of each U_e row; anchored rows -> 0 (with zero U)
    valid: np.ndarray      # (m, p) row is not anchored
    U: np.ndarray          # (m, p, r)

    def __post_init__(self):
        p = self.U.shape[1]
        self.G = np.einsum("mpa,mqa->mpq", self.U, self.U)
        rr = np.repeat(self.rows, p, axis=1).ravel()
        cc = np.tile(self.rows, (1, p)).ravel()
        keep = (np.repeat(self.valid, p, axis=1) & np.tile(self.valid, (1, p))).ravel()
        keys = cc[keep] * self.size + rr[keep]
        uniq, self._inv = np.unique(keys, return_inverse=True)
        self._keep = keep
        self.indices = (uniq % self.size).astype(np.int32)
        self.indptr = np.searchsorted(uniq // self.size, np.arange(self.size + 1)).astype(np.int32)
        pattern = self._csc(np.ones(uniq.size))
        method = "metis" if self.size >= _METIS_FROM else "default"
        try:
            self.symbolic = SymbolicCholesky(pattern, mode="auto", ordering_method=method)
        except Exception:  # pragma: no cover - CHOLMOD without METIS
            self.symbolic = SymbolicCholesky(pattern)

    def _csc(self, data: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.size, self.size))

    def matrix(self, x: np.ndarray) -> sp.csc_matrix:
        """``sum_e x_e U_e U_e^T`` on the full pattern (zero weights stay explicit entries)."""
        vals = (x[:, None, None] * self.G).ravel()[self._keep]
        return self._csc(np.bincount(self._inv, weights=vals, minlength=self.indices.size))

    def factor(self, x: np.ndarray) -> tuple[Factor, float]:
        return self.symbolic.factor_logdet(self.matrix(x), name=self.name)

    def solves_suffice(self, edges: int) -> bool:
        """Whether ``h_many`` takes ``edges`` edges' ``H_e`` from whole-factor solves (``H_SOLVE_ENTRIES``)."""
        return self.size * edges * self.U.shape[2] <= H_SOLVE_ENTRIES

    def h_many(self, factor: Factor, edges: np.ndarray) -> np.ndarray:
        """``H_e = U_e^T M^{-1} U_e`` for many edges: by solves with the factor on small blocks
        (``solves_suffice``), by one selected inversion otherwise. Both are exact up to rounding."""
        if not self.solves_suffice(edges.size):
            return self.h_selected(factor, edges)
        r = self.U.shape[2]
        if edges.size == 0:
            return np.zeros((0, r, r))
        batch = max(1, H_SOLVE_ENTRIES // (self.size * r))
        return np.concatenate([self.h_solve(factor, edges[i:i + batch]) for i in range(0, edges.size, batch)])

    def h_selected(self, factor: Factor, edges: np.ndarray) -> np.ndarray:
        """``H_e = U_e^T M^{-1} U_e`` for many edges from one selected inversion."""

        sel = SelectedInverse(factor, self.name, repeated=True)   # one per iteration of a selection
        rows, U, valid = self.rows[edges], self.U[edges], self.valid[edges]
        k, p, _ = U.shape
        r = np.repeat(rows, p, axis=1).ravel()
        c = np.tile(rows, (1, p)).ravel()
        ok = (np.repeat(valid, p, axis=1) & np.tile(valid, (1, p))).ravel()
        s: np.ndarray = np.zeros(r.size)
        s[ok] = sel.entries(r[ok], c[ok])
        if np.isnan(s).any():  # pragma: no cover - the pattern holds every edge's block
            raise InternalError(f"{self.name}: an edge block is missing from the factor's pattern")
        s = s.reshape(k, p, p)
        return np.einsum("kpa,kpq,kqb->kab", U, s, U)

    def rhs(self, edges: np.ndarray) -> np.ndarray:
        """Dense ``[U_e1, U_e2, ...]`` (size x r*len(edges)). Within one edge the valid rows are
        distinct poses' rows, and edges have their own columns, so plain assignment suffices."""
        k = edges.size
        p, r = self.U.shape[1:]
        out = np.zeros((self.size, r * k))
        valid = self.valid[edges]
        rows = np.broadcast_to(self.rows[edges][:, :, None], (k, p, r))[valid]
        cols = np.broadcast_to((np.arange(k)[:, None] * r)[:, :, None] + np.arange(r), (k, p, r))[valid]
        out[rows, cols] = self.U[edges][valid]
        return out

    def h_solve(self, factor: Factor, edges: np.ndarray) -> np.ndarray:
        """``H_e`` by solves with the current (possibly updated) factor."""
        b = self.rhs(edges)
        y = factor.solve_A(b)
        k = edges.size
        r = self.U.shape[2]
        return np.einsum("ska,skb->kab", b.reshape(self.size, k, r), y.reshape(self.size, k, r))

    def update(self, factor: Factor, e: int) -> None:
        """Factor of ``M + U_e U_e^T`` in place (CHOLMOD rank-r update)."""
        rows, U, valid = self.rows[e], self.U[e], self.valid[e]
        r = U.shape[1]
        order = np.argsort(rows[valid])           # an edge's valid rows are distinct poses' rows
        vals = U[valid][order]                    # (rows, r): column j of U_e at the sorted rows
        c = sp.csc_matrix((vals.T.ravel(), np.tile(rows[valid][order], r), np.arange(r + 1) * order.size),
                          shape=(self.size, r))
        factor.update_inplace(c)

    def h_projected(self, factor: Factor, x: np.ndarray, edges: np.ndarray, k: int,
                    rng: np.random.Generator) -> np.ndarray:
        """Johnson-Lindenstrauss estimate of ``H_e``: with ``M = W W^T``, ``W = [sqrt(x_e) U_e]``,
        ``H_e = ||W^T M^{-1} U_e||^2 ~ ||Q W^T M^{-1} U_e||^2`` for a k-row Gaussian Q (k solves)."""
        m, _, r = self.U.shape
        q = rng.standard_normal((m, r, k)) / np.sqrt(k)
        wq = np.zeros((self.size, k))
        contrib = np.einsum("mpr,mrk->mpk", np.sqrt(x)[:, None, None] * self.U, q)
        np.add.at(wq, self.rows, contrib)
        y = factor.solve_A(wq)                                # M^{-1} W Q^T
        a = np.einsum("epk,epr->ekr", y[self.rows[edges]], self.U[edges])
        return np.einsum("eka,ekb->eab", a, a)


@dataclass
class ObjectiveState:
    """An objective evaluated at x (and what the gradient needs)."""

    x: np.ndarray
    value: float
    data: Any = None


class LogDetObjective:
    """``f(x) = sum_b mult_b logdet(M_b(x)) + const_b`` over edge weights x in [0, 1]^m."""

    kind: Literal["logdet"] = "logdet"

    def __init__(self, name: str, blocks: list[LogDetBlock], m: int, src: np.ndarray | None = None,
                 dst: np.ndarray | None = None, n: int | None = None):
        self.name, self.blocks, self.m = name, blocks, m
        # the edges' end poses (indices) and the pose count: the round greedy's local model walks the graph
        self.src = None if src is None else np.asarray(src, dtype=np.int64)
        self.dst = None if dst is None else np.asarray(dst, dtype=np.int64)
        self.n = n

    def evaluate(self, x: np.ndarray) -> ObjectiveState:
        facs = [b.factor(x) for b in self.blocks]
        val = sum(b.mult * ld + b.const for b, (_, ld) in zip(self.blocks, facs))
        return ObjectiveState(np.array(x, dtype=float), float(val), [f for f, _ in facs])

    def value(self, x: np.ndarray) -> float:
        return self.evaluate(x).value

    def _h(self, state: ObjectiveState, edges: np.ndarray) -> list[np.ndarray]:
        return [b.h_many(f, edges) for b, f in zip(self.blocks, state.data)]

    def gains(self, state: ObjectiveState, edges: np.ndarray) -> np.ndarray:
        """Exact marginal gains ``sum_b mult_b logdet(I + H_be)`` (``LogDetBlock.h_many`` per block)."""
        return sum((b.mult * logdet_eye_plus(h) for b, h in zip(self.blocks, self._h(state, edges))),
                   np.zeros(edges.size))

    def gradient(self, state: ObjectiveState, edges: np.ndarray) -> np.ndarray:
        """``df/dx_e = sum_b mult_b trace(H_be)``, by selected inversion whatever the block's size: the
        relaxation takes it at every iteration, which share the compiled kernels' one-time cost (on
        intel one selected inversion took about a fifth of the solves ``h_many`` would make)."""
        return sum(b.mult * np.trace(b.h_selected(f, edges), axis1=1, axis2=2)
                   for b, f in zip(self.blocks, state.data))

    def gains_projected(self, state: ObjectiveState, edges: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """Marginal gains from the random-projection estimates of ``H_e`` (``LogDetBlock.h_projected``)."""
        return sum((b.mult * logdet_eye_plus(b.h_projected(f, state.x, edges, k, rng))
                    for b, f in zip(self.blocks, state.data)), np.zeros(edges.size))


def tree_objective(graph: PoseGraph, anchor: int = 0, rotation_weight: str = "eq59") -> LogDetObjective:
    """eq. (75) lower bound ``d logdet L_tau + d_r logdet L_w`` as a function of edge weights.

    When ``w = c tau`` on every edge (uniform noise, e.g. city10000) ``L_w = c L_tau`` and the
    objective is ``(d + d_r) logdet L_tau + d_r (n - 1) log c``: one factor instead of two."""

    tau, kappa = isotropic_precisions(graph.info, graph.dim)
    w = rotation_weights(kappa, graph.dim, rotation_weight)
    d, dr, n1 = graph.dim, graph.rot_dim, graph.n - 1
    red = reduced_index(graph.n, anchor)
    rows = np.stack([red[graph.src], red[graph.dst]], axis=1)
    valid = rows >= 0
    rows = np.where(valid, rows, 0)
    sign = np.array([1.0, -1.0])

    def block(name, weight, mult, const=0.0):
        u = (np.sqrt(weight)[:, None] * sign[None, :] * valid)[:, :, None]
        return LogDetBlock(name, n1, float(mult), float(const), rows, valid, u)

    ratio = w / tau
    if np.ptp(ratio) <= 1e-13 * abs(ratio.mean()):
        c = float(ratio.mean())
        blocks = [block("reduced Laplacians L_tau = L_w / c", tau, d + dr, dr * n1 * math.log(c))]
    else:
        blocks = [block("reduced translation Laplacian L_tau", tau, d),
                  block("reduced rotation Laplacian L_w", w, dr)]
    return LogDetObjective("tree", blocks, graph.m, graph.src, graph.dst, graph.n)


def edge_information_factors(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0,
                             variant: str = "consistent", rotation_weight: str = "eq59"
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per edge, the rows and columns ``U_e`` with ``F = sum_e U_e U_e^T`` (anchored FIM, "poses" layout).

    Rows of pose k are ``k' q .. k' q + q - 1`` (k' its reduced index): ``[x (d), theta (d_r)]``.
    Columns: d translation columns ``sqrt(tau) J_t^T`` with ``J_t = [-R_i^T, R_i^T, D]`` on
    ``(x_i, x_j, theta_i)`` (the Jacobian of ``R_i^T (x_j - x_i) - p_ij``, posecrb.models.paper.fim), and d_r
    rotation columns ``sqrt(w) [I; -R_j^T R_i]`` on ``(theta_i, theta_j)``: ``U U^T`` gives the
    diagonal blocks ``w I`` and the coupling ``-w R_i^T R_j`` of the frame-consistent FIM
    (``-w I`` for ``variant="eq64"``, eq. 61-62 as printed). Returns (rows (m, 2q), valid, U (m, 2q, q)).
    """

    d, dr, q = graph.dim, graph.rot_dim, graph.q
    tau = graph.tau
    w = graph.rotation_weights_by(rotation_weight)
    ri, dmat = rotation_jacobians(graph, rot, trans)
    m = graph.m
    u = np.zeros((m, 2 * q, q))
    st = np.sqrt(tau)[:, None, None]
    sw = np.sqrt(w)[:, None, None]
    u[:, 0:d, 0:d] = -st * ri                                   # x_i rows: (-R_i^T)^T
    u[:, d:q, 0:d] = st * np.transpose(dmat, (0, 2, 1))         # theta_i rows: D^T
    u[:, q:q + d, 0:d] = st * ri                                # x_j rows: R_i
    u[:, d:q, d:q] = sw * np.eye(dr)                            # theta_i rows: I
    if variant == "consistent" and d == 3:
        rel = np.transpose(rot[graph.dst], (0, 2, 1)) @ rot[graph.src]   # R_j^T R_i
        u[:, q + d:, d:q] = -sw * rel
    elif variant in ("eq64", "consistent"):
        u[:, q + d:, d:q] = -sw * np.eye(dr)
    else:
        raise UsageError(f"unknown FIM variant {variant!r}")
    red = reduced_index(graph.n, anchor)
    pi, pj = red[graph.src], red[graph.dst]
    rows = np.concatenate([pi[:, None] * q + np.arange(q), pj[:, None] * q + np.arange(q)], axis=1)
    valid = np.concatenate([np.repeat((pi >= 0)[:, None], q, 1), np.repeat((pj >= 0)[:, None], q, 1)], axis=1)
    u[~valid] = 0.0
    return np.where(valid, rows, 0), valid, u


def fim_objective(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0,
                  variant: str = "consistent") -> LogDetObjective:
    """``logdet F`` of the anchored FIM at the estimate ``(rot, trans)`` (eq. 42 / 64, frame-consistent)."""
    rows, valid, u = edge_information_factors(graph, rot, trans, anchor, variant)
    return LogDetObjective("fim", [LogDetBlock("anchored FIM", (graph.n - 1) * graph.q, 1.0, 0.0, rows, valid, u)],
                           graph.m, graph.src, graph.dst, graph.n)


class FiedlerObjective:
    """``lambda_2`` of the full Laplacian ``sum_e x_e w_e (e_i - e_j)(e_i - e_j)^T``."""

    kind: Literal["fiedler"] = "fiedler"

    def __init__(self, graph: PoseGraph, weights: np.ndarray, anchor: int = 0):
        self.n, self.m = graph.n, graph.m
        self.src, self.dst = graph.src, graph.dst
        self.w = np.asarray(weights, float)
        self.anchor = anchor
        red = reduced_index(graph.n, anchor)
        rows = np.stack([red[graph.src], red[graph.dst]], axis=1)
        valid = rows >= 0
        u = (np.sqrt(self.w)[:, None] * np.array([1.0, -1.0]) * valid)[:, :, None]
        self._block = None if self.n <= _DENSE_EIG_UP_TO else LogDetBlock(
            "reduced Laplacian (lambda_2)", self.n - 1, 1.0, 0.0, np.where(valid, rows, 0), valid, u)
        self._free = np.flatnonzero(np.arange(self.n) != anchor)

    def _rayleigh(self, x: np.ndarray, v: np.ndarray) -> tuple[float, np.ndarray]:
        v = v - v.mean()
        v = v / np.linalg.norm(v)
        dv = v[self.src] - v[self.dst]
        return float(np.dot(x * self.w, dv * dv)), v

    def evaluate(self, x: np.ndarray, v0: np.ndarray | None = None) -> ObjectiveState:
        """Value = Rayleigh quotient of the computed unit Fiedler vector (>= lambda_2, equal to
        it up to the eigensolver's tolerance squared)."""
        if self._block is None:
            lap = laplacian(self.n, self.src, self.dst, x * self.w).toarray()
            _, vecs = np.linalg.eigh(lap)
            val, v = self._rayleigh(x, vecs[:, 1])
            return ObjectiveState(np.array(x, float), val, v)

        factor, _ = self._block.factor(x)
        free, n = self._free, self.n

        def apply(y):
            y = np.asarray(y, float).ravel()
            y = y - y.mean()
            out = np.zeros(n)
            out[free] = factor.solve_A(y[free])
            return out - out.mean()

        # deterministic start: the previous Fiedler vector, else the slowest cosine along the ids
        start = np.cos(np.linspace(0.0, np.pi, n)) if v0 is None else np.asarray(v0, float).copy()
        start -= start.mean()
        # apply is L^+ (the grounded inverse, centred), whose largest eigenvalue is 1 / lambda_2.
        # Lanczos tests convergence after every product: from the previous Fiedler vector (a
        # warm start after a small change of x) it stops after ~10 solves where ARPACK, which
        # tests only when its basis of 20 is full, needed 21.
        ritz = largest_eigenpair(apply, start, tol=_EIG_TOL, max_restarts=_EIG_RESTARTS)
        if not ritz.converged:
            raise NumericalError(f"lambda_2: Lanczos did not converge (residual {ritz.residual:.2g} after "
                                 f"{ritz.matvecs} solves with the {self._block.name})")
        val, v = self._rayleigh(x, ritz.vector)
        return ObjectiveState(np.array(x, float), val, v)

    def value(self, x: np.ndarray) -> float:
        return self.evaluate(x).value

    def gradient(self, state: ObjectiveState, edges: np.ndarray) -> np.ndarray:
        v = state.data
        dv = v[self.src[edges]] - v[self.dst[edges]]
        return self.w[edges] * dv * dv


def make_objective(graph: PoseGraph, objective: str, anchor: int = 0, estimate: Estimate | None = None,
                   fiedler_weight: str = "w", rotation_weight: str = "eq59") -> LogDetObjective | FiedlerObjective:
    """The objective as a function of edge weights (all m edges)."""
    if objective == "tree":
        return tree_objective(graph, anchor, rotation_weight)
    if objective == "fim":
        if estimate is None:
            raise UsageError("the fim objective needs an estimate")
        return fim_objective(graph, estimate.rot, estimate.trans, anchor)
    if objective == "fiedler":
        if fiedler_weight == "w":
            weights = rotation_weights(graph.kappa, graph.dim, rotation_weight)
        elif fiedler_weight == "kappa":
            weights = graph.kappa
        else:
            raise UsageError(f"fiedler weight must be w or kappa, not {fiedler_weight!r}")
        return FiedlerObjective(graph, weights, anchor)
    raise UsageError(f"unknown objective {objective!r}; choose from {', '.join(OBJECTIVES)}")

