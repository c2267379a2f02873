"""Synthetic pose graphs of our own (docs/design.md#datasets), with the ground truth attached.

Every generator returns a ``PoseGraph`` whose vertices (``vertex_rot``,
``vertex_trans``) are the ground truth and whose measurements are the relative
poses ``X_i^{-1} X_j`` (g2o convention): exactly, or perturbed by the paper's
noise model, eq. (3)-(5) and (80):

* translation ``t~_ij = R_i^T (t_j - t_i) + y_ij``, ``y_ij ~ N(0, I / tau)``
  (``tau = delta^-2``);
* rotation ``R~_ij = R_i^T R_j Z_ij``, ``Z_ij ~ Lang(I, kappa)`` with density
  proportional to ``exp(kappa tr Z)`` (exact sampler ``posecrb.sim.sampling.sample_langevin``).

Information matrices follow SE-Sync's convention (docs/design.md#noise-model,
``posecrb.core.noise.isotropic_information``): 2D ``diag(tau, tau, kappa)``, 3D
``diag(tau I3, 2 kappa I3)``, so that ``graph.tau`` and ``graph.kappa`` read back
exactly the values used to generate the noise.

Generators: ``grid`` (2D/3D lattice walked in boustrophedon order, like the
tiny/small/grid3D benchmarks), ``sphere`` (sphere2500-like rings), ``torus``
(torus3D-like rings), ``octagon`` (the paper's Fig. 2), ``builtin_demo`` (the fixed graph ``make run`` uses when
no dataset is found). Random graphs for tests (parallel edges, gaps in the ids, anisotropic
information) are ``posecrb.sim.random_graphs``.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.choices import SYNTH_KINDS
from ..core.errors import InternalError, UsageError
from ..core.graph import PoseGraph
from ..core.noise import isotropic_information
from ..io.rotations import quat_to_rot
from ..lie.se import relative_poses
from ..lie.so import so2_exp, so3_exp
from .sampling import isotropic_noise

KINDS = SYNTH_KINDS

DEFAULT_TAU = 100.0      # translation precision (delta = 0.1)
DEFAULT_KAPPA = 1000.0   # Langevin concentration (angle std ~ 1/sqrt(2 kappa) = 0.022 rad)
OCTAGON_TAU = 1e4        # paper section VIII-A: delta^2 = 1e-4
OCTAGON_KAPPA = 5e3


# ---- shared machinery ------------------------------------------------------------


def _rng(rng: np.random.Generator | int | None, needed: bool) -> np.random.Generator | None:
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None:
        if needed:
            raise UsageError("noisy generation needs an explicit seed or numpy Generator (rng=...)")
        return None
    return np.random.default_rng(rng)


def _given(rng: np.random.Generator | None) -> np.random.Generator:
    """``rng`` where ``_rng(..., needed=True)`` produced it (so never None)."""
    if rng is None:
        raise InternalError("a random generator is needed here")
    return rng


def assemble_graph(dim: int, rot: np.ndarray, trans: np.ndarray, src: np.ndarray, dst: np.ndarray,
              tau: npt.ArrayLike, kappa: npt.ArrayLike, noise: bool, rng: np.random.Generator | None,
              ids: np.ndarray | None = None, info: np.ndarray | None = None) -> PoseGraph:
    """Measurements from the truth (optionally noisy), isotropic information, truth as vertices."""

    src = np.asarray(src, dtype=np.int64)
    dst = np.asarray(dst, dtype=np.int64)
    m = src.shape[0]
    tau = np.broadcast_to(np.asarray(tau, dtype=float), (m,)).copy()
    kappa = np.broadcast_to(np.asarray(kappa, dtype=float), (m,)).copy()
    if np.any(tau <= 0) or np.any(kappa <= 0):
        raise UsageError("tau and kappa must be > 0")
    mrot, mtrans = relative_poses(rot, trans, src, dst)
    if noise:
        mrot, mtrans = isotropic_noise(mrot, mtrans, tau, kappa, dim, _given(rng))
    n = rot.shape[0]
    return PoseGraph(
        dim=dim, ids=np.arange(n, dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64),
        src=src, dst=dst, rot=mrot, trans=mtrans,
        info=isotropic_information(tau, kappa, dim) if info is None else info,
        vertex_rot=rot, vertex_trans=trans, path=None, format="synthetic",
    )


def _frames(x_axis: np.ndarray, z_axis: np.ndarray) -> np.ndarray:
    """(n, 3, 3) right-handed frames with columns (x, z cross x, z) from orthonormal x and z."""
    return np.stack([x_axis, np.cross(z_axis, x_axis), z_axis], axis=-1)


def _yaw_rotations(yaw: np.ndarray, dim: int) -> np.ndarray:
    if dim == 2:
        return so2_exp(yaw)
    return so3_exp(np.column_stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw]))


def uniform_rotations(n: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """(n, d, d) Haar-uniform rotations (uniform angle in 2D, normalised Gaussian quaternions in 3D)."""
    if dim == 2:
        return so2_exp(rng.uniform(-np.pi, np.pi, n))

    q = rng.standard_normal((n, 4))
    return quat_to_rot(q / np.linalg.norm(q, axis=1, keepdims=True))


# ---- grids -----------------------------------------------------------------------

def boustrophedon(side: int, dim: int, count: int) -> np.ndarray:
    """(count, dim) integer lattice coordinates of the first ``count`` cells of a snake walk.

    Digit i of k (base ``side``) is reflected when ``k // side**(i+1)`` is odd, so
    consecutive cells are always lattice neighbours (reflected mixed-radix Gray order).
    """
    k = np.arange(count, dtype=np.int64)[:, None]
    powers = side ** np.arange(dim, dtype=np.int64)[None, :]
    digits = (k // powers) % side
    flip = ((k // (powers * side)) % 2).astype(bool)
    return np.where(flip, side - 1 - digits, digits)


def grid(dim: int, side: int, *, poses: int | None = None, spacing: float = 1.0,
         tau: float = DEFAULT_TAU, kappa: float = DEFAULT_KAPPA, noise: bool = False,
         rng: np.random.Generator | int | None = None, orientation: str = "travel") -> PoseGraph:
    """A ``side``^dim lattice walked in boustrophedon order (tiny/small/grid3D-like).

    Edges: odometry between consecutive poses, plus one loop closure between every
    other pair of lattice neighbours that are both visited. ``poses`` truncates the
    walk (default: the whole lattice). Orientation: ``"travel"`` faces the direction
    of the next step (vertical steps in 3D keep the previous heading); ``"random"``
    draws Haar-uniform rotations from ``rng``.
    """
    if dim not in (2, 3):
        raise UsageError(f"dimension must be 2 or 3, got {dim}")
    if side < 2:
        raise UsageError("grid side must be >= 2")
    total = side ** dim
    n = total if poses is None else int(poses)
    if not 2 <= n <= total:
        raise UsageError(f"poses must be in [2, {total}] for side {side}")
    rng = _rng(rng, noise or orientation == "random")
    coords = boustrophedon(side, dim, n)
    trans = spacing * coords.astype(float)
    if orientation == "random":
        rot = uniform_rotations(n, dim, _given(rng))
    elif orientation == "travel":
        step = np.diff(coords, axis=0)
        # Heading of the step leaving each pose; vertical steps (3D) and the last pose
        # keep the previous heading (forward fill by running maximum of defined indices).
        has = np.zeros(n, dtype=bool)
        has[:-1] = np.any(step[:, :2] != 0, axis=1)
        yaw = np.zeros(n)
        yaw[:-1] = np.arctan2(step[:, 1], step[:, 0])
        yaw = yaw[np.maximum.accumulate(np.where(has, np.arange(n), 0))]
        rot = _yaw_rotations(yaw, dim)
    else:
        raise UsageError(f"orientation must be 'travel' or 'random', got {orientation!r}")

    # Lattice neighbours: cell index -> walk index, -1 for unvisited cells.
    index = np.full(total, -1, dtype=np.int64)
    flat = (coords * (side ** np.arange(dim))).sum(axis=1)
    index[flat] = np.arange(n)
    cells = np.stack(np.unravel_index(np.arange(total), (side,) * dim, order="F"), axis=1)
    pairs = []
    for axis in range(dim):  # loop over the d axes only, never over poses
        ok = cells[:, axis] < side - 1
        a = index[np.flatnonzero(ok)]
        b = index[np.flatnonzero(ok) + side ** axis]
        keep = (a >= 0) & (b >= 0)
        pairs.append(np.column_stack([a[keep], b[keep]]))
    nb = np.concatenate(pairs)
    lo, hi = nb.min(axis=1), nb.max(axis=1)
    loops = hi - lo != 1
    src = np.concatenate([np.arange(n - 1), lo[loops]])
    dst = np.concatenate([np.arange(1, n), hi[loops]])
    order = np.lexsort((src, dst))  # edges grouped by their later pose, as a robot would record them
    return assemble_graph(dim, rot, trans, src[order], dst[order], tau, kappa, noise, rng)


# ---- surfaces of revolution -------------------------------------------------------

def _ring_walk(rings: int, per_ring: int, poses: int | None, min_rings: int, noise: bool,
               rng: np.random.Generator | int | None) -> tuple[int, np.ndarray, np.random.Generator | None]:
    """(n, pose indices 0..n-1, generator) of a walk ring by ring over ``rings x per_ring`` poses,
    truncated to ``poses``; the sizes are checked here for every surface of revolution."""
    total = rings * per_ring
    n = total if poses is None else int(poses)
    if rings < min_rings or per_ring < 3 or not 2 <= n <= total:
        raise UsageError(f"need rings >= {min_rings}, per_ring >= 3 and 2 <= poses <= {total}")
    return n, np.arange(n), _rng(rng, noise)


def _ring_edges(n: int, per_ring: int, wrap: bool) -> tuple[np.ndarray, np.ndarray]:
    """Odometry chain plus a loop closure from each pose to the one a ring earlier (and wrap-around)."""
    k = np.arange(per_ring, n)
    src = np.concatenate([np.arange(n - 1), k - per_ring])
    dst = np.concatenate([np.arange(1, n), k])
    if wrap:
        first = np.arange(per_ring)
        src = np.concatenate([src, first])
        dst = np.concatenate([dst, n - per_ring + first])
    order = np.lexsort((src, np.maximum(src, dst)))
    return src[order], dst[order]


def sphere(rings: int = 50, per_ring: int = 50, *, poses: int | None = None, radius: float = 50.0,
           tau: float = DEFAULT_TAU, kappa: float = DEFAULT_KAPPA, noise: bool = False,
           rng: np.random.Generator | int | None = None) -> PoseGraph:
    """sphere2500-like: ``rings`` circles of latitude, ``per_ring`` poses each, walked ring by ring.

    Pose (r, j) sits at polar angle ``pi (r + 1) / (rings + 1)`` and azimuth
    ``2 pi j / per_ring``, facing east with z along the outward normal. Edges:
    odometry chain and one loop closure to the pose one ring below
    (50 x 50 gives 2500 poses and 4949 edges, as sphere2500).
    """
    n, k, rng = _ring_walk(rings, per_ring, poses, 1, noise, rng)
    phi = np.pi * (k // per_ring + 1) / (rings + 1)
    theta = 2 * np.pi * (k % per_ring) / per_ring
    normal = np.column_stack([np.sin(phi) * np.cos(theta), np.sin(phi) * np.sin(theta), np.cos(phi)])
    east = np.column_stack([-np.sin(theta), np.cos(theta), np.zeros(n)])
    src, dst = _ring_edges(n, per_ring, wrap=False)
    return assemble_graph(3, _frames(east, normal), radius * normal, src, dst, tau, kappa, noise, rng)


def torus(rings: int = 100, per_ring: int = 50, *, poses: int | None = None, major: float = 50.0,
          minor: float = 15.0, tau: float = DEFAULT_TAU, kappa: float = DEFAULT_KAPPA, noise: bool = False,
          rng: np.random.Generator | int | None = None) -> PoseGraph:
    """torus3D-like: ``rings`` circles around the tube, ``per_ring`` poses each.

    Pose (r, j) at major angle ``u = 2 pi r / rings`` and tube angle
    ``v = 2 pi j / per_ring``, x along the tube circle, z along the outward tube
    normal. Edges: odometry chain, a loop closure to the pose one ring back, and,
    when the torus is complete, from the last ring back to the first.
    """
    n, k, rng = _ring_walk(rings, per_ring, poses, 3, noise, rng)
    u = 2 * np.pi * (k // per_ring) / rings
    v = 2 * np.pi * (k % per_ring) / per_ring
    cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
    trans = np.column_stack([(major + minor * cv) * cu, (major + minor * cv) * su, minor * sv])
    normal = np.column_stack([cv * cu, cv * su, sv])
    tangent = np.column_stack([-sv * cu, -sv * su, cv])
    src, dst = _ring_edges(n, per_ring, wrap=n == rings * per_ring)
    return assemble_graph(3, _frames(tangent, normal), trans, src, dst, tau, kappa, noise, rng)


# ---- the paper's octagon (Fig. 2-5) -----------------------------------------------

def octagon_candidate_edges() -> list[tuple[int, int]]:
    """The 21 additional measurements of section VIII-A: every pair of poses 1..7.

    "Because the first pose is the anchor, the additional edges are not allowed to be
    connected with the first pose", and 21 = C(7, 2): pairs of consecutive poses
    are allowed and become parallel edges to the odometry.
    """
    return [(i, j) for i in range(1, 8) for j in range(i + 1, 8)]


def octagon(extra_edges: int | Iterable[tuple[int, int]] = 0, *, radius: float = 1.0,
            tau: float = OCTAGON_TAU, kappa: float = OCTAGON_KAPPA, noise: bool = False,
            rng: np.random.Generator | int | None = None) -> PoseGraph:
    """The paper's Fig. 2: 8 poses on a regular octagon, odometry chain 0-1-...-7.

    ``delta^2 = 1e-4`` (tau = 1e4) and kappa = 5e3 on every edge. Pose k sits at
    angle ``2 pi k / 8`` on a circle of ``radius`` and faces along the octagon
    (tangent). ``extra_edges``: an explicit list of (i, j) pose pairs, or a count k:
    the first k pairs of ``octagon_candidate_edges()``, or, when ``rng`` is given, k
    pairs drawn without repetition from those 21 candidates (as in Fig. 3-5).
    """
    cand = octagon_candidate_edges()
    if isinstance(extra_edges, (int, np.integer)):
        k = int(extra_edges)
        if not 0 <= k <= len(cand):
            raise UsageError(f"extra_edges must be in [0, {len(cand)}]")
        gen = _rng(rng, noise)
        pick = gen.permutation(len(cand))[:k] if gen is not None else np.arange(k)
        extra = [cand[p] for p in pick]
    else:
        extra = [(int(i), int(j)) for i, j in extra_edges]
        gen = _rng(rng, noise)
        bad = [(i, j) for i, j in extra if not (0 <= i < 8 and 0 <= j < 8) or i == j]
        if bad:
            raise UsageError(f"octagon edges must join two distinct poses 0..7, got {bad}")
    ang = 2 * np.pi * np.arange(8) / 8
    trans = radius * np.column_stack([np.cos(ang), np.sin(ang)])
    rot = so2_exp(ang + np.pi / 2)
    src = np.concatenate([np.arange(7), np.array([e[0] for e in extra], dtype=np.int64)])
    dst = np.concatenate([np.arange(1, 8), np.array([e[1] for e in extra], dtype=np.int64)])
    return assemble_graph(2, rot, trans, src, dst, tau, kappa, noise, gen)


# ---- the built-in demo --------------------------------------------------------------

DEMO_SEED = 20240501


def builtin_demo() -> PoseGraph:
    """The graph ``make run`` uses when no dataset is found: a noisy 10 x 10 2D grid.

    100 poses, 180 edges (99 odometry + 81 loop closures), tau = 100 (delta = 0.1),
    kappa = 1000, noise drawn with the fixed seed ``DEMO_SEED``; vertices are the
    ground truth. Same bytes on every run and machine (numpy's PCG64 stream).
    """
    return grid(2, 10, tau=DEFAULT_TAU, kappa=DEFAULT_KAPPA, noise=True, rng=DEMO_SEED)


# ---- front door for the CLI ----------------------------------------------------------

def generate(kind: str, poses: int | None = None, *, tau: float | None = None, kappa: float | None = None,
             noise: bool = False, seed: int | None = None, extra_edges: int = 0) -> PoseGraph:
    """One of ``KINDS`` sized by a pose count (``datasets synth``).

    grid2d/grid3d: side ``ceil(poses^(1/d))``, walk truncated to ``poses``;
    sphere: ``ceil(sqrt(poses))`` rings of as many poses; torus: rings of
    ``round(sqrt(poses / 2))`` poses (100 x 50 for 5000, as torus3D); octagon: 8
    poses (``poses`` must be 8 or None) with ``extra_edges`` from
    ``octagon_candidate_edges()`` (random when a seed is given); demo: ``builtin_demo()``.
    """
    if kind not in KINDS:
        raise UsageError(f"unknown generator {kind!r}; choose from {', '.join(KINDS)}")
    if kind == "demo":
        return builtin_demo()
    if kind == "octagon":
        if poses not in (None, 8):
            raise UsageError("the octagon has 8 poses")
        return octagon(extra_edges, tau=OCTAGON_TAU if tau is None else tau,
                       kappa=OCTAGON_KAPPA if kappa is None else kappa, noise=noise, rng=seed)
    tau = DEFAULT_TAU if tau is None else tau
    kappa = DEFAULT_KAPPA if kappa is None else kappa
    common: dict[str, Any] = {"tau": tau, "kappa": kappa, "noise": noise, "rng": seed}
    if kind in ("grid2d", "grid3d"):
        d = 2 if kind == "grid2d" else 3
        n = poses or (100 if d == 2 else 125)
        side = max(2, _iroot_ceil(n, d))
        return grid(d, side, poses=n, **common)
    if kind == "sphere":
        n = poses or 2500
        side = max(3, math.isqrt(n - 1) + 1)
        return sphere(side, side, poses=n, **common)
    n = poses or 5000
    per_ring = max(3, round(math.sqrt(n / 2)))
    rings = max(3, -(-n // per_ring))
    return torus(rings, per_ring, poses=n, **common)


def _iroot_ceil(n: int, d: int) -> int:
    """Smallest s with s**d >= n (exact integer arithmetic)."""
    s = max(1, int(round(n ** (1.0 / d))))
    while s ** d < n:
        s += 1
    while s > 1 and (s - 1) ** d >= n:
        s -= 1
    return s


__all__: Sequence[str] = (
    "KINDS", "uniform_rotations", "boustrophedon", "grid", "sphere", "torus",
    "octagon", "octagon_candidate_edges", "builtin_demo", "assemble_graph",
    "generate", "DEMO_SEED",
)
