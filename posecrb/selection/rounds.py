"""The round greedy: the greedy of the log-det objectives in R rounds, for budgets too large for the
incremental greedy's K steps over the whole factor (``posecrb.selection.greedy``).

Each step of the incremental greedy solves with the whole factor and passes over every candidate,
so K steps cost about K times the graph: quadratic on the large grids, where K is a fifth of the
candidates. The round greedy spends that global work once per round instead:

* a round starts exactly: the factor of the current set and every alive candidate's
  ``H_f = U_f^T M^{-1} U_f`` (``LogDetBlock.h_many``), hence its exact gain, and Minoux's bound
  ``f(OPT) <= f(S) + (sum of the K largest gains at S)`` at the round's set S;
* within the round, candidates are chosen greedily by their gains, each choice e correcting the gains
  of the candidates near it by the Woodbury identity ``H_f <- H_f - C (I + H_e)^{-1} C^T`` with
  ``C = U_f^T Phi_e``, where ``Phi_e`` is ``M^{-1} U_e`` approximated in the **ball** of e: the poses
  within ``RADIUS x R_e`` of e's end poses in the current graph (edge lengths 1/strength, R_e = e's
  ``trace(H_e) / r`` over its strength: its effective resistance for a Laplacian), with the
  boundary held at zero (the ball's principal submatrix of M, a Dirichlet problem, solved by
  conjugate gradients preconditioned by the ball's shortest-path tree, ``posecrb.selection._local``)
  and then scaled to give back the exact ``H_e``, which the grounded boundary lowers.

The corrections use the round's first matrix (one Woodbury term per earlier choice of the round, not
their product) and only within balls, so the choices after a round's first are approximate: the set
may differ from the exact greedy's. What is reported stays exact: the value of the chosen set is
evaluated from scratch, and every upper bound (Minoux's at each round's start and at the chosen set,
``posecrb.selection.certificate``) is taken from exact gains, so it holds whatever the choices were.
Nothing is random: the same problem gives the same set.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from types import ModuleType

import numpy as np

from ..core.errors import InternalError, UsageError
from .objectives import LogDetObjective, logdet_eye_plus

# ``auto`` greedy takes the round greedy above this many steps (K) on graphs of this many poses or more;
# the incremental greedy, exact, stays the default on the others: every shared dataset (at most 15,115
# poses) at every budget, and the 2D grid of 10,000 poses at 20% (docs/decisions/selection-at-scale.md).
ROUNDS_FROM_STEPS = 4096
ROUNDS_FROM_POSES = 20_000
# Rounds of the round greedy: each costs one factorization and one selected inversion.
ROUNDS = 24
# The ball of a chosen candidate e reaches RADIUS x R_e from its end poses, with at most BALL_ROWS rows
# (the nearest poses): the Fisher information's R_e grows with a path's length cubed (rotation errors
# move the poses by their lever arms), so without it a ball would hold most of a large graph.
RADIUS = 2.0
BALL_ROWS = 4096
# A ball's potential: conjugate gradients to this relative residual (the potential corrects gains, two
# or three digits suffice), at most this many iterations: preconditioned by the ball's shortest-path
# tree they took 2-15 on the tree objective's balls on the grids, 10-60 on the Fisher information's,
# whose off-tree blocks carry the loop closures' rotation coupling. A stopped solve is counted.
CG_TOL = 1e-3
CG_MAX_ITER = 40


def _compiled() -> ModuleType:
    from . import _local  # noqa: PLC0415 -- lazy: start-up time (numba)

    return _local


@dataclass(frozen=True)
class RoundStats:
    """What the round greedy did (the JSON ``stats`` with ``strategy: rounds``)."""

    rounds: int                 # rounds run: each one factorization and one selected inversion
    round_sizes: list[int]      # candidates chosen per round
    radius: float               # RADIUS
    local_solves: int           # balls solved for a local potential (every choice but each round's last)
    local_poses: int            # poses of those balls, summed
    largest_ball: int           # poses of the largest ball
    corrections: int            # gains corrected by a choice's local potential
    cg_iterations: int          # conjugate-gradient iterations of the local solves (per block and column)
    cg_unconverged: int         # local solves stopped at CG_MAX_ITER above CG_TOL
    online_bound: float         # the smallest of Minoux's bounds at the rounds' starts

    def to_dict(self) -> dict:
        return {"strategy": "rounds", **asdict(self)}


def round_sizes(k: int, rounds: int) -> list[int]:
    """K split into ``min(rounds, K)`` rounds of sizes differing by at most one (the larger first)."""
    r = min(rounds, k)
    return [k // r + (1 if i < k % r else 0) for i in range(r)]


def _pose_rows(obj: LogDetObjective) -> np.ndarray:
    """(n, rows per pose): each pose's rows in the blocks (-1 for the anchor's), from the edges: rows
    0..p/2-1 of an edge belong to its first pose, the rest to its second. Checked consistent and
    shared by every block, with a pose's rows all valid or all anchored."""
    b0 = obj.blocks[0]
    p = b0.rows.shape[1]
    rpp = p // 2
    if obj.src is None or obj.dst is None or obj.n is None or p != 2 * rpp:
        raise InternalError(f"{obj.name}: the round greedy needs the objective's poses and two end poses per edge")
    out = np.full((obj.n, rpp), -1, dtype=np.int64)
    sides = [(poses, np.where(b0.valid[:, side * rpp:(side + 1) * rpp], b0.rows[:, side * rpp:(side + 1) * rpp], -1))
             for side, poses in enumerate((obj.src, obj.dst))]
    for poses, rows in sides:
        out[poses] = rows
    if not all(np.array_equal(out[poses], rows) for poses, rows in sides):
        raise InternalError(f"{obj.name}: an edge's rows disagree with its poses' rows")
    if not np.all((out >= 0).all(axis=1) | (out < 0).all(axis=1)):
        raise InternalError(f"{obj.name}: a pose with valid and anchored rows")
    for b in obj.blocks[1:]:
        if not (np.array_equal(b.rows, b0.rows) and np.array_equal(b.valid, b0.valid) and b.U.shape == b0.U.shape):
            raise InternalError(f"{obj.name}: the blocks do not share their rows")
    return out


def _csr(n: int, heads: np.ndarray, tails: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, ...]:
    """(indptr, tails, values) of the lists heads -> (tail, value), grouped by head (stable)."""
    order = np.argsort(heads, kind="stable")
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(heads, minlength=n), out=ptr[1:])
    return ptr, np.ascontiguousarray(tails[order]), np.ascontiguousarray(values[order])


def _round(obj: LogDetObjective, x: np.ndarray, ce: np.ndarray, hs: np.ndarray, keys: np.ndarray,
           pose_rows: np.ndarray, strength: np.ndarray, radius: float, take: int) -> tuple[np.ndarray, np.ndarray]:
    """One round's ``take`` choices among the alive candidates ``ce`` from the exact state at x
    (``hs`` their H per block, ``keys`` their gains): positions in ``ce`` in order, and the
    kernel's counters (``_local.round_steps``)."""
    n = obj.n
    assert n is not None and obj.src is not None and obj.dst is not None
    sel = np.flatnonzero(x > 0)
    adj = _csr(n, np.r_[obj.src[sel], obj.dst[sel]], np.r_[obj.dst[sel], obj.src[sel]], np.tile(1.0 / strength[sel], 2))
    ends = np.ascontiguousarray(np.stack([obj.src[ce], obj.dst[ce]], axis=1))
    pos = np.arange(ce.size, dtype=np.int64)
    inc_ptr, inc_cand, _ = _csr(n, ends.T.ravel(), np.r_[pos, pos], np.zeros(2 * ce.size))
    us = np.ascontiguousarray(np.stack([b.U[ce] for b in obj.blocks]))
    mats = [b.matrix(x) for b in obj.blocks]
    if any(not (np.array_equal(m.indptr, mats[0].indptr) and np.array_equal(m.indices, mats[0].indices))
           for m in mats[1:]):  # pragma: no cover - the blocks share their rows, hence their pattern
        raise InternalError(f"{obj.name}: the blocks' matrices do not share their pattern")
    data = np.ascontiguousarray(np.stack([m.data for m in mats]))
    # each candidate's R_e from its exact H at the round's start: its ball's radius
    reach = radius * (np.trace(hs[0], axis1=1, axis2=2) / hs.shape[2]) / strength[ce]
    mult = np.array([b.mult for b in obj.blocks])
    cap = max(2, BALL_ROWS // pose_rows.shape[1])
    return _compiled().round_steps(keys, hs, us, mult, ends, reach, cap, inc_ptr, inc_cand, *adj, pose_rows,
                                   mats[0].indptr.astype(np.int64), mats[0].indices.astype(np.int64), data, take,
                                   CG_TOL, CG_MAX_ITER)


def round_greedy(obj: LogDetObjective, x: np.ndarray, cand: np.ndarray, k: int, rounds: int | None = None,
                 radius: float | None = None) -> tuple[np.ndarray, RoundStats]:
    """The round greedy (module docstring): K of the candidates ``cand`` added to the weights ``x``
    (changed in place) in ``rounds`` rounds (default ROUNDS). Returns the chosen edges in order and
    what the rounds did, with the smallest of Minoux's bounds at their starts."""
    rounds = ROUNDS if rounds is None else int(rounds)
    radius = RADIUS if radius is None else float(radius)
    if rounds < 1:
        raise UsageError(f"rounds must be an integer >= 1, not {rounds!r}")
    pose_rows = _pose_rows(obj)
    b0 = obj.blocks[0]
    # an edge's strength: its mean squared entry per row and column (the weight w of a Laplacian edge)
    strength = np.maximum(np.einsum("mpr,mpr->m", b0.U, b0.U) / b0.U.shape[2] / 2.0, np.finfo(float).tiny)
    alive = np.ones(cand.size, dtype=bool)
    sizes = round_sizes(k, rounds)
    order: list[np.ndarray] = []
    online = math.inf
    counters = np.zeros(6, dtype=np.int64)
    for take in sizes:
        state = obj.evaluate(x)
        idx = np.flatnonzero(alive)
        ce = cand[idx]
        hs = np.ascontiguousarray(np.stack([b.h_many(f, ce) for b, f in zip(obj.blocks, state.data)]))
        keys = sum((b.mult * logdet_eye_plus(h) for b, h in zip(obj.blocks, hs)), np.zeros(ce.size))
        online = min(online, state.value + float(np.partition(keys, keys.size - k)[keys.size - k:].sum()
                                                 if keys.size > k else keys.sum()))
        picks, stats = _round(obj, x, ce, hs, keys, pose_rows, strength, radius, take)
        if picks.size != take:  # pragma: no cover - a round never asks for more than the alive candidates
            raise InternalError(f"round greedy: {picks.size} of {take} choices made")
        counters[[0, 1, 3, 4, 5]] += stats[[0, 1, 3, 4, 5]]
        counters[2] = max(counters[2], stats[2])
        x[ce[picks]] = 1.0
        alive[idx[picks]] = False
        order.append(ce[picks])
    solves, poses, largest, corrections, iterations, unconverged = (int(v) for v in counters)
    return np.concatenate(order), RoundStats(len(sizes), sizes, radius, solves, poses, largest, corrections,
                                             iterations, unconverged, online)
