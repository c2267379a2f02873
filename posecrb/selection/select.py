"""Measurement selection: keep K of a pose graph's candidate edges, with a certificate.

The paper's section VIII-B: D-optimal measurement selection (the k-ESP+ problem of
Khosoussi et al.) becomes cheap with the graph-only bounds, and extends to 3D (eq. 75).
Given fixed edges F (default: the odometry chain) and candidates C, choose S within C,
|S| = K, maximising one of

* ``tree``: the paper's lower bound ``d logdet L_tau + d_r logdet L_w`` (eq. 75, Algorithm 1),
  the weighted tree-connectivity of the translation and rotation graphs;
* ``fim``: ``logdet F`` of the anchored Fisher information (eq. 42 / 64, frame-consistent
  rotation coupling, docs/design.md#paper-fim) at a fixed estimate, by default the
  certified optimum of the full graph;
* ``fiedler``: the algebraic connectivity ``lambda_2`` of the rotation-weighted Laplacian
  (the objective of MAC, Doherty et al. 2022), for comparison.

Both log-det objectives have the form ``f(x) = sum_b c_b logdet(M_b0 + sum_e x_e U_e U_e^T)``:
for ``tree`` ``U_e = sqrt(w_e) (e_i - e_j)`` (reduced incidence, one column) in L_tau (c = d)
and in L_w (c = d_r); for ``fim`` ``U_e`` is the edge's ``q`` columns of ``J^T Omega^{1/2}``
(translation residual and relative rotation, anchored), so ``F = sum_e U_e U_e^T``. With
``H_e = U_e^T M^{-1} U_e`` (``w_e r_e`` for a Laplacian, r_e the effective resistance):

* the marginal gain of e is ``logdet(I + H_e)`` (``log(1 + w_e r_e)``) and f is monotone
  submodular, so greedy keeps ``(1 - 1/e)`` of the optimal gain and, for any set S,
  ``f(OPT) <= f(S) + (sum of the K largest gains at S)``;
* the gradient of the relaxation ``x in [0, 1]^C, sum x = K`` is ``trace(H_e)``; f is
  concave there, so at any point ``f(x) + max_s grad^T (s - x)`` (the Frank-Wolfe duality
  gap added to the value) bounds the relaxation's optimum, hence the best K-subset.

Every ``H_e`` for all candidates at once comes from one selected inversion (Takahashi
recurrences, ``posecrb.linalg.selinv``) of a factor whose pattern is that of the FULL graph: the
matrices are assembled with explicit zeros for unselected edges, so one CHOLMOD analysis
serves every subset and the pattern holds every candidate's (i, j) block. The greedy keeps every
``H_f`` exact from step to step by the Woodbury identity (one solve ``M^{-1} U_e`` per accepted
edge, posecrb.linalg.pathchol) and updates the factor in place by rank-one updates along the
elimination-tree path of the edge, never refactorising per candidate; the textbook lazy greedy
(priority queue, stale gains re-evaluated by path solves, optionally seeded by random
projections) is kept as ``strategy="lazy"``. The submodular bound is the smallest Minoux bound
over the final set and ~64 of the greedy's intermediate sets.

The fiedler objective is concave in x but not submodular; its greedy is MAC's GreedyEig
(candidates evaluated in the order of the supergradient bound ``R(v) + g_e``) and its
relaxation MAC's Frank-Wolfe (start at the heaviest edges, step ``2/(t+2)``). Its bounds
use the Rayleigh quotient ``R(v) >= lambda_2`` of the computed unit vector v orthogonal to
1, for which ``lambda_2(x') <= R(v) + g_v^T (x' - x)`` holds whatever the eigensolver's
accuracy.
"""
from __future__ import annotations

import heapq
import logging
import math
import re
import time
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.sparse.linalg import LinearOperator, eigsh

from ..core.errors import InternalError, NumericalError, ParseError, PosecrbError, UsageError
from ..core.graph import PoseGraph
from ..core.noise import isotropic_precisions, rotation_weight
from ..io import write_g2o
from ..linalg.cholesky import Factor, SymbolicCholesky
from ..linalg.laplacian import laplacian, reduced_index
from ..linalg.pathchol import PathFactor, logdet_eye_plus, scalar_greedy_steps, woodbury_downdate, woodbury_downdate1
from ..linalg.selinv import SelectedInverse
from ..models.paper.fim import rotation_jacobians
from ..solver.estimate import Estimate, get_estimate

log = logging.getLogger("posecrb")

OBJECTIVES = ("tree", "fim", "fiedler")
METHODS = ("greedy", "relax", "random", "naive")
GAINS = ("auto", "exact", "jl")
FIXED_RULES = ("odometry",)

# Greedy refreshes every gain by one selected inversion when one step needs more re-evaluations
# than max(REFRESH_AFTER, remaining candidates / REFRESH_FRACTION) (deterministic: a count, not a
# time). A refresh re-evaluates every remaining candidate at once, so it pays off only when a
# comparable number of path solves would be needed.
REFRESH_AFTER = 64
REFRESH_FRACTION = 4
# The incremental greedy recomputes its factor and every gain by selected inversion this often.
REFRESH_EVERY = 256
_BATCH_GROWTH = 2
# From this many rows on, the symbolic analysis uses METIS (less fill on pose graphs, as in selinv).
_METIS_FROM = 4000
# The lazy greedy seeds its queue by random projections ("auto") from this many candidates on.
JL_FROM_CANDIDATES = 50_000
JL_PROJECTIONS = 64
# "auto" greedy strategy: incremental (every gain exact at every step, O(candidates) per step)
# unless candidates x budget x (per-edge work) exceeds this, then lazy.
_INCREMENTAL_WORK = 2e9
STRATEGIES = ("auto", "incremental", "lazy")
# The relaxation is rounded by top-K and by this many seeded Madow draws; the best is kept.
MADOW_DRAWS = 8
# fiedler-relax polishes its rounded set by swaps: at most this many eigensolves, trials among the
# this-many best-ranked additions and removals per round.
POLISH_SOLVES = 60
POLISH_WIDTH = 16
# Dense eigensolver for lambda_2 up to this many poses.
_DENSE_EIG_UP_TO = 300


class DisconnectedFixedSet(PosecrbError):
    """The fixed edges do not connect the graph, so the base objective is -inf."""


# ======================================================================= budget and edges
def parse_budget(spec: str | int, n_candidates: int) -> int:
    """``K`` (an integer) or ``P%`` (of the candidates, rounded down as MAC does) -> K.

    Raises UsageError for 0, negative, malformed, or more than the candidates."""
    text = str(spec).strip()
    m = re.fullmatch(r"([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*%", text)
    if m:
        pct = float(m.group(1))
        if not 0 < pct <= 100:
            raise UsageError(f"--budget {text}: a percentage must be in (0, 100]")
        k = math.floor(pct / 100.0 * n_candidates + 1e-9)
        if k < 1:
            raise UsageError(f"--budget {text} of {n_candidates} candidate edge(s) rounds down to 0 edges")
        return k
    if not re.fullmatch(r"[+-]?[0-9]+", text):
        raise UsageError(f"--budget {text!r}: expected a number of edges K or a percentage P% of the candidates")
    k = int(text)
    if k <= 0:
        raise UsageError(f"--budget {text}: the number of edges to select must be >= 1")
    if k > n_candidates:
        raise UsageError(f"--budget {k} exceeds the {n_candidates} candidate edge(s)")
    return k


@dataclass(frozen=True)
class EdgeSplit:
    """Fixed edges and candidates, as indices into the graph's edges (file order)."""

    fixed: np.ndarray            # (f,) sorted
    candidates: np.ndarray       # (c,) sorted
    rule: str                    # "odometry" or the path of a pairs file
    connectivity: np.ndarray     # edges added to the odometry chain to connect it (subset of fixed)


def _components(n: int, src: np.ndarray, dst: np.ndarray) -> tuple[int, np.ndarray]:
    adj = sp.coo_matrix((np.ones(src.size), (src, dst)), shape=(n, n)).tocsr()
    return connected_components(adj, directed=False)


def _connecting_edges(graph: PoseGraph, fixed_mask: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Candidate edges that connect the components of the fixed edges: a maximum-weight spanning
    forest of the graph whose nodes are those components (heaviest parallel edge per pair)."""
    nc, labels = _components(graph.n, graph.src[fixed_mask], graph.dst[fixed_mask])
    if nc == 1:
        return np.zeros(0, dtype=np.int64)
    cand = np.flatnonzero(~fixed_mask)
    a, b = labels[graph.src[cand]], labels[graph.dst[cand]]
    cross = a != b
    cand, a, b = cand[cross], a[cross], b[cross]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((cand, -weight[cand], hi, lo))   # per pair: heaviest first, then file order
    cand, lo, hi = cand[order], lo[order], hi[order]
    first = np.ones(cand.size, dtype=bool)
    first[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
    cand, lo, hi = cand[first], lo[first], hi[first]
    # minimum spanning forest on 1/w = maximum weight (distinct pairs, so no duplicate summing)
    mst = minimum_spanning_tree(sp.coo_matrix((1.0 / weight[cand], (lo, hi)), shape=(nc, nc))).tocoo()
    pair_pos = np.searchsorted(lo * nc + hi, np.minimum(mst.row, mst.col) * nc + np.maximum(mst.row, mst.col))
    # lo*nc+hi is sorted because of the lexsort on (lo, hi)
    return np.sort(cand[pair_pos])


def split_edges(graph: PoseGraph, fixed: str = "odometry") -> EdgeSplit:
    """Fixed edges and candidates.

    ``"odometry"``: every edge between poses that are consecutive in id order (MAC's
    ``|i - j| = 1`` on contiguous ids), plus, when that chain does not connect the graph, the
    heaviest candidates (translation precision tau) of a spanning forest joining its pieces
    (listed in ``connectivity``). Otherwise ``fixed`` is the path of a text file of pose-id
    pairs ``i j`` (one per line, ``#`` comments), every edge between a listed pair is fixed;
    the fixed set must connect the graph. Raises DisconnectedGraph when the whole graph is
    disconnected, ParseError for a pair that is no edge, DisconnectedFixedSet otherwise.
    """
    graph.require_connected()
    if fixed == "odometry":
        mask = np.abs(graph.src - graph.dst) == 1
        extra = _connecting_edges(graph, mask, graph.tau)
        if extra.size:
            log.warning("%s: the odometry chain is not connected; %d loop closure(s) fixed to connect it: %s",
                        graph.name, extra.size, ", ".join(f"{graph.ids[graph.src[e]]}-{graph.ids[graph.dst[e]]}"
                                                          for e in extra[:8]) + (" ..." if extra.size > 8 else ""))
            mask[extra] = True
        rule = "odometry"
    else:
        mask = _fixed_from_file(graph, fixed)
        extra = np.zeros(0, dtype=np.int64)
        nc, labels = _components(graph.n, graph.src[mask], graph.dst[mask])
        if nc > 1:
            sizes = np.bincount(labels)
            raise DisconnectedFixedSet(
                f"{fixed}: the fixed edges leave the graph in {nc} pieces (sizes "
                f"{', '.join(map(str, sorted(sizes.tolist(), reverse=True)[:6]))}{', ...' if nc > 6 else ''}); "
                "the fixed set must connect every pose (add odometry pairs or use --fixed odometry)")
        rule = str(fixed)
    fixed_idx = np.flatnonzero(mask)
    cand = np.flatnonzero(~mask)
    return EdgeSplit(fixed=fixed_idx, candidates=cand, rule=rule, connectivity=extra)


def _fixed_from_file(graph: PoseGraph, path: str) -> np.ndarray:
    try:
        with open(path) as fh:
            lines = fh.read().splitlines()
    except OSError as exc:
        raise ParseError(path, None, f"cannot read the fixed-edge file: {exc.strerror or exc}") from None
    pairs, where = [], []
    for k, line in enumerate(lines, 1):
        tok = line.split("#", 1)[0].split()
        if not tok:
            continue
        if len(tok) != 2 or not all(re.fullmatch(r"[0-9]{1,18}", t) for t in tok):
            raise ParseError(path, k, f"expected two pose ids 'i j', got {line.strip()!r}")
        pairs.append((int(tok[0]), int(tok[1])))
        where.append(k)
    if not pairs:
        raise ParseError(path, None, "no pose-id pairs in the fixed-edge file")
    p = np.array(pairs, dtype=np.int64)
    # pose ids -> internal indices (ids are sorted); unknown ids make the pair unknown
    pos = np.minimum(np.searchsorted(graph.ids, p), graph.n - 1)
    known = (graph.ids[pos] == p).all(axis=1)
    lo, hi = np.minimum(pos[:, 0], pos[:, 1]), np.maximum(pos[:, 0], pos[:, 1])
    n = graph.n
    ekey = np.minimum(graph.src, graph.dst) * n + np.maximum(graph.src, graph.dst)
    pkey = np.where(known, lo * n + hi, -1)
    known &= np.isin(pkey, ekey)
    if not known.all():
        k = int(np.flatnonzero(~known)[0])
        raise ParseError(path, where[k], f"no edge between pose ids {pairs[k][0]} and {pairs[k][1]} in {graph.name}")
    return np.isin(ekey, pkey)


# ======================================================================= log-det objectives
@dataclass(eq=False)
class _Block:
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

    def h_selected(self, factor: Factor, edges: np.ndarray) -> np.ndarray:
        """``H_e = U_e^T M^{-1} U_e`` for many edges from one selected inversion."""

        sel = SelectedInverse(factor, self.name)
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
        rr = np.repeat(rows[valid], r)
        cc = np.tile(np.arange(r), int(valid.sum()))
        c = sp.csc_matrix((U[valid].ravel(), (rr, cc)), shape=(self.size, r))
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


def _logdet_i_plus(h: np.ndarray) -> np.ndarray:
    """logdet(I + H) for a batch of PSD H (k, r, r), via Cholesky."""
    if h.shape[1] == 1:
        return np.log1p(np.maximum(h[:, 0, 0], 0.0))
    eye = np.eye(h.shape[1])
    c = np.linalg.cholesky(eye[None] + 0.5 * (h + np.transpose(h, (0, 2, 1))))
    return 2.0 * np.log(np.diagonal(c, axis1=1, axis2=2)).sum(axis=1)


@dataclass
class _State:
    """An objective evaluated at x (and what the gradient needs)."""

    x: np.ndarray
    value: float
    data: Any = None


class LogDetObjective:
    """``f(x) = sum_b mult_b logdet(M_b(x)) + const_b`` over edge weights x in [0, 1]^m."""

    kind: Literal["logdet"] = "logdet"

    def __init__(self, name: str, blocks: list[_Block], m: int):
        self.name, self.blocks, self.m = name, blocks, m

    def evaluate(self, x: np.ndarray) -> _State:
        facs = [b.factor(x) for b in self.blocks]
        val = sum(b.mult * ld + b.const for b, (_, ld) in zip(self.blocks, facs))
        return _State(np.array(x, dtype=float), float(val), [f for f, _ in facs])

    def value(self, x: np.ndarray) -> float:
        return self.evaluate(x).value

    def _h(self, state: _State, edges: np.ndarray) -> list[np.ndarray]:
        return [b.h_selected(f, edges) for b, f in zip(self.blocks, state.data)]

    def gains(self, state: _State, edges: np.ndarray) -> np.ndarray:
        """Exact marginal gains ``sum_b mult_b logdet(I + H_be)`` (one selected inversion per block)."""
        return sum((b.mult * _logdet_i_plus(h) for b, h in zip(self.blocks, self._h(state, edges))),
                   np.zeros(edges.size))

    def gradient(self, state: _State, edges: np.ndarray) -> np.ndarray:
        """``df/dx_e = sum_b mult_b trace(H_be)``."""
        return sum(b.mult * np.trace(h, axis1=1, axis2=2) for b, h in zip(self.blocks, self._h(state, edges)))

    def gains_projected(self, state: _State, edges: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        return sum((b.mult * _logdet_i_plus(b.h_projected(f, state.x, edges, k, rng))
                    for b, f in zip(self.blocks, state.data)), np.zeros(edges.size))



def tree_objective(graph: PoseGraph, anchor: int = 0, rotation_model: str = "eq59") -> LogDetObjective:
    """eq. (75) lower bound ``d logdet L_tau + d_r logdet L_w`` as a function of edge weights.

    When ``w = c tau`` on every edge (uniform noise, e.g. city10000) ``L_w = c L_tau`` and the
    objective is ``(d + d_r) logdet L_tau + d_r (n - 1) log c``: one factor instead of two."""

    tau, kappa = isotropic_precisions(graph.info, graph.dim)
    w = rotation_weight(kappa, graph.dim, rotation_model)
    d, dr, n1 = graph.dim, graph.rot_dim, graph.n - 1
    red = reduced_index(graph.n, anchor)
    rows = np.stack([red[graph.src], red[graph.dst]], axis=1)
    valid = rows >= 0
    rows = np.where(valid, rows, 0)
    sign = np.array([1.0, -1.0])

    def block(name, weight, mult, const=0.0):
        u = (np.sqrt(weight)[:, None] * sign[None, :] * valid)[:, :, None]
        return _Block(name, n1, float(mult), float(const), rows, valid, u)

    ratio = w / tau
    if np.ptp(ratio) <= 1e-13 * abs(ratio.mean()):
        c = float(ratio.mean())
        blocks = [block("reduced Laplacians L_tau = L_w / c", tau, d + dr, dr * n1 * math.log(c))]
    else:
        blocks = [block("reduced translation Laplacian L_tau", tau, d),
                  block("reduced rotation Laplacian L_w", w, dr)]
    return LogDetObjective("tree", blocks, graph.m)


def edge_information_factors(graph: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0,
                             variant: str = "consistent", rotation_model: str = "eq59"
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
    w = graph.rotation_weight if rotation_model == "eq59" else rotation_weight(graph.kappa, d, rotation_model)
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
    return LogDetObjective("fim", [_Block("anchored FIM", (graph.n - 1) * graph.q, 1.0, 0.0, rows, valid, u)],
                           graph.m)


# ======================================================================= algebraic connectivity
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
        self._block = None if self.n <= _DENSE_EIG_UP_TO else _Block(
            "reduced Laplacian (lambda_2)", self.n - 1, 1.0, 0.0, np.where(valid, rows, 0), valid, u)
        self._free = np.flatnonzero(np.arange(self.n) != anchor)

    def _rayleigh(self, x: np.ndarray, v: np.ndarray) -> tuple[float, np.ndarray]:
        v = v - v.mean()
        v = v / np.linalg.norm(v)
        dv = v[self.src] - v[self.dst]
        return float(np.dot(x * self.w, dv * dv)), v

    def evaluate(self, x: np.ndarray, v0: np.ndarray | None = None) -> _State:
        """Value = Rayleigh quotient of the computed unit Fiedler vector (>= lambda_2, equal to
        it up to the eigensolver's tolerance squared)."""
        if self._block is None:
            lap = laplacian(self.n, self.src, self.dst, x * self.w).toarray()
            _, vecs = np.linalg.eigh(lap)
            val, v = self._rayleigh(x, vecs[:, 1])
            return _State(np.array(x, float), val, v)

        factor, _ = self._block.factor(x)
        free, n = self._free, self.n

        def apply(y):
            y = np.asarray(y, float).ravel()
            y = y - y.mean()
            out = np.zeros(n)
            out[free] = factor.solve_A(y[free])
            return out - out.mean()

        op = LinearOperator((n, n), matvec=apply, dtype=float)
        # deterministic start: the previous Fiedler vector, else the slowest cosine along the ids
        start = np.cos(np.linspace(0.0, np.pi, n)) if v0 is None else np.asarray(v0, float).copy()
        start -= start.mean()
        _, vec = eigsh(op, k=1, which="LA", v0=start, tol=1e-10, maxiter=5000)
        val, v = self._rayleigh(x, vec[:, 0])
        return _State(np.array(x, float), val, v)

    def value(self, x: np.ndarray) -> float:
        return self.evaluate(x).value

    def gradient(self, state: _State, edges: np.ndarray) -> np.ndarray:
        v = state.data
        dv = v[self.src[edges]] - v[self.dst[edges]]
        return self.w[edges] * dv * dv


# ======================================================================= algorithms
@dataclass(frozen=True)
class GreedyStats:
    evaluations: int          # stale gains re-evaluated by solves
    refreshes: int            # full refreshes by selected inversion (including the first)
    updates: int              # factor updates (edges added)
    gains: str                # "exact" | "jl"
    online_bound: float | None = None   # min over the greedy's steps of Minoux's bound


ENGINES = ("path", "cholmod")


class _Engine:
    """Solves and rank-r updates against the current factors of an objective's blocks.

    ``"path"``: posecrb.linalg.pathchol (forward solves along the elimination-tree reach of the edge's
    rows, in-place rank-one updates on the fixed full-graph pattern). ``"cholmod"``: CHOLMOD's
    own ``update_inplace`` and dense solves with the whole factor (kept for comparison)."""

    def __init__(self, obj: LogDetObjective, factors: list, kind: str):
        self.obj, self.kind = obj, kind
        if kind == "path":

            self.factors: list[Any] = [PathFactor(f) for f in factors]  # CHOLMOD Factors otherwise
        else:
            self.factors = factors

    def gains(self, edges: np.ndarray) -> np.ndarray:
        total = np.zeros(edges.size)
        for b, f in zip(self.obj.blocks, self.factors):
            h = f.h(b.rows[edges], b.valid[edges], b.U[edges]) if self.kind == "path" else b.h_solve(f, edges)
            total += b.mult * _logdet_i_plus(h)
        return total

    def solve(self, i: int, e: int) -> np.ndarray:
        """``M_i^{-1} U_e`` (size x r) with the current factor of block i."""
        b, f = self.obj.blocks[i], self.factors[i]
        if self.kind == "path":
            return f.solve(b.rows[e], b.valid[e], b.U[e])
        return f.solve_A(b.rhs(np.array([e])))

    def add(self, e: int) -> None:
        for b, f in zip(self.obj.blocks, self.factors):
            if self.kind == "path":
                f.update(b.rows[e], b.valid[e], b.U[e])
            else:
                b.update(f, e)


def _incremental_greedy(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int,
                        engine: str = "path", refresh_every: int | None = None) -> tuple[np.ndarray, GreedyStats]:
    """Greedy with every candidate's gain kept exact at every step.

    ``H_f = U_f^T M^{-1} U_f`` for all candidates comes from one selected inversion; adding e
    changes it by the Woodbury identity

        H_f <- H_f - C_f (I + H_e)^{-1} C_f^T,    C_f = U_f^T M^{-1} U_e,

    so one solve ``M^{-1} U_e`` with the current factor (then updated by U_e) and one compiled
    pass over the candidates replace re-evaluations: the argmax is the exact greedy choice (ties:
    the first edge in the file). Every ``refresh_every`` steps the factor is recomputed and every
    H re-derived by selected inversion, so rounding in the updates cannot accumulate."""

    refresh_every = refresh_every or REFRESH_EVERY
    if engine == "path" and len(obj.blocks) == 1 and obj.blocks[0].U.shape[2] == 1:
        return _incremental_greedy_scalar(obj, x, cand, k, refresh_every)
    state = obj.evaluate(x)
    hs = [b.h_selected(f, cand) for b, f in zip(obj.blocks, state.data)]
    local = [(np.ascontiguousarray(b.U[cand]), np.ascontiguousarray(b.rows[cand]),
              np.ascontiguousarray(b.valid[cand])) for b in obj.blocks]
    eng = _Engine(obj, state.data, engine)
    alive = np.ones(cand.size, dtype=bool)
    chosen: list[int] = []
    solves = 0
    refreshes = 1
    value = state.value
    online = math.inf
    # One Laplacian block: the gain mult * log1p(h) is increasing in h, so h itself ranks the
    # candidates (chosen ones are set to -inf) and logarithms are only taken where needed.
    scalar = len(obj.blocks) == 1 and obj.blocks[0].U.shape[2] == 1
    mult0 = obj.blocks[0].mult
    every = max(1, k // 64)   # Minoux's bound on ~64 prefixes: any subset of them is a valid min

    def gains_alive():
        g = sum(b.mult * logdet_eye_plus(h) for b, h in zip(obj.blocks, hs))
        g[~alive] = -np.inf
        return g

    for step in range(k):
        if scalar:
            key = hs[0][:, 0, 0]
            pos = int(np.argmax(key))
            gain = mult0 * math.log1p(max(float(key[pos]), 0.0))
        else:
            g = gains_alive()
            pos = int(np.argmax(g))
            gain = float(g[pos])
        if step % every == 0:
            # Minoux's online bound at S_t: f(OPT) <= f(S_t) + (sum of the K largest gains at S_t)
            top = gains_alive()[alive]
            online = min(online, value + (float(np.partition(top, top.size - k)[top.size - k:].sum())
                                          if top.size > k else float(top.sum())))
        value += gain
        e = int(cand[pos])
        chosen.append(e)
        alive[pos] = False
        x[e] = 1.0
        h_e = [h[pos].copy() for h in hs]
        if scalar:
            hs[0][pos] = -np.inf
        if step + 1 == k:
            break
        if (step + 1) % refresh_every == 0:
            state = obj.evaluate(x)
            idx = np.flatnonzero(alive)
            for h, b, f in zip(hs, obj.blocks, state.data):
                h[idx] = b.h_selected(f, cand[idx])
            eng = _Engine(obj, state.data, engine)
            refreshes += 1
            continue
        for i, (h, (uc, rc, vc)) in enumerate(zip(hs, local)):
            z = eng.solve(i, e)                                         # M^{-1} U_e (size, r)
            solves += 1
            he = h_e[i]
            inv = np.linalg.inv(np.eye(he.shape[0]) + 0.5 * (he + he.T))
            (woodbury_downdate1 if inv.shape[0] == 1 else woodbury_downdate)(
                h, uc, rc, vc, alive, np.ascontiguousarray(z), inv)
        eng.add(e)
    return np.array(chosen, dtype=np.int64), GreedyStats(solves, refreshes, len(chosen), "exact", online)


def _incremental_greedy_scalar(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int,
                               refresh_every: int) -> tuple[np.ndarray, GreedyStats]:
    """``_incremental_greedy`` for one Laplacian block with the path engine, every step of a
    stretch fused into one compiled call (posecrb.linalg.pathchol.scalar_greedy_steps); Python only
    between stretches: Minoux's bound on ~64 prefixes and a refresh every ``refresh_every`` steps."""

    b = obj.blocks[0]
    uc = np.ascontiguousarray(b.U[cand][:, :, 0])
    rc = b.rows[cand]
    vc = np.ascontiguousarray(b.valid[cand])
    alive = np.ones(cand.size, dtype=bool)
    every = max(1, k // 64)
    chosen: list[np.ndarray] = []
    online = math.inf
    refreshes = solves = 0
    step = 0
    h: np.ndarray        # h, pf and prow are set by the refresh at step 0
    pf: PathFactor
    prow: np.ndarray
    value = 0.0
    while step < k:
        if step % refresh_every == 0:
            state = obj.evaluate(x)
            value = state.value
            h = np.full(cand.size, -np.inf)
            idx = np.flatnonzero(alive)
            h[idx] = b.h_selected(state.data[0], cand[idx])[:, 0, 0]
            pf = PathFactor(state.data[0])
            prow = np.ascontiguousarray(pf.iperm[rc])
            refreshes += 1
        if step % every == 0:
            top = b.mult * np.log1p(np.maximum(h[alive], 0.0))
            online = min(online, value + (float(np.partition(top, top.size - k)[top.size - k:].sum())
                                          if top.size > k else float(top.sum())))
        stop = min(k, (step // every + 1) * every, (step // refresh_every + 1) * refresh_every)
        update_last = stop < k and stop % refresh_every != 0
        pf._mark[:] = 0
        pos, gains = scalar_greedy_steps(pf.indptr, pf.indices, pf.lval, pf.parent, prow, vc, uc, h, alive,
                                         stop - step, b.mult, update_last, pf._mark, np.zeros(pf.n))
        pf._mark[:] = 0
        x[cand[pos]] = 1.0
        chosen.append(cand[pos])
        value += float(gains.sum())
        solves += stop - step - (0 if update_last else 1)
        step = stop
    return np.concatenate(chosen), GreedyStats(solves, refreshes, k, "exact", online)


def _pick_strategy(strategy: str, n_cand: int, k: int, obj: LogDetObjective) -> str:
    if strategy not in STRATEGIES:
        raise UsageError(f"unknown greedy strategy {strategy!r}; choose from {', '.join(STRATEGIES)}")
    if strategy != "auto":
        return strategy
    p, r = obj.blocks[0].U.shape[1:]
    return "incremental" if n_cand * k * p * r * r <= _INCREMENTAL_WORK else "lazy"


def _lazy_greedy(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int, gains: str,
                 rng: np.random.Generator, engine: str = "path") -> tuple[np.ndarray, GreedyStats]:
    """Lazy greedy (Minoux) on a monotone submodular log-det objective.

    Stale gains in the priority queue are upper bounds on the current ones (submodularity), so an
    entry on top whose gain was computed at the current step is the exact greedy choice. Stale
    entries on top are re-evaluated in batches of 1, 2, 4, ... against the current factor; a step
    that needs many re-evaluations (REFRESH_AFTER, REFRESH_FRACTION) refreshes every gain by one
    selected inversion of a fresh factorisation instead. The first gains come from one selected inversion,
    or with ``gains="jl"`` from random projections (then the initial queue is an estimate and the
    choice greedy only approximately; every accepted gain is still computed exactly)."""
    state = obj.evaluate(x)
    if gains == "jl":
        g0 = obj.gains_projected(state, cand, JL_PROJECTIONS, rng)
    else:
        g0 = obj.gains(state, cand)
    eng = _Engine(obj, state.data, engine)
    heap = [(-float(g), int(e), 0) for g, e in zip(g0, cand)]
    heapq.heapify(heap)
    chosen: list[int] = []
    step = evals = evals_step = 0
    refreshes = 1
    batch = 1
    while len(chosen) < k:
        if heap[0][2] == step:
            _, e, _ = heapq.heappop(heap)
            chosen.append(e)
            x[e] = 1.0
            eng.add(e)
            step += 1
            evals_step = 0
            batch = 1
            continue
        if evals_step >= max(REFRESH_AFTER, len(heap) // REFRESH_FRACTION):
            rest = np.array(sorted(t[1] for t in heap), dtype=np.int64)
            state = obj.evaluate(x)
            g = obj.gains(state, rest)
            eng = _Engine(obj, state.data, engine)
            heap = [(-float(gv), int(ev), step) for gv, ev in zip(g, rest)]
            heapq.heapify(heap)
            refreshes += 1
            evals_step = 0
            continue
        stale: list[int] = []
        while heap and heap[0][2] != step and len(stale) < batch:
            stale.append(heapq.heappop(heap)[1])
        g = eng.gains(np.array(stale, dtype=np.int64))
        for gv, ev in zip(g, stale):
            heapq.heappush(heap, (-float(gv), ev, step))
        evals += len(stale)
        evals_step += len(stale)
        batch *= _BATCH_GROWTH
    return np.array(chosen, dtype=np.int64), GreedyStats(evals, refreshes, len(chosen), gains, None)


def _greedy_fiedler(obj: FiedlerObjective, x: np.ndarray, cand: np.ndarray, k: int) -> tuple[np.ndarray, dict]:
    """MAC's GreedyEig: per step, candidates in decreasing order of the bound ``R(v) + g_e``
    (concavity), each evaluated exactly, until the bound cannot beat the best found."""
    avail = np.ones(cand.size, dtype=bool)
    chosen = []
    evals = 0
    state = obj.evaluate(x)
    for _ in range(k):
        idx = np.flatnonzero(avail)
        g = obj.gradient(state, cand[idx])
        order = idx[np.argsort(-g, kind="stable")]
        bounds = state.value + obj.gradient(state, cand[order])
        best, best_state, best_pos = -np.inf, None, -1
        for pos, ub in zip(order, bounds):
            if ub <= best:
                break
            x[cand[pos]] = 1.0
            st = obj.evaluate(x, v0=state.data)
            x[cand[pos]] = 0.0
            evals += 1
            if st.value > best:
                best, best_state, best_pos = st.value, st, pos
        if best_state is None:  # every candidate's lambda_2 was NaN (or there was no candidate)
            raise NumericalError("lambda_2 greedy: no candidate edge gives a finite algebraic connectivity")
        avail[best_pos] = False
        x[cand[best_pos]] = 1.0
        chosen.append(int(cand[best_pos]))
        state = best_state
    return np.array(chosen, dtype=np.int64), {"evaluations": evals}


@dataclass(frozen=True)
class Relaxation:
    """A Frank-Wolfe run on the concave relaxation ``x in [0, 1]^C, sum x = K``."""

    weights: np.ndarray        # (c,) last iterate, per candidate
    value: float               # f at the last iterate
    bound: float               # min over iterates of f(x_t) + gap_t: >= the relaxation's optimum
    gap: float                 # duality gap at the last iterate
    iterations: int
    converged: bool
    step: str                  # "backtracking" | "2/(t+2)"
    history: list = field(default_factory=list)   # (iteration, value, bound)


def _top_k(scores: np.ndarray, k: int, tiebreak: np.ndarray | None = None) -> np.ndarray:
    """Positions of the k largest scores; ties by ``tiebreak`` (larger first), then position."""
    keys = (np.arange(scores.size),) + ((-tiebreak,) if tiebreak is not None else ()) + (-scores,)
    return np.lexsort(keys)[:k]


def frank_wolfe(obj: LogDetObjective | FiedlerObjective, x_full: np.ndarray, cand: np.ndarray, k: int,
                start: np.ndarray, *, max_iter: int,
                tol: float, base_value: float, step: str = "backtracking") -> Relaxation:
    """Frank-Wolfe ascent on ``f(x)`` over ``{0 <= x <= 1, sum x = K}`` (candidates only).

    The linear maximisation oracle is the indicator of the K largest gradient entries; the
    duality gap ``g^T (s - x)`` added to ``f(x)`` bounds the relaxation's maximum (f concave),
    and the smallest such bound over the iterates is returned. Stops when the gap is below
    ``tol * (bound - base_value)`` (the gain is known to a relative ``tol``) or after
    ``max_iter`` iterations. ``step="backtracking"``: the adaptive step of Pedregosa et al.
    (2020), sufficient increase against a local quadratic model whose curvature is
    doubled on failure; ``"2/(t+2)"``: the classical rule (MAC's).
    """
    x = x_full.copy()
    x[cand] = start
    state = obj.evaluate(x)
    best = math.inf
    lip = None
    hist = []
    gap = math.inf
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        g = obj.gradient(state, cand)
        s = np.zeros(cand.size)
        s[_top_k(g, k)] = 1.0
        d = s - x[cand]
        gap = float(np.dot(g, d))
        best = min(best, state.value + max(gap, 0.0))
        hist.append((it, state.value, best))
        if gap <= tol * max(best - base_value, 1e-300):
            converged = True
            break
        dd = float(np.dot(d, d))
        if step == "2/(t+2)":
            gamma = 2.0 / (it + 2.0)
            x[cand] += gamma * d
            state = obj.evaluate(x, v0=state.data) if obj.kind == "fiedler" else obj.evaluate(x)
            continue
        if lip is None:
            lip = gap / dd
        for _ in range(60):
            gamma = min(1.0, gap / (lip * dd))
            trial = x.copy()
            trial[cand] += gamma * d
            new = obj.evaluate(trial)
            if new.value >= state.value + gamma * gap - 0.5 * gamma * gamma * lip * dd - 1e-12 * abs(state.value):
                break
            lip *= 2.0
        x, state = trial, new
        lip *= 0.5
    np.clip(x, 0.0, 1.0, out=x)
    return Relaxation(weights=x[cand].copy(), value=state.value, bound=best, gap=gap, iterations=it,
                      converged=converged, step=step, history=hist)


def _heaviest(weights: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Positions of the k largest weights, ties broken at random (seeded): on datasets with one
    noise level for every edge this is a random selection, not the first k in the file."""
    return np.lexsort((rng.permutation(weights.size), -weights))[:k]


def madow(weights: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Madow's systematic sampling: K distinct positions, position e with probability weights[e]
    (weights in [0, 1] summing to K): one uniform u, the points u, u + 1, ..., u + K - 1 on the
    cumulative sums."""
    cum = np.cumsum(np.clip(weights, 0.0, 1.0))
    cum *= k / cum[-1]
    u = rng.random()
    pos = np.searchsorted(cum, u + np.arange(k), side="right")
    pos = np.unique(np.minimum(pos, weights.size - 1))
    if pos.size < k:  # rounding at an interval boundary: fill with the largest remaining weights
        rest = np.setdiff1d(np.arange(weights.size), pos)
        pos = np.union1d(pos, rest[_top_k(weights[rest], k - pos.size)])
    return pos


@dataclass(frozen=True)
class PolishStats:
    """What the swap search after rounding did (``polish_fiedler``)."""

    solves: int            # eigenproblems solved for trial sets
    swaps: int             # candidates exchanged in accepted moves
    moves: int             # accepted moves (one or a block of paired swaps each)
    value_before: float    # lambda_2 of the rounded set
    value_after: float     # lambda_2 of the polished set (as computed during the search)
    stopped: str           # "no-ascent" | "no-improving-trial" | "solves"


def polish_fiedler(obj: FiedlerObjective, base: np.ndarray, cand: np.ndarray, pick: np.ndarray, *,
                   max_solves: int = POLISH_SOLVES, width: int = POLISH_WIDTH,
                   state: _State | None = None) -> tuple[np.ndarray, _State, PolishStats]:
    """Swap search on a K-subset of the candidates for a larger ``lambda_2``.

    ``pick``: positions in ``cand`` of the K selected candidates; ``base``: the weights of every
    edge with the fixed ones at 1. With ``v`` the unit Fiedler vector of the current set S and
    ``g_e = w_e (v_i - v_j)^2``, any set S' satisfies ``lambda_2(S') <= v^T L(S') v = R(v) + sum_{S'
    minus S} g - sum_{S minus S'} g`` (``lambda_2`` is a minimum of Rayleigh quotients): exchanging
    removals R for additions A can raise ``lambda_2`` above ``R(v)`` only if ``g(A) > g(R)``. The
    search stops when even the best single swap (largest g outside S against smallest g inside)
    has ``g_a <= g_r`` ("no-ascent"): then no K-subset exceeds ``R(v)``, S is optimal up to the
    eigensolver's accuracy (its Frank-Wolfe duality gap is zero). Trial moves per round, each
    costing one eigensolve warm-started at v: the ``p`` largest additions paired with the ``p``
    smallest removals for p = block, block/2, ..., 2 (block doubles after an accepted block move),
    then single swaps in decreasing order of ``g_a - g_r`` (at most ``width`` of them; additions and
    removals among the ``width`` best-ranked each). The first trial that raises ``lambda_2`` is
    accepted; the search stops when a round has none ("no-improving-trial") or after
    ``max_solves`` eigensolves. Never returns a set worse than ``pick`` as evaluated; the
    budget (K) and the fixed edges are unchanged by construction.
    """
    sel = np.zeros(cand.size, dtype=bool)
    sel[pick] = True
    x = base.copy()
    x[cand[sel]] = 1.0
    if state is None:
        state = obj.evaluate(x)
    before = state.value
    solves = swaps = moves = 0
    block = 2
    stopped = "solves"
    while solves < max_solves:
        ins, outs = np.flatnonzero(sel), np.flatnonzero(~sel)
        if ins.size == 0 or outs.size == 0:
            stopped = "no-ascent"
            break
        g = obj.gradient(state, cand)
        add = outs[np.argsort(-g[outs], kind="stable")[:width]]
        rem = ins[np.argsort(g[ins], kind="stable")[:width]]
        # an exchange must beat R(v) by more than the rounding of the values themselves
        eps = 1e-12 * abs(state.value)
        w = min(add.size, rem.size)
        paired = g[add[:w]] - g[rem[:w]]    # decreasing: rank-i addition with rank-i removal
        p_max = int(np.count_nonzero(paired > eps))
        if p_max == 0:
            stopped = "no-ascent"
            break
        trials = []
        p = min(block, p_max)
        while p >= 2:
            trials.append((add[:p], rem[:p]))
            p //= 2
        est = g[add][:, None] - g[rem][None, :]
        for f in np.argsort(-est, axis=None, kind="stable")[:width]:
            i, j = divmod(int(f), rem.size)
            if est[i, j] <= eps:
                break
            trials.append((add[i:i + 1], rem[j:j + 1]))
        accepted = False
        for a, r in trials:
            if solves >= max_solves:
                break
            x[cand[a]] = 1.0
            x[cand[r]] = 0.0
            trial = obj.evaluate(x, v0=state.data)
            solves += 1
            if trial.value > state.value + eps:
                sel[a], sel[r] = True, False
                state = trial
                swaps += a.size
                moves += 1
                block = max(2, 2 * a.size)
                accepted = True
                break
            x[cand[a]] = 0.0
            x[cand[r]] = 1.0
        if not accepted:
            if solves < max_solves:
                stopped = "no-improving-trial"
            break
    stats = PolishStats(solves=solves, swaps=swaps, moves=moves, value_before=float(before),
                        value_after=float(state.value), stopped=stopped)
    return np.flatnonzero(sel), state, stats


# ======================================================================= driver
@dataclass(frozen=True)
class Certificate:
    """Upper bounds on the best K-subset's objective (each valid on its own)."""

    upper_bound: float | None           # the smallest of the bounds below
    relaxation_bound: float | None      # Frank-Wolfe: min_t f(x_t) + gap_t (>= relaxation optimum); for
    #                                     lambda_2 also f + gap at the returned set
    submodular_bound: float | None      # f(S) + sum of the K largest marginal gains at S (log-det only)
    relaxed_value: float | None         # f at the last Frank-Wolfe iterate
    iterations: int = 0
    converged: bool | None = None
    step: str | None = None


@dataclass(frozen=True)
class SelectionResult:
    dataset: str
    path: str | None
    dim: int
    poses: int
    edges: int
    anchor_id: int
    objective: str
    method: str
    budget: int
    budget_spec: str
    split: EdgeSplit
    selected: np.ndarray          # edge indices (file order)
    selected_ids: np.ndarray      # (K, 2) pose ids
    value: float
    base_value: float
    full_value: float             # every candidate kept
    certificate: Certificate
    rounding: str | None
    order: np.ndarray | None      # greedy: the edges in the order chosen
    seed: int
    stats: dict
    estimate: dict | None
    times: dict

    @property
    def upper_bound(self) -> float | None:
        return self.certificate.upper_bound

    @property
    def certified_ratio(self) -> float | None:
        """(value - base) / (upper_bound - base): the fraction of the best achievable gain
        guaranteed to be reached (1 = provably optimal)."""
        ub = self.certificate.upper_bound
        if ub is None:
            return None
        den = ub - self.base_value
        if den <= 0:
            return 1.0
        return float(min(1.0, max(0.0, (self.value - self.base_value) / den)))

    @property
    def kept_edges(self) -> np.ndarray:
        return np.union1d(self.split.fixed, self.selected)

    def to_dict(self) -> dict:
        c = self.certificate
        return {
            "dataset": self.dataset, "path": self.path, "dim": self.dim, "poses": self.poses,
            "edges": self.edges, "anchor": self.anchor_id,
            "objective": self.objective, "method": self.method,
            "budget": self.budget, "budget_spec": self.budget_spec,
            "fixed": {"rule": self.split.rule, "edges": int(self.split.fixed.size),
                      "added_for_connectivity": [[int(a), int(b), int(e)] for (a, b), e in
                                                 zip(self._ids(self.split.connectivity), self.split.connectivity)]},
            "candidates": int(self.split.candidates.size),
            "selected": [[int(a), int(b), int(e)] for (a, b), e in zip(self.selected_ids, self.selected)],
            "value": self.value, "base_value": self.base_value, "full_value": self.full_value,
            "upper_bound": c.upper_bound, "certified_ratio": self.certified_ratio,
            "bounds": {"relaxation": c.relaxation_bound, "submodular": c.submodular_bound,
                       "relaxed_value": c.relaxed_value, "iterations": c.iterations,
                       "converged": c.converged, "step": c.step},
            "order": None if self.order is None else [int(e) for e in self.order],
            "rounding": self.rounding, "seed": self.seed, "stats": self.stats, "estimate": self.estimate,
            "times": self.times,
        }

    def to_row(self) -> dict:
        """``to_dict()`` without the per-edge lists (``selected``, ``order``): one row of a table."""
        return {k: v for k, v in self.to_dict().items() if k not in ("selected", "order")}

    def _ids(self, edges: np.ndarray) -> np.ndarray:
        if edges.size == 0:
            return self.selected_ids[:0]
        if self._id_pairs is None:  # select_edges always sets it
            raise InternalError("selection result without its edges' id pairs")
        return self._id_pairs[edges]

    _id_pairs: np.ndarray | None = field(default=None, repr=False)


def _submodular_bound(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int) -> tuple[float, float]:
    """(f(S), f(S) + sum of the K largest exact marginal gains over the candidates not in S)."""
    state = obj.evaluate(x)
    rest = cand[x[cand] == 0.0]
    if rest.size == 0:
        return state.value, state.value
    g = obj.gains(state, rest)
    return state.value, state.value + float(np.sort(g)[::-1][:k].sum())


def make_objective(graph: PoseGraph, objective: str, anchor: int = 0, estimate: Estimate | None = None,
                   fiedler_weight: str = "w", rotation_model: str = "eq59") -> LogDetObjective | FiedlerObjective:
    """The objective as a function of edge weights (all m edges)."""
    if objective == "tree":
        return tree_objective(graph, anchor, rotation_model)
    if objective == "fim":
        if estimate is None:
            raise UsageError("the fim objective needs an estimate")
        return fim_objective(graph, estimate.rot, estimate.trans, anchor)
    if objective == "fiedler":
        if fiedler_weight == "w":

            weights = rotation_weight(graph.kappa, graph.dim, rotation_model)
        elif fiedler_weight == "kappa":
            weights = graph.kappa
        else:
            raise UsageError(f"fiedler weight must be w or kappa, not {fiedler_weight!r}")
        return FiedlerObjective(graph, weights, anchor)
    raise UsageError(f"unknown objective {objective!r}; choose from {', '.join(OBJECTIVES)}")


def select_edges(graph: PoseGraph, budget: str | int, *, objective: str = "tree", method: str = "greedy",
                 fixed: str = "odometry", certify: bool = False, seed: int = 0, anchor: int | None = None,
                 estimate: str = "solve", gains: str = "auto", max_iter: int | None = None,
                 tol: float = 1e-3, fiedler_weight: str = "w", split: EdgeSplit | None = None,
                 reference: Estimate | None = None, engine: str = "path", strategy: str = "auto",
                 polish: int | None = None) -> SelectionResult:
    """Choose ``budget`` candidate edges maximising ``objective`` (module docstring).

    ``budget``: K or "P%" of the candidates. ``method``: ``greedy`` (exact greedy; MAC's
    GreedyEig for fiedler), ``relax`` (Frank-Wolfe on the relaxation, rounded by top-K and by
    MADOW_DRAWS seeded Madow draws, the best kept), ``random`` (seeded), ``naive`` (the K
    heaviest by rotation weight, MAC's baseline; ties at random). ``certify``: also run the
    relaxation for a bound (greedy, random, naive; relax always has one). Log-det objectives always
    report the submodular bound.
    ``estimate`` (fim only): "solve" (certified optimum of the full graph), "vertices" or a
    file; ``reference`` an already computed ``posecrb.solver.estimate.Estimate``. ``strategy`` (log-det
    greedy): "incremental" (every gain exact at every step), "lazy" (priority queue) or "auto"
    (incremental unless candidates x budget is huge). ``gains`` (lazy only): "exact" (selected
    inversion), "jl" (random projections seed the queue) or "auto" (jl above 50000 candidates).
    ``engine``: "path" (posecrb.linalg.pathchol) or "cholmod" (CHOLMOD update_inplace and whole-factor
    solves, for comparison). ``polish`` (fiedler relax): at most this many eigensolves of swap search
    after the rounding (``polish_fiedler``; default POLISH_SOLVES, 0 = none); the polished set is
    kept only if its recomputed lambda_2 is larger. ``max_iter``/``tol``: Frank-Wolfe limits (default 100 for the
    log-dets, 20 for fiedler as MAC). ``split``: precomputed fixed/candidate edges.
    """
    t_total = time.perf_counter()
    if objective not in OBJECTIVES:
        raise UsageError(f"unknown objective {objective!r}; choose from {', '.join(OBJECTIVES)}")
    if method not in METHODS:
        raise UsageError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    if gains not in GAINS:
        raise UsageError(f"unknown gains mode {gains!r}; choose from {', '.join(GAINS)}")
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    split = split or split_edges(graph, fixed)
    cand = split.candidates
    if cand.size == 0:
        raise UsageError(f"{graph.name}: no candidate edges (every edge is fixed)")
    k = parse_budget(budget, cand.size)
    anchor = graph.anchor_index(None) if anchor is None else int(anchor)
    est_info = None
    est = reference
    if objective == "fim":
        if est is None:

            t1 = time.perf_counter()
            est = get_estimate(graph, estimate, anchor=anchor) if estimate == "solve" else get_estimate(graph, estimate)
            times["estimate"] = time.perf_counter() - t1
        if est.certified is False:
            log.warning("%s: the estimate of the full graph is NOT certified; the fim objective is evaluated "
                        "at an uncertified point", graph.name)
        est_info = {"source": est.source, "certified": est.certified, "objective": est.objective}
    obj = make_objective(graph, objective, anchor, est, fiedler_weight)
    base = np.zeros(graph.m)
    base[split.fixed] = 1.0
    times["setup"] = time.perf_counter() - t0 - times.get("estimate", 0.0)
    rng = np.random.default_rng(seed)
    w_rot = graph.rotation_weight if fiedler_weight == "w" else graph.kappa
    stats: dict[str, Any] = {}
    rounding = None
    relax: Relaxation | None = None
    max_iter = max_iter if max_iter is not None else (20 if obj.kind == "fiedler" else 100)

    t0 = time.perf_counter()
    base_state = obj.evaluate(base)
    full = base.copy()
    full[cand] = 1.0
    full_value = obj.value(full)
    times["base"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    order = None
    if k == cand.size:
        chosen = cand.copy()
    elif method == "random":
        chosen = np.sort(rng.choice(cand, size=k, replace=False))
    elif method == "naive":
        chosen = np.sort(cand[_heaviest(w_rot[cand], k, rng)])
    elif method == "greedy" and obj.kind == "logdet":
        strategy = _pick_strategy(strategy, cand.size, k, obj)
        mode = gains
        if mode == "auto":
            mode = "jl" if strategy == "lazy" and cand.size > JL_FROM_CANDIDATES else "exact"
        elif mode == "jl" and strategy == "incremental":
            raise UsageError("random-projection gains (--jl) only seed the lazy greedy's queue; "
                             "the incremental greedy keeps every gain exact")
        if strategy == "incremental":
            chosen, gstats = _incremental_greedy(obj, base.copy(), cand, k, engine)
        else:
            chosen, gstats = _lazy_greedy(obj, base.copy(), cand, k, mode, rng, engine)
        stats.update(vars(gstats), strategy=strategy, engine=engine)
        order = chosen
        chosen = np.sort(chosen)
    elif method == "greedy" and obj.kind == "fiedler":
        if k * graph.n > 2_000_000:
            log.warning("%s: the lambda_2 greedy (MAC's GreedyEig) solves at least one eigenproblem of %d poses "
                        "per selected edge (%d); this takes long, fiedler-relax is the scalable method",
                        graph.name, graph.n, k)
        chosen, fstats = _greedy_fiedler(obj, base.copy(), cand, k)
        stats.update(fstats)
        order = chosen
        chosen = np.sort(chosen)
    else:  # relax
        if obj.kind == "fiedler":
            start = np.zeros(cand.size)
            start[_heaviest(w_rot[cand], k, rng)] = 1.0   # MAC's initial point: the naive selection
            relax = frank_wolfe(obj, base, cand, k, start, max_iter=max_iter, tol=tol,
                                base_value=base_state.value, step="2/(t+2)")
        else:
            start = np.full(cand.size, k / cand.size)
            relax = frank_wolfe(obj, base, cand, k, start, max_iter=max_iter, tol=tol,
                                base_value=base_state.value)
        pick_top = _top_k(relax.weights, k, tiebreak=w_rot[cand])
        picks = [("top-k", pick_top)] + [(f"madow-{i + 1}", madow(relax.weights, k, rng))
                                         for i in range(MADOW_DRAWS)]
        vals = {}
        for name, pick in picks:
            xx = base.copy()
            xx[cand[pick]] = 1.0
            vals[name] = (obj.value(xx), pick)
        rounding = max(vals, key=lambda n: (vals[n][0], n == "top-k"))   # first best; top-k wins ties
        chosen = np.sort(cand[vals[rounding][1]])
        stats["rounding_values"] = {n: v for n, (v, _) in vals.items()}
        n_polish = POLISH_SOLVES if polish is None else int(polish)
        if obj.kind == "fiedler" and n_polish > 0:
            pos, _, pstats = polish_fiedler(obj, base, cand, vals[rounding][1], max_solves=n_polish)
            xx = base.copy()
            xx[cand[pos]] = 1.0
            polished = obj.value(xx)   # recomputed from a cold start, as every reported value
            # keep the rounded set unless the recomputed value confirms the search's improvement
            if polished > vals[rounding][0]:
                chosen = np.sort(cand[pos])
                rounding += "+polish"
            stats["polish"] = {**vars(pstats), "recomputed": polished}
    times["select"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    xs = base.copy()
    xs[chosen] = 1.0
    sub_bound = None
    if obj.kind == "logdet":
        value, sub_bound = _submodular_bound(obj, xs, cand, k)
        if stats.get("online_bound") is not None:
            sub_bound = min(sub_bound, stats["online_bound"])
    else:
        final = obj.evaluate(xs)
        value = final.value
    times["value"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if relax is None and certify and k < cand.size:
        # warm start at the selection itself: the bound is then at most value + gap there
        relax = frank_wolfe(obj, base, cand, k, xs[cand].copy(), max_iter=max_iter, tol=tol,
                            base_value=base_state.value,
                            step="2/(t+2)" if obj.kind == "fiedler" else "backtracking")
    if relax is not None:
        times["certify" if method != "relax" else "relax"] = time.perf_counter() - t0 + (
            times.pop("select") if method == "relax" else 0.0)
    relax_bound = relax.bound if relax else None
    if relax is not None and relax_bound is not None and obj.kind == "fiedler" and k < cand.size:
        # the same supergradient bound at the returned set itself: R(v) + Frank-Wolfe gap there
        g = obj.gradient(final, cand)
        own = value + float(np.sort(g)[::-1][:k].sum() - g[xs[cand] == 1.0].sum())
        relax_bound = min(relax_bound, own)
        stats["bound_at_selection"] = own
    bounds = [b for b in (relax_bound, sub_bound) if b is not None]
    if k == cand.size:
        bounds.append(value)
    upper = min(bounds) if bounds else None
    cert = Certificate(upper_bound=upper, relaxation_bound=relax_bound,
                       submodular_bound=sub_bound, relaxed_value=relax.value if relax else None,
                       iterations=relax.iterations if relax else 0,
                       converged=relax.converged if relax else None, step=relax.step if relax else None)
    if upper is not None and value > upper + 1e-9 * max(1.0, abs(upper)):  # pragma: no cover - a bug
        raise PosecrbError(f"internal inconsistency: value {value} above its upper bound {upper}")
    times["total"] = time.perf_counter() - t_total
    id_pairs = np.stack([graph.ids[graph.src], graph.ids[graph.dst]], axis=1)
    res = SelectionResult(
        dataset=graph.name, path=graph.path, dim=graph.dim, poses=graph.n, edges=graph.m,
        anchor_id=int(graph.ids[anchor]), objective=objective, method=method, budget=k,
        budget_spec=str(budget), split=split, selected=chosen, selected_ids=id_pairs[chosen],
        value=float(value), base_value=float(base_state.value), full_value=float(full_value), certificate=cert,
        rounding=rounding, order=order, seed=int(seed), stats=stats, estimate=est_info, times=times, _id_pairs=id_pairs)
    return res


# ======================================================================= pruned graph
def pruned_graph(graph: PoseGraph, keep: np.ndarray) -> PoseGraph:
    """The graph with only the edges ``keep`` (indices, file order); vertices and estimate kept."""
    keep = np.sort(np.asarray(keep, dtype=np.int64))
    lines = graph.edge_lines[keep] if graph.edge_lines is not None else None
    return replace(graph, src=graph.src[keep], dst=graph.dst[keep], rot=graph.rot[keep],
                   trans=graph.trans[keep], info=graph.info[keep], edge_lines=lines, sha256=None)


def write_pruned(graph: PoseGraph, result: SelectionResult, path: str) -> PoseGraph:
    """Write fixed + selected edges (and every vertex) as g2o, atomically (posecrb.io.write_g2o)."""

    pruned = pruned_graph(graph, result.kept_edges)
    write_g2o(pruned, path)
    return pruned
