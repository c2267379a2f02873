"""Dense references for subset selection, each edge's term written out from its definition."""
from __future__ import annotations

import itertools

import numpy as np
from scipy.special import ive

from posecrb.core.graph import PoseGraph
from posecrb.selection import split_edges

from ..helpers import random_rotations, random_spd


# ----------------------------------------------------------------------------- small graphs
def chain_graph(rng: np.random.Generator, n: int = 7, extra: int = 8, dim: int = 2, uniform: bool = False,
                ids: np.ndarray | None = None) -> PoseGraph:
    """Odometry chain 0-1-...-(n-1) and ``extra`` distinct loop closures (|i - j| >= 2),
    anisotropic information (isotropic and identical on every edge with ``uniform``)."""
    pairs = [(i, j) for i in range(n) for j in range(i + 2, n)]
    pick = rng.choice(len(pairs), extra, replace=False)
    src = np.array(list(range(n - 1)) + [pairs[p][0] for p in pick])
    dst = np.array(list(range(1, n)) + [pairs[p][1] for p in pick])
    m, q = src.size, dim + (1 if dim == 2 else 3)
    info = random_spd(rng, m, q)
    if uniform:
        info = np.broadcast_to(np.diag(np.r_[np.full(dim, 20.0), np.full(q - dim, 50.0)]), (m, q, q)).copy()
    return PoseGraph(dim=dim, ids=np.arange(n) if ids is None else ids, src=src, dst=dst,
                     rot=random_rotations(rng, m, dim), trans=rng.normal(size=(m, dim)), info=info,
                     vertex_rot=random_rotations(rng, n, dim), vertex_trans=2.0 * rng.normal(size=(n, dim)))


def precisions(info: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """SE-Sync's (tau, kappa) written out per edge."""
    tau, kappa = [], []
    for a in info:
        if dim == 2:
            tau.append(2.0 / np.trace(np.linalg.inv(a[:2, :2])))
            kappa.append(a[2, 2])
        else:
            tau.append(3.0 / np.trace(np.linalg.inv(a[:3, :3])))
            kappa.append(3.0 / (2.0 * np.trace(np.linalg.inv(a[3:, 3:]))))
    return np.array(tau), np.array(kappa)


def rot_weight(kappa: np.ndarray, dim: int) -> np.ndarray:
    """2 kappa (2D), omega(kappa)/3 with omega = kappa (I1 - I2)/(I0 - I1) at 2 kappa (3D, eq. 59)."""
    if dim == 2:
        return 2.0 * kappa
    x = 2.0 * kappa
    return kappa * (ive(1, x) - ive(2, x)) / (ive(0, x) - ive(1, x)) / 3.0


def chol_logdet(a: np.ndarray) -> float:
    return float(2.0 * np.log(np.diag(np.linalg.cholesky(a))).sum())


def dense_laplacian_terms(g: PoseGraph, weights: np.ndarray, anchor: int = 0) -> np.ndarray:
    """(m, n-1, n-1): each edge's contribution to the reduced Laplacian."""
    free = [k for k in range(g.n) if k != anchor]
    pos = {k: t for t, k in enumerate(free)}
    out = np.zeros((g.m, g.n - 1, g.n - 1))
    for e, (i, j) in enumerate(zip(g.src, g.dst)):
        a = np.zeros(g.n - 1)
        if i in pos:
            a[pos[i]] += 1.0
        if j in pos:
            a[pos[j]] -= 1.0
        out[e] = weights[e] * np.outer(a, a)
    return out


def dense_fim_terms(g: PoseGraph, rot: np.ndarray, trans: np.ndarray, anchor: int = 0) -> np.ndarray:
    """(m, N, N): each edge's Fisher information, order [x_free; theta_free], from the residuals
    r_t = R_i^T (x_j - x_i) - p (tau I) and the relative rotation Log(Rbar^T R_i^T R_j) (w I) under
    body-frame perturbations R Exp(delta E) (E_k = G_k / sqrt 2 in 3D), written out per edge."""
    d = g.dim
    dr = 1 if d == 2 else 3
    tau, kappa = precisions(g.info, d)
    w = rot_weight(kappa, d)
    free = [k for k in range(g.n) if k != anchor]
    pos = {k: t for t, k in enumerate(free)}
    nf = len(free)
    size = nf * (d + dr)
    out = np.zeros((g.m, size, size))
    for e, (i, j) in enumerate(zip(g.src, g.dst)):
        jt = np.zeros((d, size))
        jr = np.zeros((dr, size))
        ri, rj = rot[i], rot[j]
        u = ri.T @ (trans[j] - trans[i])
        if d == 2:
            du = np.array([[u[1]], [-u[0]]])          # d/dtheta of Rot(-theta) u at 0
        else:
            du = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]]) / np.sqrt(2.0)
        if i in pos:
            jt[:, pos[i] * d:(pos[i] + 1) * d] = -ri.T
            jt[:, nf * d + pos[i] * dr: nf * d + (pos[i] + 1) * dr] = du
            jr[:, nf * d + pos[i] * dr: nf * d + (pos[i] + 1) * dr] = -(rj.T @ ri if d == 3 else np.eye(1))
        if j in pos:
            jt[:, pos[j] * d:(pos[j] + 1) * d] = ri.T
            jr[:, nf * d + pos[j] * dr: nf * d + (pos[j] + 1) * dr] = np.eye(dr)
        out[e] = tau[e] * jt.T @ jt + w[e] * jr.T @ jr
    return out


def dense_value(objective: str, g: PoseGraph, kept: np.ndarray, anchor: int = 0) -> float:
    kept = np.asarray(kept)
    tau, kappa = precisions(g.info, g.dim)
    w = rot_weight(kappa, g.dim)
    if objective == "tree":
        lt = dense_laplacian_terms(g, tau, anchor)[kept].sum(0)
        lw = dense_laplacian_terms(g, w, anchor)[kept].sum(0)
        return g.dim * chol_logdet(lt) + (1 if g.dim == 2 else 3) * chol_logdet(lw)
    if objective == "fim":
        return chol_logdet(dense_fim_terms(g, g.vertex_rot, g.vertex_trans, anchor)[kept].sum(0))
    lap = np.zeros((g.n, g.n))
    for e in kept:
        i, j = g.src[e], g.dst[e]
        lap[[i, j], [i, j]] += w[e]
        lap[i, j] -= w[e]
        lap[j, i] -= w[e]
    return float(np.linalg.eigvalsh(lap)[1])


class Exhaustive:
    """Every K-subset of the candidates, values from dense per-edge terms."""

    def __init__(self, objective: str, g: PoseGraph):
        self.objective, self.g = objective, g
        split = split_edges(g)
        self.fixed, self.cand = split.fixed, split.candidates
        tau, kappa = precisions(g.info, g.dim)
        w = rot_weight(kappa, g.dim)
        if objective == "tree":
            self.terms = [(g.dim, dense_laplacian_terms(g, tau)), (1 if g.dim == 2 else 3, dense_laplacian_terms(g, w))]
        elif objective == "fim":
            self.terms = [(1, dense_fim_terms(g, g.vertex_rot, g.vertex_trans))]

    def value(self, subset) -> float:
        kept = np.r_[self.fixed, np.asarray(subset, dtype=int)].astype(int)
        if self.objective == "fiedler":
            return dense_value("fiedler", self.g, kept)
        return sum(c * chol_logdet(t[kept].sum(0)) for c, t in self.terms)

    def best(self, k: int) -> tuple[float, tuple]:
        return max((self.value(s), s) for s in itertools.combinations(self.cand.tolist(), k))

    def greedy_replay(self, k: int) -> list[int]:
        chosen: list[int] = []
        for _ in range(k):
            rest = [e for e in self.cand.tolist() if e not in chosen]
            vals = [self.value(chosen + [e]) for e in rest]
            chosen.append(rest[int(np.argmax(vals))])
        return chosen
