"""The timeline's result: one row per kept step, monotonicity, loop-closure gains (one protocol:
``to_dict()`` is the command's JSON, ``from_dict`` its inverse, ``to_frame()`` a DataFrame)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.status import OK, Status, put, worst

if TYPE_CHECKING:
    import pandas as pd

# Loop closures in the summary (table view, JSON "top_loop_closures").
TOP = 10
_AFTER_DISCONNECTED = Status.unavailable("the previous prefix is disconnected").as_json()


@dataclass(frozen=True)
class LoopClosure:
    """One loop closure: added at the step with ``poses`` poses (newest pose ``pose``), the edge
    ``source -> target`` (ids as in the file) read from ``line`` (None for a graph not read from a
    file); ``gain`` its sequential increase of lb (None when the prefix before it is
    disconnected, with ``status`` saying so)."""

    poses: int
    pose: int
    source: int
    target: int
    line: int | None
    gain: float | None
    status: Status = OK

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"poses": self.poses, "pose": self.pose, "source": self.source, "target": self.target,
                               "line": self.line, "gain": self.gain}
        if not self.status.ok:
            out["gain_status"] = self.status.as_json()
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LoopClosure:
        st = Status.from_json(d["gain_status"]) if "gain_status" in d else OK
        return cls(int(d["poses"]), int(d["pose"]), int(d["source"]), int(d["target"]),
                   None if d.get("line") is None else int(d["line"]),
                   None if d.get("gain") is None else float(d["gain"]), st)


@dataclass(frozen=True)
class Monotonicity:
    """Whether a metric never decreases from one connected step to the next (steps whose prefix or
    predecessor is disconnected are not compared): ``decreases`` counts the steps where it does,
    ``first`` is the first of them (``{"poses", "pose", "change"}``) and ``largest`` the largest
    drop, both None when monotone."""

    monotone: bool
    decreases: int
    first: dict[str, Any] | None = None
    largest: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"monotone": self.monotone, "decreases": self.decreases, "first": self.first, "largest": self.largest}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Monotonicity:
        return cls(bool(d["monotone"]), int(d["decreases"]), d.get("first"), d.get("largest"))


def _monotone(values: np.ndarray, compare: np.ndarray, poses: np.ndarray, ids: np.ndarray) -> Monotonicity:
    change = np.diff(values)
    drops = np.flatnonzero(compare[1:] & (change < 0)) + 1
    if drops.size == 0:
        return Monotonicity(True, 0)

    def at(k: int) -> dict[str, Any]:
        return {"poses": int(poses[k]), "pose": int(ids[k]), "change": float(values[k] - values[k - 1])}

    largest = drops[np.argmin(change[drops - 1])]
    return Monotonicity(False, int(drops.size), at(int(drops[0])), at(int(largest)))


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


_BEFORE_DISCONNECTED = Status.unavailable("the prefix before it is disconnected")


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
    def from_dicts(cls, items: list[dict[str, Any]]) -> ClosureTable:
        def col(key: str, missing: float, dtype: type) -> np.ndarray:
            return np.array([missing if c.get(key) is None else c[key] for c in items], dtype=dtype)

        return cls(col("poses", 0, np.int64), col("pose", 0, np.int64), col("source", 0, np.int64),
                   col("target", 0, np.int64), col("line", -1, np.int64), col("gain", np.nan, float))

    def top(self, k: int) -> np.ndarray:
        """Indices of the ``k`` largest known gains, largest first (ties: earlier first)."""
        known = np.flatnonzero(np.isfinite(self.gain))
        order = np.lexsort((known, -self.gain[known]))
        return known[order[:k]]


@dataclass(frozen=True, eq=False)
class TimelineResult:
    """What ``posecrb.timeline`` computes: the information timeline (docs/design.md#timeline).

    Graph: ``dataset``, ``path``, ``sha256``, ``dim``, ``n_poses``, ``n_edges``, ``anchor`` (the
    smallest id, anchored in every prefix), ``rotation_weight``, ``fim_variant`` and ``estimate``
    (source, certified, objective; None for graph-only rows). Range: ``first``..``last`` (numbers of
    poses) and ``every``. Rows (arrays, one entry per kept step): ``poses``, ``pose`` (the newest
    id), ``edges``, ``loop_closures``, ``components``, ``lb``, ``ub``, ``t_opt_graph``,
    ``fim_logdet`` (None without an estimate) and ``gain`` (NaN where unavailable: a disconnected
    prefix, or for ``gain`` a disconnected predecessor). ``lb_status``, ``ub_status``,
    ``fim_status``: a metric that could not be verified. ``monotonicity[metric]["raw" |
    "per_dimension"]``, ``closure_table`` (every loop closure of the range, in processing order;
    ``closures`` gives them as ``LoopClosure``), ``checks`` (per tracked matrix: checkpoints,
    largest drift, tolerance) and ``times``.

    ``to_dict()`` is the ``timeline`` command's JSON object and ``from_dict`` its inverse;
    ``to_frame()`` has one row per kept step, ``closures_frame()`` one per loop closure.
    Log-dets are natural logarithms; ``lb``, ``ub`` and ``fim_logdet`` are those of ``bounds`` on
    each prefix.

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.timeline("intel", estimate="none", every=500)
    >>> frame = res.to_frame()
    >>> frame.columns.tolist()[:5]
    ['poses', 'pose', 'edges', 'loop_closures', 'components']
    >>> round(float(frame["lb"].iloc[-1]), 2) == round(posecrb.bounds("intel", estimate="none").lb, 2)
    True
    >>> type(res).from_dict(res.to_dict()).to_dict() == res.to_dict()
    True
    """

    dataset: str
    path: str | None
    sha256: str | None
    dim: int
    n_poses: int
    n_edges: int
    anchor: int
    rotation_weight: str
    fim_variant: str | None
    estimate: dict[str, Any] | None
    every: int
    first: int
    last: int
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
    lb_status: Status = OK
    ub_status: Status = OK
    fim_status: Status = OK
    monotonicity: dict[str, dict[str, Monotonicity]] = field(default_factory=dict)
    closure_table: ClosureTable | None = None
    checks: dict[str, dict[str, Any]] = field(default_factory=dict)
    times: dict[str, float] = field(default_factory=dict)

    @property
    def q(self) -> int:
        """Tangent dimension of a pose: the rows per free pose of the anchored matrices."""
        return self.dim + (1 if self.dim == 2 else 3)

    # ------------------------------------------------------------------ rows
    def _metric_columns(self) -> dict[str, np.ndarray]:
        cols = {"lb": self.lb, "ub": self.ub, "t_opt_graph": self.t_opt_graph}
        if self.fim_logdet is not None:
            cols["fim_logdet"] = self.fim_logdet
        return cols

    def rows(self, start: int = 0, stop: int | None = None) -> list[dict[str, Any]]:
        """One dict per kept step (the JSON rows; ``start:stop`` a slice of them): a disconnected
        prefix has None values and a ``status``; a metric with a status that is not ok carries
        ``<metric>_status`` (``posecrb.core.status.put``); ``gain`` after a disconnected prefix is
        None with ``gain_status``."""
        sl = slice(start, stop)
        statuses = {"lb": self.lb_status, "ub": self.ub_status, "fim_logdet": self.fim_status}
        ints = [c[sl].tolist() for c in (self.poses, self.pose, self.edges, self.loop_closures, self.components)]
        floats = {k: v[sl].tolist() for k, v in self._metric_columns().items()}
        gains = self.gain[sl].tolist()
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
                row["gain_status"] = _AFTER_DISCONNECTED
            out.append(row)
        return out

    @property
    def closures(self) -> tuple[LoopClosure, ...]:
        """Every loop closure of the range, in processing order."""
        return tuple(LoopClosure.from_dict(d) for d in self._closure_dicts())

    def _closure_dicts(self, index: np.ndarray | None = None) -> list[dict[str, Any]]:
        return [] if self.closure_table is None else self.closure_table.dicts(index)

    def top_closures(self, k: int = TOP) -> list[LoopClosure]:
        """The ``k`` loop closures with the largest gains (ties: earlier first)."""
        if self.closure_table is None:
            return []
        return [LoopClosure.from_dict(d) for d in self.closure_table.dicts(self.closure_table.top(k))]

    # ------------------------------------------------------------------ protocol
    def statuses(self) -> dict[str, Status]:
        """The status of each metric (``lb``, ``ub``, ``fim_logdet``), as the command logs them, and
        the estimate's duality-gap status when the solver's relaxation was not exact."""
        out = {"lb": self.lb_status, "ub": self.ub_status, "fim_logdet": self.fim_status}
        if self.estimate is not None and self.estimate.get("objective_status") is not None:
            out["estimate duality gap"] = Status.from_json(self.estimate["objective_status"])
        return out

    @property
    def status(self) -> Status:
        """The most severe of ``statuses()``."""
        return worst(*self.statuses().values())

    def to_dict(self) -> dict[str, Any]:
        """The ``posecrb timeline --format json`` object."""
        return {
            "dataset": self.dataset, "path": self.path, "sha256": self.sha256, "dim": self.dim,
            "poses": self.n_poses, "edges": self.n_edges, "anchor": self.anchor,
            "rotation_weight": self.rotation_weight, "fim_variant": self.fim_variant, "estimate": self.estimate,
            "range": {"from": self.first, "to": self.last, "every": self.every},
            "statuses": {k: s.as_json() for k, s in (("lb", self.lb_status), ("ub", self.ub_status),
                                                      ("fim_logdet", self.fim_status)) if not s.ok},
            "monotonicity": {m: {s: v.to_dict() for s, v in d.items()} for m, d in self.monotonicity.items()},
            "top_loop_closures": ([] if self.closure_table is None
                                  else self.closure_table.dicts(self.closure_table.top(TOP))),
            "checks": self.checks,
            "times": self.times,
            "rows": self.rows(),
            "loop_closures": self._closure_dicts(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TimelineResult:
        """The inverse of ``to_dict``."""
        rows = d["rows"]

        def ints(key: str) -> np.ndarray:
            return np.array([r[key] for r in rows], dtype=np.int64)

        def floats(key: str) -> np.ndarray:
            return np.array([np.nan if r.get(key) is None else r[key] for r in rows], dtype=float)

        st = {k: Status.from_json(v) for k, v in d.get("statuses", {}).items()}
        return cls(
            dataset=d["dataset"], path=d["path"], sha256=d["sha256"], dim=int(d["dim"]), n_poses=int(d["poses"]),
            n_edges=int(d["edges"]), anchor=int(d["anchor"]), rotation_weight=d["rotation_weight"],
            fim_variant=d["fim_variant"], estimate=d["estimate"], every=int(d["range"]["every"]),
            first=int(d["range"]["from"]), last=int(d["range"]["to"]),
            poses=ints("poses"), pose=ints("pose"), edges=ints("edges"), loop_closures=ints("loop_closures"),
            components=ints("components"), lb=floats("lb"), ub=floats("ub"), t_opt_graph=floats("t_opt_graph"),
            fim_logdet=floats("fim_logdet") if d["estimate"] is not None else None, gain=floats("gain"),
            lb_status=st.get("lb", OK), ub_status=st.get("ub", OK), fim_status=st.get("fim_logdet", OK),
            monotonicity={m: {s: Monotonicity.from_dict(v) for s, v in x.items()}
                          for m, x in d["monotonicity"].items()},
            closure_table=ClosureTable.from_dicts(d["loop_closures"]),
            checks=d["checks"], times=d["times"],
        )

    def to_frame(self) -> pd.DataFrame:
        """One row per kept step (columns of the JSON rows, NaN where unavailable)."""
        import pandas as pd  # noqa: PLC0415 -- lazy: only for DataFrames

        cols: dict[str, Any] = {"poses": self.poses, "pose": self.pose, "edges": self.edges,
                                "loop_closures": self.loop_closures, "components": self.components}
        cols.update(self._metric_columns())
        cols["gain"] = self.gain
        return pd.DataFrame(cols)

    def closures_frame(self) -> pd.DataFrame:
        """One row per loop closure of the range (columns of the JSON ``loop_closures``)."""
        import pandas as pd  # noqa: PLC0415 -- lazy: only for DataFrames

        t = self.closure_table
        if t is None:
            return pd.DataFrame(columns=["poses", "pose", "source", "target", "line", "gain"])
        return pd.DataFrame({"poses": t.poses, "pose": t.pose, "source": t.source, "target": t.target,
                             "line": pd.array([x if x >= 0 else None for x in t.line.tolist()], dtype="Int64"),
                             "gain": t.gain})

    # ------------------------------------------------------------------ summary (table view)
    def final(self) -> dict[str, Any]:
        """The last row (empty without rows)."""
        return self.rows(self.poses.size - 1)[0] if self.poses.size else {}

    def summary_rows(self) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        """The table view: per metric its final value (raw and per dimension) and its monotonicity
        (raw and per dimension: monotone, number of decreases, the first one), and the top loop
        closures (``LoopClosure.to_dict()`` with their rank)."""
        last = self.final()
        dims = self.q * (last["poses"] - 1) if last else 1
        metrics = []
        for name in self._metric_columns():
            value = last.get(name)
            row: dict[str, Any] = {"metric": name, "final": value}
            if f"{name}_status" in last:
                row["final_status"] = last[f"{name}_status"]
            row["per_dimension"] = None if value is None else value / dims
            for scale, m in self.monotonicity.get(name, {}).items():
                row[f"{scale}_monotone"] = m.monotone
                row[f"{scale}_decreases"] = m.decreases
                row[f"{scale}_first_break"] = None if m.first is None else f"{m.first['poses']} (id {m.first['pose']})"
            metrics.append(row)
        top = [{"rank": k + 1, **c.to_dict()} for k, c in enumerate(self.top_closures())]
        return metrics, top
