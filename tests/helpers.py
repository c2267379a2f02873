"""Builders and dense references shared by the tests (test modules do not import each other).

Small synthetic pose graphs with known ground truth (for tests and benchmarks of the solver).

Edges are an odometry chain plus random loop closures; each measurement is the true
relative pose ``X_i^{-1} X_j`` perturbed by isotropic noise (rotation: exp of a Gaussian
tangent vector; translation: Gaussian), with information matrices encoding the given
(tau, kappa) in the SE-Sync convention (docs/design.md#noise-model).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

import posecrb
from posecrb.core.graph import PoseGraph
from posecrb.core.noise import isotropic_information, rotation_weights
from posecrb.core.result import Result
from posecrb.lie import se as L
from posecrb.lie.so import so2_exp, so3_exp
from posecrb.sim.generators import uniform_rotations
from posecrb.sim.random_graphs import random_graph

# Every public result type by name: the protocol and misuse tests run over all of them.
PUBLIC_RESULT_TYPES = sorted(n for n in posecrb.__all__ if isinstance(getattr(posecrb, n), type)
                             and issubclass(getattr(posecrb, n), Result))


def _small_rotations(m: int, dim: int, sigma: float, rng: np.random.Generator) -> np.ndarray:
    if dim == 2:
        return so2_exp(sigma * rng.standard_normal(m))
    return so3_exp(sigma * rng.standard_normal((m, 3)))


def random_pose_graph(n: int, dim: int, rng: np.random.Generator, *, loop_closures: int | None = None,
                      rot_noise: float = 0.0, trans_noise: float = 0.0, tau: float = 10.0,
                      kappa: float = 50.0, step: float = 1.0) -> tuple[PoseGraph, np.ndarray, np.ndarray]:
    """(graph, true rotations (n, d, d), true translations (n, d)); vertices hold the truth."""
    rot = uniform_rotations(n, dim, rng)
    trans = np.cumsum(step * rng.standard_normal((n, dim)), axis=0)
    k = n if loop_closures is None else loop_closures
    src = np.arange(n - 1)
    dst = np.arange(1, n)
    if k > 0 and n > 2:
        a = rng.integers(0, n, size=4 * k)
        b = rng.integers(0, n, size=4 * k)
        keep = a != b
        a, b = a[keep][:k], b[keep][:k]
        src = np.concatenate([src, np.minimum(a, b)])
        dst = np.concatenate([dst, np.maximum(a, b)])
    m = src.shape[0]
    rel_rot = np.swapaxes(rot[src], 1, 2) @ rot[dst] @ _small_rotations(m, dim, rot_noise, rng)
    rel_t = np.einsum("eba,eb->ea", rot[src], trans[dst] - trans[src]) + trans_noise * rng.standard_normal((m, dim))
    q = 3 if dim == 2 else 6
    info = np.zeros((m, q, q))
    info[:, :dim, :dim] = tau * np.eye(dim)
    info[:, dim:, dim:] = (kappa if dim == 2 else 2.0 * kappa) * np.eye(q - dim)
    graph = PoseGraph(dim=dim, ids=np.arange(n), src=src, dst=dst, rot=rel_rot, trans=rel_t, info=info,
                      vertex_rot=rot, vertex_trans=trans, format="synthetic")
    return graph, rot, trans


def objective_loop(graph: PoseGraph, rot, trans) -> float:
    """F(R, t) edge by edge, written independently of the package."""
    total = 0.0
    for e in range(graph.m):
        i, j = graph.src[e], graph.dst[e]
        total += graph.kappa[e] * np.sum((rot[j] - rot[i] @ graph.rot[e]) ** 2)
        total += graph.tau[e] * np.sum((trans[j] - trans[i] - rot[i] @ graph.trans[e]) ** 2)
    return float(total)


def random_rotations(rng: np.random.Generator, k: int, dim: int) -> np.ndarray:
    if dim == 2:
        return so2_exp(rng.uniform(-np.pi, np.pi, k))
    return so3_exp(rng.normal(size=(k, 3)))


def random_spd(rng: np.random.Generator, k: int, q: int, scale: float = 10.0) -> np.ndarray:
    a = rng.normal(size=(k, q, q))
    return scale * (a @ a.transpose(0, 2, 1) / q + 0.5 * np.eye(q))


def make_random_graph(rng: np.random.Generator, n: int = 8, extra: int = 6, dim: int = 2,
                      parallel: int = 2, sparse_ids: bool = True, block_isotropic: bool = False) -> PoseGraph:
    """A connected random graph from the library's generator (``posecrb.sim.generators.random_graph``):
    a random spanning tree + ``extra`` random edges + ``parallel`` more (one of them repeating a tree
    edge), anisotropic information with eigenvalues in [5, 50] (full, or without cross terms with
    ``block_isotropic``): rotation information weak enough for the curvature terms to matter; ids with
    gaps unless not ``sparse_ids``, the truth as vertices and exact measurements."""
    return random_graph(rng, n, n - 1 + extra + parallel, dim, info="block" if block_isotropic else "full",
                        parallel=parallel > 0, id_gaps=sparse_ids, scale=3.0,
                        tau_range=(5.0, 50.0), kappa_range=(5.0, 50.0))


def _fd_error(jac, weights, r_max, h, f) -> float:
    """Relative 2-norm error bound of ``J^T W J`` from central differences (``dense_model_fisher``)."""
    from .numerics import EPS, MARGIN

    d_jac = np.sqrt(jac.size) * EPS * r_max / h
    return MARGIN * 2 * weights.max() * np.linalg.norm(jac, 2) * d_jac / np.linalg.norm(f, 2)


def _body_perturbed(rot: np.ndarray, dim: int, delta: np.ndarray) -> np.ndarray:
    """R Exp(delta) along R E (2D angle; 3D E_k = G_k / sqrt 2), through scipy only."""
    if dim == 2:
        c, s = np.cos(delta[0]), np.sin(delta[0])
        return rot @ np.array([[c, -s], [s, c]])
    return rot @ Rotation.from_rotvec(np.asarray(delta) / np.sqrt(2.0)).as_matrix()


def _rotation_coords(mat: np.ndarray, dim: int) -> np.ndarray:
    """Coordinates of Log(mat) in the FIM's basis: the angle (2D), sqrt 2 * rotation vector (3D)."""
    if dim == 2:
        return np.array([np.arctan2(mat[1, 0], mat[0, 0])])
    return np.sqrt(2.0) * Rotation.from_matrix(mat).as_rotvec()


def central_jacobian(residual, rot: np.ndarray, trans: np.ndarray, free, h: float) -> np.ndarray:
    """Jacobian of ``residual(rot, trans)`` by central differences of step ``h`` over the poses
    ``free``: columns [translations x_k + dx; rotations R_k Exp(delta)] (body frame, the FIM's
    rotation basis: the angle in 2D, E_k = G_k / sqrt 2 in 3D)."""
    d = rot.shape[-1]
    dr = 1 if d == 2 else 3
    cols = []
    for k in free:
        for a in range(d):
            tp, tm = trans.copy(), trans.copy()
            tp[k, a] += h
            tm[k, a] -= h
            cols.append((residual(rot, tp) - residual(rot, tm)) / (2 * h))
    for k in free:
        for a in range(dr):
            delta = np.zeros(dr)
            delta[a] = h
            rp, rm = rot.copy(), rot.copy()
            rp[k] = _body_perturbed(rot[k], d, delta)
            rm[k] = _body_perturbed(rot[k], d, -delta)
            cols.append((residual(rp, trans) - residual(rm, trans)) / (2 * h))
    return np.stack(cols, axis=1)


def dense_model_fisher(graph, rot, trans, anchor: int, h: float = 1e-6, with_error: bool = False):
    """Fisher information J^T W J of the model's mean function, from central differences,
    every pose perturbed in its body frame (x_k + dx, R_k Exp(delta)), order [translations;
    rotations]. Per edge: translation residual R_i^T (x_j - x_i) - p_ij (weight tau I_d) and
    rotation residual Log(Rbar_ij^T R_i^T R_j) in the E_k coordinates (weight w I_dr, eq. 39-41 /
    59), with Rbar_ij = R_i^T R_j at the estimate itself: the noise-free measurement, where the
    Jacobian of the residual is that of the mean function, as the Fisher information needs.

    ``with_error=True`` also returns a bound on the relative 2-norm error of the result: central
    differences of residuals of size at most R carry a rounding error ``eps R / h`` per Jacobian
    entry (the truncation error, h^2 times a third derivative, is far smaller for h = 1e-6), so
    ``||dF|| <= 2 ||W|| ||J|| ||dJ||_F`` relative to ``||F||``, times ``MARGIN``."""
    d = graph.dim
    dr = 1 if d == 2 else 3
    rbar = [rot[i].T @ rot[j] for i, j in zip(graph.src, graph.dst)]

    def residual(r, t):
        out = []
        for e, (i, j) in enumerate(zip(graph.src, graph.dst)):
            out.append(r[i].T @ (t[j] - t[i]) - graph.trans[e])
            out.append(_rotation_coords(rbar[e].T @ r[i].T @ r[j], d))
        return np.concatenate(out)

    jac = central_jacobian(residual, rot, trans, [k for k in range(graph.n) if k != anchor], h)
    w = rotation_weights(graph.kappa, d)
    weights = np.concatenate([np.concatenate([np.full(d, t), np.full(dr, v)]) for t, v in zip(graph.tau, w)])
    f = jac.T @ (weights[:, None] * jac)
    if not with_error:
        return f
    r_max = max(np.abs(residual(rot, trans)).max(), np.abs(graph.trans).max(), np.abs(trans).max())
    return f, _fd_error(jac, weights, r_max, h, f)


def hat_ref(xi: np.ndarray) -> np.ndarray:
    """Generators written out from the thesis' basis (sec. 6.2 for SE(2), 2.5 for SE(3))."""
    if xi.size == 3:
        w, x, y = xi
        return np.array([[0, -w, x], [w, 0, y], [0, 0, 0]], float)
    w1, w2, w3, v1, v2, v3 = xi
    return np.array([[0, -w3, w2, v1], [w3, 0, -w1, v2], [-w2, w1, 0, v3], [0, 0, 0, 0]], float)


def gtsam_information(graph: PoseGraph) -> np.ndarray:
    """(m, q, q) file information in GTSAM's order (2D unchanged; 3D rotation block first)."""
    p = np.arange(3) if graph.dim == 2 else np.r_[3:6, 0:3]
    return graph.info[:, p][:, :, p]


def body_fim_reference(graph: PoseGraph, rot, trans) -> np.ndarray:
    """Dense ``sum J^T I J`` with J = d e_ij / d(xi_i, xi_j) by central differences.

    The perturbation ``expm(hat(+-H e_a))`` is one 4x4 (3x3) matrix per coordinate; the
    logarithm of the perturbed relative poses is ``se_lie.se_log`` (closed form, checked
    against scipy's logm in tests/lie/test_se_lie.py), batched over the edges."""
    q, n, d = graph.q, graph.n, graph.dim
    info = gtsam_information(graph)
    xs = np.stack([homog(rot[i], trans[i]) for i in range(n)])
    zinv = np.linalg.inv(np.stack([homog(a, b) for a, b in zip(graph.rot, graph.trans)]))
    xi, xj = xs[graph.src], xs[graph.dst]
    to_gtsam = np.array([1, 2, 0]) if d == 2 else np.arange(6)

    def err(ei, ej):
        a = zinv @ np.linalg.inv(xi @ ei) @ xj @ ej
        return L.se_log(a[:, :d, :d], a[:, :d, d])[:, to_gtsam]

    one = np.eye(d + 1)
    jac_i = np.empty((graph.m, q, q))
    jac_j = np.empty((graph.m, q, q))
    for a in range(q):  # q coordinates, each batched over every edge
        e = np.zeros(q)
        e[a] = H
        ep, em = expm(hat_gtsam(e)), expm(hat_gtsam(-e))
        jac_i[:, :, a] = (err(ep, one) - err(em, one)) / (2 * H)
        jac_j[:, :, a] = (err(one, ep) - err(one, em)) / (2 * H)
    w = 0.5 * (info + np.swapaxes(info, 1, 2))
    f = np.zeros((n * q, n * q))
    for k in range(graph.m):
        jac = np.zeros((q, n * q))
        i, j = int(graph.src[k]), int(graph.dst[k])
        jac[:, i * q:(i + 1) * q] += jac_i[k]
        jac[:, j * q:(j + 1) * q] += jac_j[k]
        f += jac.T @ w[k] @ jac
    return f


def perturbed_graph(rng: np.random.Generator, dim: int, noise: float = 0.3, **kw) -> PoseGraph:
    """``make_random_graph(rng, dim=dim, **kw)`` whose measurements are its vertices' relative poses
    times Exp(xi), xi ~ N(0, noise^2 I): residual angles ~ noise, well inside (-pi, pi), far from
    the branch cut of Log where the dense references break down; anisotropic full information."""
    g = make_random_graph(rng, dim=dim, **kw)
    ri, ti = L.se_inverse(g.vertex_rot[g.src], g.vertex_trans[g.src])
    rz, tz = L.se_compose(ri, ti, g.vertex_rot[g.dst], g.vertex_trans[g.dst])
    re, te = L.se_exp(noise * rng.normal(size=(g.m, g.q)))
    rz, tz = L.se_compose(rz, tz, re, te)
    return replace(g, rot=rz, trans=tz)


def consistent_graph(dim: int, seed: int, noise: float = 0.1, **kw) -> PoseGraph:
    """``perturbed_graph`` from a seed, with small residuals (noise 0.1) by default."""
    return perturbed_graph(np.random.default_rng(seed), dim, noise, **kw)


def drop_edges(graph: PoseGraph, drop: np.ndarray) -> PoseGraph:
    """The graph without the edges where the boolean mask ``drop`` is true (vertices kept)."""
    keep = ~np.asarray(drop, dtype=bool)
    return replace(graph, src=graph.src[keep], dst=graph.dst[keep], rot=graph.rot[keep],
                   trans=graph.trans[keep], info=graph.info[keep])


def component_count(graph: PoseGraph) -> int:
    """Connected components of the graph's poses, by scipy's union-find (independent of PoseGraph)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    adj = coo_matrix((np.ones(graph.m), (graph.src, graph.dst)), shape=(graph.n, graph.n))
    return int(connected_components(adj, directed=False)[0])


def free_dofs(n: int, q: int, anchors) -> np.ndarray:
    keep = np.setdiff1d(np.arange(n), anchors)
    return (keep[:, None] * q + np.arange(q)).ravel()


# Finite differences: step H, truncation ~H^2 and rounding ~eps/H (the closed-form Log is
# accurate to a few eps) put each Jacobian entry within ~1e-10 relative; FD_RTOL leaves a
# margin of 100 for F; an inverse loses at most cond(F) more.
H = 1e-5


# ------------------------------------------------------------------ independent reference
def hat_gtsam(xi: np.ndarray) -> np.ndarray:
    """hat() of a tangent vector in GTSAM's order."""
    if xi.size == 3:
        x, y, th = xi
        return np.array([[0, -th, x], [th, 0, y], [0, 0, 0]], float)
    w1, w2, w3, v1, v2, v3 = xi
    return np.array([[0, -w3, w2, v1], [w3, 0, -w1, v2], [-w2, w1, 0, v3], [0, 0, 0, 0]], float)


def vee_gtsam(x: np.ndarray) -> np.ndarray:
    if x.shape[0] == 3:
        return np.array([x[0, 2], x[1, 2], x[1, 0]])
    return np.array([x[2, 1], x[0, 2], x[1, 0], x[0, 3], x[1, 3], x[2, 3]])


def homog(r, t):
    d = r.shape[-1]
    out = np.eye(d + 1)
    out[:d, :d], out[:d, d] = r, t
    return out


# SE-Sync stops its trust region at a 1e-6 relative decrease: a reference more than that above
# our certified value must be shown not to be the minimum (a feasible estimate below it).
SESYNC_STOP = 1e-6


def print_rounding(value: float) -> float:
    """Half a unit of the last digit of a value as typed in (REFERENCE literals: SE-Sync's printout)."""
    from decimal import Decimal

    return 0.5 * 10.0 ** Decimal(repr(value)).as_tuple().exponent


def _bridge_graph(dim: int, weak: float):
    """Two 4-pose clusters (tau 100, kappa 1000) joined by one edge of precision ``weak``."""
    from posecrb.core.graph import PoseGraph
    from posecrb.core.noise import isotropic_information
    from posecrb.lie.se import relative_poses
    from posecrb.sim.generators import uniform_rotations

    rng = np.random.default_rng(2)
    src, dst = np.array([0, 1, 2, 0, 4, 5, 6, 4, 3]), np.array([1, 2, 3, 2, 5, 6, 7, 6, 4])
    rot, trans = uniform_rotations(8, dim, rng), 3 * rng.standard_normal((8, dim))
    mr, mt = relative_poses(rot, trans, src, dst)
    tau, kappa = np.full(9, 100.0), np.full(9, 1000.0)
    tau[-1] = kappa[-1] = weak
    return PoseGraph(dim=dim, ids=np.arange(8), src=src, dst=dst, rot=mr, trans=mt,
                     info=isotropic_information(tau, kappa, dim), vertex_rot=rot, vertex_trans=trans,
                     format="synthetic")


def run_cli(argv, capsys):
    """(exit code, stdout, stderr) of ``posecrb ARGV`` through the entry point's error mapping."""
    from posecrb.cli import main

    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def record_factor_full(monkeypatch) -> list[tuple[str, float]]:
    """Record (name, shift) of every ``Problem.factor_full`` call from now on (monkeypatched)."""
    from posecrb.solver.problem import Problem

    calls: list[tuple[str, float]] = []
    real = Problem.factor_full

    def recording(self, lam, shift, name):
        calls.append((name, shift))
        return real(self, lam, shift, name)

    monkeypatch.setattr(Problem, "factor_full", recording)
    return calls


def ring(n: int, dim: int, seed: int = 1, noise: float = 0.01, closures: int = 0) -> PoseGraph:
    """A noisy ring of n poses on a circle of radius 10 (plus a few chords), vertices the truth."""
    rng = np.random.default_rng(seed)
    ang = 2 * np.pi * np.arange(n) / n
    z = np.zeros(n)
    if dim == 2:
        rot, trans = so2_exp(ang + np.pi / 2), 10 * np.column_stack([np.cos(ang), np.sin(ang)])
    else:
        rot = so3_exp(np.column_stack([z, z, ang + np.pi / 2]))
        trans = 10 * np.column_stack([np.cos(ang), np.sin(ang), z])
    src, dst = np.arange(n), (np.arange(n) + 1) % n
    if closures:
        a = rng.choice(n, closures, replace=False)
        src, dst = np.concatenate([src, a]), np.concatenate([dst, (a + n // 2) % n])
    m = src.size
    turn = so2_exp(noise * rng.standard_normal(m)) if dim == 2 else so3_exp(noise * rng.standard_normal((m, 3)))
    rel = np.swapaxes(rot[src], 1, 2) @ rot[dst] @ turn
    rel_t = np.einsum("eba,eb->ea", rot[src], trans[dst] - trans[src]) + noise * rng.standard_normal((m, dim))
    info = isotropic_information(np.full(m, 100.0), np.full(m, 100.0), dim)
    return PoseGraph(dim=dim, ids=np.arange(n) * 3 + 5, src=src, dst=dst, rot=rel, trans=rel_t, info=info,
                     vertex_rot=rot, vertex_trans=trans, format="synthetic")
