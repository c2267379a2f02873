"""The pose graph: measurements as edge arrays, ids remapped to 0..n-1.

A measurement on edge k = (src[k], dst[k]) is the relative pose X_i^{-1} X_j
(g2o / SE-Sync convention, docs/design.md#formats): rotation ``rot[k]`` and
translation ``trans[k]`` expressed in frame i. ``info[k]`` is the file's
information matrix in g2o order (translation block first, then rotation).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Any

import numpy as np

from .errors import ArgumentError, ComponentSummary, DisconnectedGraph, UsageError
from .noise import isotropic_precisions, rotation_weights

_INT64_MAX = 2 ** 63 - 1


def _is_frozen(array: np.ndarray) -> bool:
    """Whether nothing can write ``array``'s values through numpy: it and every array it views are
    read-only, down to memory that is not writeable at all (an array's own, or ``bytes``)."""
    base: Any = array
    while isinstance(base, np.ndarray):
        if base.flags.writeable:
            return False
        base = base.base
    return base is None or isinstance(base, bytes)


def frozen_array(value: Any) -> np.ndarray:
    """``value`` as a read-only array whose values nothing else can change: ``value`` itself when it
    already is one (an array of another frozen graph, so ``dataclasses.replace`` shares them), else a
    read-only copy, so that the caller's array stays writeable and its later changes do not reach
    the graph."""
    array = np.asarray(value)
    if _is_frozen(array):
        return array
    array = np.array(array, copy=True)
    array.setflags(write=False)
    return array


def _read_only(array: np.ndarray) -> np.ndarray:
    """``array`` (computed here, referenced nowhere else) made read-only: a cached property."""
    array.setflags(write=False)
    return array


def connected_components(n: int, src: np.ndarray, dst: np.ndarray) -> tuple[int, np.ndarray]:
    """Number of connected components of the undirected graph on 0..n-1 with edges (src[k], dst[k]),
    and each vertex's component, components numbered by their smallest vertex (as
    ``scipy.sparse.csgraph.connected_components`` numbers them).

    numpy only, so that ``posecrb info`` needs no scipy (start-up time): min-label hooking with
    pointer jumping over the edge arrays. Every round hooks the larger of the two roots of each edge
    whose endpoints are still apart onto the smaller (``label[v] <= v`` throughout, so every tree is
    rooted at its smallest vertex), then shortcuts every vertex to its root; each round strictly lowers
    some label, so the loop ends, and it ends only when both ends of every edge share a root. Random
    and pose graphs take a handful of rounds, each O(m + n log depth).
    """
    label = np.arange(n, dtype=np.intp)
    u = np.asarray(src, dtype=np.intp)
    v = np.asarray(dst, dtype=np.intp)
    while u.size:
        lu, lv = label[u], label[v]
        apart = lu != lv
        if not apart.any():
            break
        u, v, lu, lv = u[apart], v[apart], lu[apart], lv[apart]   # joined edges stay joined
        np.minimum.at(label, np.maximum(lu, lv), np.minimum(lu, lv))
        while True:
            jumped = label[label]
            if np.array_equal(jumped, label):
                break
            label = jumped
    is_root = label == np.arange(n)
    component = np.cumsum(is_root) - 1          # roots in increasing order = by smallest vertex
    return int(np.count_nonzero(is_root)), component[label]


# The array fields of a PoseGraph: read-only, copied from the caller unless already frozen.
_ARRAY_FIELDS = frozenset({"ids", "src", "dst", "rot", "trans", "info", "vertex_rot", "vertex_trans", "edge_lines"})


def rotation_dimension(dim: int) -> int:
    """d_r = dim SO(d): 1 in 2D, 3 in 3D."""
    return 1 if dim == 2 else 3


class PoseDimensions:
    """``rot_dim`` (d_r) and ``q`` (d + d_r) of anything with a ``dim`` (a graph, a FIM)."""

    dim: int

    @property
    def rot_dim(self) -> int:
        """d_r: 1 in 2D, 3 in 3D."""
        return rotation_dimension(self.dim)

    @property
    def q(self) -> int:
        """Tangent dimension of one pose: 3 (SE(2)) or 6 (SE(3))."""
        return self.dim + self.rot_dim


@dataclass(frozen=True, eq=False)
class PoseGraph(PoseDimensions):
    """A pose graph: relative-pose measurements as edge arrays over poses 0..n-1.

    The measurement on edge k is the relative pose ``X_i^{-1} X_j`` of its ends
    i = ``src[k]``, j = ``dst[k]`` (g2o and SE-Sync convention): rotation ``rot[k]`` and
    translation ``trans[k]`` in frame i, in the file's length units, with the information
    matrix ``info[k]`` in g2o order (translation block first). Poses are numbered by their ids'
    order: ``ids[k]`` is the id, as in the file, of internal pose k. Every public function takes
    and reports ids; ``index_of`` maps an id to its index.

    Read one with ``posecrb.load`` or ``posecrb.parse``.

    A graph is immutable, arrays included: every array is read-only (``g.info[:] *= 4`` raises
    ``ValueError``), so the values derived from them and cached (``tau``, ``kappa``, the
    components) cannot go stale. The constructor takes a read-only copy of each array argument
    (the caller's own array stays writeable, and changing it later does not change the graph),
    except an array that is already frozen, such as another graph's: ``dataclasses.replace(g,
    info=...)`` shares the arrays it keeps. A changed graph is a new one made with ``replace``.

    Attributes
    ----------
    dim : int
        d = 2 or 3.
    ids : numpy.ndarray
        (n,) pose ids, increasing.
    src, dst : numpy.ndarray
        (m,) internal indices of each edge's ends.
    rot, trans, info : numpy.ndarray
        (m, d, d) measured rotations, (m, d) translations, (m, q, q) information matrices.
    vertex_rot, vertex_trans : numpy.ndarray or None
        The file's VERTEX poses, if any (an estimate).
    path, format, sha256 : str or None
        The file read, its format (``"g2o"``, ``"toro"``) and the sha256 of its bytes.

    Examples
    --------
    >>> import posecrb
    >>> g = posecrb.load("intel")
    >>> g.n, g.m, g.n_components, g.has_vertices
    (1728, 2512, 1, True)
    >>> g.index_of(5)
    5
    """

    dim: int                                # d = 2 or 3
    ids: np.ndarray                         # (n,) original vertex ids, increasing; index = internal id
    src: np.ndarray                         # (m,) internal index of i
    dst: np.ndarray                         # (m,) internal index of j
    rot: np.ndarray                         # (m, d, d) measured relative rotation
    trans: np.ndarray                       # (m, d) measured relative translation (frame i)
    info: np.ndarray                        # (m, q, q) information matrix, (translation, rotation) order
    vertex_rot: np.ndarray | None = None    # (n, d, d) initial estimate from the file, if any
    vertex_trans: np.ndarray | None = None  # (n, d)
    path: str | None = None
    format: str = "g2o"                     # "g2o" | "toro" | "synthetic"
    skipped: dict[str, int] = field(default_factory=dict)
    edge_lines: np.ndarray | None = None    # (m,) 1-based line numbers of the edges in the file
    sha256: str | None = None               # of the file's bytes, for reproducibility records
    quaternions: str = "normalize"          # how the reader took 3D edge quaternions (posecrb.io.load)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in _ARRAY_FIELDS and value is not None:
                object.__setattr__(self, f.name, frozen_array(value))

    # ---- sizes -------------------------------------------------------------
    @property
    def n(self) -> int:
        return int(self.ids.shape[0])

    @property
    def m(self) -> int:
        return int(self.src.shape[0])

    @property
    def name(self) -> str:
        if self.path is None:
            return "synthetic"

        base = os.path.basename(self.path)
        if base.lower().endswith(".gz") and base.count(".") > 1:
            base = base[:-3]            # intel.g2o.gz is intel, read transparently (posecrb.core.inputs)
        return base.rsplit(".", 1)[0] if "." in base else base

    @property
    def has_vertices(self) -> bool:
        return self.vertex_rot is not None

    # ---- noise model (docs/design.md#noise-model) ---------------------------
    @cached_property
    def _precisions(self) -> tuple[np.ndarray, np.ndarray]:
        tau, kappa = isotropic_precisions(self.info, self.dim)
        return _read_only(tau), _read_only(kappa)

    @property
    def tau(self) -> np.ndarray:
        """Isotropic translation precision per edge (SE-Sync convention), read-only."""
        return _read_only(self._precisions[0])      # also when the reader seeded the cache

    @property
    def kappa(self) -> np.ndarray:
        """Langevin rotation concentration per edge (SE-Sync convention), read-only."""
        return _read_only(self._precisions[1])

    @cached_property
    def rotation_weights(self) -> np.ndarray:
        """Edge weight of the rotation Laplacian in the paper's coordinates (eq. 39-41, 59), read-only."""
        return _read_only(rotation_weights(self.kappa, self.dim))

    def rotation_weights_by(self, rule: str) -> np.ndarray:
        """Edge weights of the rotation Laplacian under ``rule`` (``posecrb.core.noise.rotation_weights``):
        the cached ``rotation_weights`` for ``"eq59"``."""
        return self.rotation_weights if rule == "eq59" else rotation_weights(self.kappa, self.dim, rule)

    # ---- topology ----------------------------------------------------------
    @cached_property
    def _components(self) -> tuple[int, np.ndarray]:
        count, labels = connected_components(self.n, self.src, self.dst)
        return count, _read_only(labels)

    @property
    def n_components(self) -> int:
        return int(self._components[0])

    @property
    def component_labels(self) -> np.ndarray:
        """(n,) component index of each pose; components numbered by their smallest pose."""
        return self._components[1]

    def component_summaries(self, samples: int = 3) -> list[ComponentSummary]:
        labels = self.component_labels
        order = np.argsort(labels, kind="stable")
        starts = np.searchsorted(labels[order], np.arange(self.n_components))
        sizes = np.bincount(labels, minlength=self.n_components)
        out = [
            ComponentSummary(int(sizes[c]),
                             tuple(int(x) for x in self.ids[order[starts[c]: starts[c] + min(samples, int(sizes[c]))]]))
            for c in range(self.n_components)
        ]
        return sorted(out, key=lambda c: -c.size)

    def require_connected(self) -> None:
        if self.n_components != 1:
            raise DisconnectedGraph(self.path, self.component_summaries())

    @cached_property
    def degree(self) -> np.ndarray:
        """(n,) node degree; each parallel edge counts (read-only)."""
        return _read_only(np.bincount(self.src, minlength=self.n) + np.bincount(self.dst, minlength=self.n))

    # ---- ids ---------------------------------------------------------------
    def index_of(self, vertex_id: int, parameter: str = "pose") -> int:
        """Internal index of the pose whose id (as in the file) is ``vertex_id``.

        Raises ``ArgumentError`` naming ``parameter`` (``anchor=5 is not a pose id of g.g2o``)
        unless ``vertex_id`` is an integer (not a bool, not a float) that is a pose id."""
        if isinstance(vertex_id, (bool, np.bool_)) or not isinstance(vertex_id, (int, np.integer)):
            raise ArgumentError(parameter, vertex_id, "is not a pose id (an integer)")
        vertex_id = int(vertex_id)
        where = os.path.basename(self.path) if self.path else "the graph"
        k = int(np.searchsorted(self.ids, vertex_id)) if 0 <= vertex_id <= _INT64_MAX else self.n
        if k >= self.n or self.ids[k] != vertex_id:
            raise ArgumentError(parameter, vertex_id,
                                f"is not a pose id of {where} (ids {self.ids[0]}..{self.ids[-1]})")
        return k

    def check_estimate(self, rot: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(rot, trans)`` as float arrays of shapes (n, d, d) and (n, d) with finite values, or a
        UsageError: the one check every model applies to the estimate it is evaluated at."""
        d, n = self.dim, self.n
        rot = np.asarray(rot, dtype=float)
        trans = np.asarray(trans, dtype=float)
        if rot.shape != (n, d, d) or trans.shape != (n, d):
            raise UsageError(f"estimate shapes {rot.shape}, {trans.shape} do not match the graph "
                             f"({n} poses, {d}D): expected ({n}, {d}, {d}) and ({n}, {d})")
        if not (np.isfinite(rot).all() and np.isfinite(trans).all()):
            raise UsageError("the estimate has non-finite values")
        return rot, trans

    def anchor_index(self, anchor_id: int | None, parameter: str = "anchor") -> int:
        """Internal index of the anchor, a pose id (``index_of``); default the smallest id
        (docs/design.md#anchor)."""
        return 0 if anchor_id is None else self.index_of(anchor_id, parameter)

    def with_vertices(self, rot: np.ndarray, trans: np.ndarray) -> PoseGraph:
        """The same measurements with another estimate attached."""

        return replace(self, vertex_rot=np.asarray(rot, float), vertex_trans=np.asarray(trans, float))
