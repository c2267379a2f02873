"""The parts of a timeline's result: its rows (one per kept step), its loop closures, and the
monotonicity of each metric (posecrb.incremental.result.TimelineResult)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.errors import ArgumentError
from ..core.result import Result
from ..core.status import OK, Status, put

_BEFORE_DISCONNECTED = Status.unavailable("the prefix before it is disconnected")
_AFTER_DISCONNECTED = Status.unavailable("the previous prefix is disconnected")
METRICS = ("lb", "ub", "t_opt_graph", "fim_logdet")


@dataclass(frozen=True, kw_only=True)
class LoopClosure(Result):
    """One loop closure: added at the step with ``poses`` poses (newest pose ``pose``), the edge
    ``source -> target`` (ids as in the file) read from ``line`` (None for a graph not read from a
    file); ``gain`` its sequential increase of lb (None when the prefix before it is
    disconnected, with ``gain_status`` saying so).

    Examples
    --------
    >>> import posecrb
    >>> top = posecrb.timeline("intel", estimate="none").top_closures(1)[0]
    >>> top.gain > 0, top.gain_status.ok
    (True, True)
    """

    poses: int
    pose: int
    source: int
    target: int
    line: int | None
    gain: float | None
    gain_status: Status = OK


@dataclass(frozen=True, kw_only=True)
class Monotonicity(Result):
    """Whether a metric never decreases from one connected step to the next (steps whose prefix or
    predecessor is disconnected are not compared): ``decreases`` counts the steps where it does,
    ``first`` is the first of them (``{"poses", "pose", "change"}``) and ``largest`` the largest
    drop, both None when monotone. ``monotone`` is None when no two steps could be compared.

    Examples
    --------
    >>> import posecrb
    >>> m = posecrb.timeline("intel", estimate="none").monotonicity["lb"]["raw"]
    >>> m.monotone, m.decreases
    (True, 0)
    """

    monotone: bool | None
    decreases: int
    first: dict[str, Any] | None = None
    largest: dict[str, Any] | None = None


def _monotone(values: np.ndarray, compare: np.ndarray, poses: np.ndarray, ids: np.ndarray) -> Monotonicity:
    if not compare.any():
        return Monotonicity(monotone=None, decreases=0)
    change = np.diff(values)
    drops = np.flatnonzero(compare[1:] & (change < 0)) + 1
    if drops.size == 0:
        return Monotonicity(monotone=True, decreases=0)

    def at(k: int) -> dict[str, Any]:
        return {"poses": int(poses[k]), "pose": int(ids[k]), "change": float(values[k] - values[k - 1])}

    largest = drops[np.argmin(change[drops - 1])]
    return Monotonicity(monotone=False, decreases=int(drops.size), first=at(int(drops[0])), largest=at(int(largest)))


def monotonicity(metrics: dict[str, np.ndarray], connected: np.ndarray, poses: np.ndarray, ids: np.ndarray,
                 q: int) -> dict[str, dict[str, Monotonicity]]:
    """For each metric (values over consecutive steps): ``raw`` and ``per_dimension`` (divided by
    the dimension q (poses - 1) of the anchored matrices, Carrillo et al.'s D-criterion scale)."""
    compare = connected.copy()
    compare[1:] &= connected[:-1]
    compare[0] = False
    dims = q * (poses - 1).astype(float)
    out = {}
    for name, vals in metrics.items():
        ok = compare & np.isfinite(vals)
        ok[1:] &= np.isfinite(vals[:-1])
        out[name] = {"raw": _monotone(vals, ok, poses, ids), "per_dimension": _monotone(vals / dims, ok, poses, ids)}
    return out


@dataclass(frozen=True, eq=False)
class ClosureTable:
    """Every loop closure of a timeline as columns (``LoopClosure`` fields; ``line`` -1 and
    ``gain`` NaN where there is none)."""

    poses: np.ndarray
    pose: np.ndarray
    source: np.ndarray
    target: np.ndarray
    line: np.ndarray
    gain: np.ndarray

    def __len__(self) -> int:
        return int(self.poses.size)

    def dicts(self, index: np.ndarray | None = None) -> list[dict[str, Any]]:
        """``LoopClosure.to_dict()`` of every closure (or of ``index``), built column-wise."""
        idx = np.arange(len(self)) if index is None else np.asarray(index, dtype=np.int64)
        cols = [c[idx].tolist() for c in (self.poses, self.pose, self.source, self.target, self.line, self.gain)]
        bad = _BEFORE_DISCONNECTED.as_json()
        out = []
        for k, p, s, t, ln, g in zip(*cols, strict=True):
            d: dict[str, Any] = {"poses": k, "pose": p, "source": s, "target": t, "line": None if ln < 0 else ln,
                                 "gain": None if g != g else g}
            if g != g:
                d["gain_status"] = bad
            out.append(d)
        return out

    @classmethod
    def from_dicts(cls, items: Any) -> ClosureTable:
        """The inverse of ``dicts`` (``ArgumentError`` for an item that is not a loop closure)."""
        if not isinstance(items, list):
            raise ArgumentError("loop_closures", type(items).__name__, "is not a list of loop closures", sep=": ")
        closures = [LoopClosure.from_dict(c) for c in items]

        def col(key: str, missing: float, dtype: type) -> np.ndarray:
            values = [getattr(c, key) for c in closures]
            return np.array([missing if v is None else v for v in values], dtype=dtype)

        return cls(col("poses", 0, np.int64), col("pose", 0, np.int64), col("source", 0, np.int64),
                   col("target", 0, np.int64), col("line", -1, np.int64), col("gain", np.nan, float))

    def top(self, k: int) -> np.ndarray:
        """Indices of the ``k`` largest known gains, largest first (ties: earlier first)."""
        known = np.flatnonzero(np.isfinite(self.gain))
        order = np.lexsort((known, -self.gain[known]))
        return known[order[:k]]


@dataclass(frozen=True, eq=False)
class TimelineRows:
    """One entry per kept step, as columns: ``poses`` (the prefix's number of poses), ``pose`` (the
    newest id), ``edges``, ``loop_closures``, ``components``, ``lb``, ``ub``, ``t_opt_graph``,
    ``fim_logdet`` (None without an estimate) and ``gain`` (NaN where unavailable: a disconnected
    prefix, or for ``gain`` a disconnected predecessor)."""

    poses: np.ndarray
    pose: np.ndarray
    edges: np.ndarray
    loop_closures: np.ndarray
    components: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    t_opt_graph: np.ndarray
    fim_logdet: np.ndarray | None
    gain: np.ndarray

    def __len__(self) -> int:
        return int(self.poses.size)

    def metrics(self) -> dict[str, np.ndarray]:
        """The metric columns (``fim_logdet`` only with an estimate)."""
        cols = {"lb": self.lb, "ub": self.ub, "t_opt_graph": self.t_opt_graph}
        if self.fim_logdet is not None:
            cols["fim_logdet"] = self.fim_logdet
        return cols

    def dicts(self, statuses: Mapping[str, Status], start: int = 0, stop: int | None = None) -> list[dict[str, Any]]:
        """One dict per step (the JSON rows; ``start:stop`` a slice of them): a disconnected prefix has
        None values and a ``status``; a metric whose status (``statuses``) is not ok carries
        ``<metric>_status`` (``posecrb.core.status.put``); ``gain`` after a disconnected prefix is
        None with ``gain_status``."""
        sl = slice(start, stop)
        ints = [c[sl].tolist() for c in (self.poses, self.pose, self.edges, self.loop_closures, self.components)]
        floats = {k: v[sl].tolist() for k, v in self.metrics().items()}
        gains = self.gain[sl].tolist()
        after = _AFTER_DISCONNECTED.as_json()
        out = []
        for k in range(len(gains)):
            comps = ints[4][k]
            row: dict[str, Any] = {"poses": ints[0][k], "pose": ints[1][k], "edges": ints[2][k],
                                   "loop_closures": ints[3][k], "components": comps}
            for name, vals in floats.items():
                v = vals[k]
                st = statuses.get(name, OK)
                if comps == 1 and not st.ok:
                    put(row, name, None if v != v else v, st)
                else:
                    row[name] = None if v != v else v
            g = gains[k]
            row["gain"] = None if g != g else g
            if comps != 1:
                row["status"] = Status.unavailable(f"the prefix is disconnected ({comps} components)").as_json()
            elif g != g:
                row["gain_status"] = after
            out.append(row)
        return out

    @classmethod
    def from_dicts(cls, rows: Any, with_fim: bool) -> TimelineRows:
        """The columns of JSON rows (their statuses are checked by the result's round trip); an
        ``ArgumentError`` for a row that lacks a key or holds a value of another type."""
        if not isinstance(rows, list) or not all(isinstance(r, Mapping) for r in rows):
            raise ArgumentError("rows", type(rows).__name__, "is not a list of timeline rows", sep=": ")

        def ints(key: str) -> np.ndarray:
            values = [r.get(key) for r in rows]
            if not all(type(v) is int for v in values):
                raise ArgumentError("rows", key, "is not an integer in every row", sep=": ")
            return np.array(values, dtype=np.int64)

        def floats(key: str) -> np.ndarray:
            values = [r.get(key, 0) for r in rows]
            if not all(v is None or type(v) in (int, float) for v in values):
                raise ArgumentError("rows", key, "is not a number (or null) in every row", sep=": ")
            return np.array([np.nan if v is None else v for v in values], dtype=float)

        return cls(poses=ints("poses"), pose=ints("pose"), edges=ints("edges"), loop_closures=ints("loop_closures"),
                   components=ints("components"), lb=floats("lb"), ub=floats("ub"),
                   t_opt_graph=floats("t_opt_graph"), fim_logdet=floats("fim_logdet") if with_fim else None,
                   gain=floats("gain"))
