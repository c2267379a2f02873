"""The timeline's result: one row per kept step, monotonicity, loop-closure gains, under the result
protocol (``to_dict()`` is the command's JSON, ``from_dict`` its inverse, ``save``/``load``, a
``status``; posecrb.core.result)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..core.errors import ArgumentError
from ..core.jsontypes import conform, is_status_json, short, type_hints, type_name
from ..core.result import GraphKeys, inputs_field
from ..core.status import OK, Status
from ..solver.estimate import Estimate
from .parts import ClosureTable, LoopClosure, Monotonicity, TimelineRows

if TYPE_CHECKING:
    import pandas as pd

# Loop closures in the summary (table view, JSON "top_loop_closures").
TOP = 10
# The keys of the JSON object, in order.
KEYS = ("dataset", "path", "sha256", "dim", "poses", "edges", "anchor", "rotation_weight", "fim_variant", "estimate",
        "range", "statuses", "monotonicity", "top_loop_closures", "checks", "times", "rows", "loop_closures")
_SCALARS = ("dataset", "path", "sha256", "dim", "poses", "edges", "anchor", "rotation_weight", "fim_variant",
            "checks", "times")


@dataclass(frozen=True, kw_only=True, eq=False)
class TimelineResult(GraphKeys):
    """What ``posecrb.timeline`` computes: the information timeline (docs/design.md#timeline).

    Graph: ``dataset``, ``path``, ``sha256``, ``dim``, ``poses`` and ``edges`` (n and m of the whole
    graph), ``anchor`` (the smallest id, anchored in every prefix), ``rotation_weight``,
    ``fim_variant`` and ``estimate`` (an ``Estimate``; None for graph-only rows). Range: ``first``
    to ``last`` (numbers of poses) and ``every``. ``rows``: one entry per kept step, as columns
    (``TimelineRows``: ``poses``, ``pose``, ``edges``, ``loop_closures``, ``components``, ``lb``,
    ``ub``, ``t_opt_graph``, ``fim_logdet``, ``gain``). ``lb_status``, ``ub_status``,
    ``fim_status``: a metric that could not be verified, or a range in which no prefix is
    connected (no values at all). ``monotonicity[metric]["raw" | "per_dimension"]``,
    ``closure_table`` (every loop closure of the range, in processing order; ``closures`` gives
    them as ``LoopClosure``), ``checks`` (per tracked matrix: checkpoints, largest drift,
    tolerance) and ``times``.

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

    anchor: int
    rotation_weight: str
    fim_variant: str | None
    estimate: Estimate | None
    every: int
    first: int
    last: int
    rows: TimelineRows
    lb_status: Status = OK
    ub_status: Status = OK
    fim_status: Status = OK
    monotonicity: dict[str, dict[str, Monotonicity]] = field(default_factory=dict)
    closure_table: ClosureTable | None = None
    checks: dict[str, dict[str, Any]] = field(default_factory=dict)
    times: dict[str, float] = field(default_factory=dict)
    inputs: tuple[str, ...] = inputs_field()

    @property
    def q(self) -> int:
        """Tangent dimension of a pose: the rows per free pose of the anchored matrices."""
        return self.dim + (1 if self.dim == 2 else 3)

    # ------------------------------------------------------------------ rows and loop closures
    def row_dicts(self, start: int = 0, stop: int | None = None) -> list[dict[str, Any]]:
        """The JSON rows (``start:stop`` a slice of them), see ``TimelineRows.dicts``."""
        return self.rows.dicts(self.metric_statuses(), start, stop)

    @property
    def closures(self) -> tuple[LoopClosure, ...]:
        """Every loop closure of the range, in processing order."""
        return tuple(LoopClosure.from_dict(d) for d in self._closure_dicts())

    def _closure_dicts(self, index: Any = None) -> list[dict[str, Any]]:
        return [] if self.closure_table is None else self.closure_table.dicts(index)

    def top_closures(self, k: int = TOP) -> list[LoopClosure]:
        """The ``k`` loop closures with the largest gains (ties: earlier first)."""
        if self.closure_table is None:
            return []
        return [LoopClosure.from_dict(d) for d in self.closure_table.dicts(self.closure_table.top(k))]

    # ------------------------------------------------------------------ protocol
    def metric_statuses(self) -> dict[str, Status]:
        """The status of each metric: ``lb``, ``ub``, ``fim_logdet``."""
        return {"lb": self.lb_status, "ub": self.ub_status, "fim_logdet": self.fim_status}

    def statuses(self) -> dict[str, Status]:
        """The status of each metric (``lb``, ``ub``, ``fim_logdet``), as the command logs them, and
        the estimate's statuses (its certificate and its duality gap)."""
        out = self.metric_statuses()
        if self.estimate is not None:
            out.update(self.estimate.statuses())
        return out

    def to_dict(self) -> dict[str, Any]:
        """The ``posecrb timeline --format json`` object."""
        return {
            "dataset": self.dataset, "path": self.path, "sha256": self.sha256, "dim": self.dim,
            "poses": self.poses, "edges": self.edges, "anchor": self.anchor,
            "rotation_weight": self.rotation_weight, "fim_variant": self.fim_variant,
            "estimate": None if self.estimate is None else self.estimate.to_dict(),
            "range": {"from": self.first, "to": self.last, "every": self.every},
            "statuses": {k: s.as_json() for k, s in self.metric_statuses().items() if not s.ok},
            "monotonicity": {m: {s: v.to_dict() for s, v in d.items()} for m, d in self.monotonicity.items()},
            "top_loop_closures": ([] if self.closure_table is None
                                  else self.closure_table.dicts(self.closure_table.top(TOP))),
            "checks": self.checks,
            "times": self.times,
            "rows": self.row_dicts(),
            "loop_closures": self._closure_dicts(),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TimelineResult:
        """The inverse of ``to_dict``, each value checked (``ArgumentError`` otherwise)."""
        if not isinstance(d, Mapping):
            raise ArgumentError("d", type(d).__name__, "is not a mapping (a TimelineResult dict)", sep=": ")
        if list(d) != list(KEYS):
            wrong = sorted(set(d) ^ set(KEYS)) or ["the order"]
            raise ArgumentError("d", f"{{... {len(d)} keys}}", f"is not a TimelineResult's dict (keys {wrong})",
                                sep=": ")
        hints = type_hints(cls)
        values: dict[str, Any] = {}
        for key in _SCALARS:
            ok, values[key] = conform(d[key], hints[key])
            if not ok:
                raise ArgumentError("d", f"{{... {len(d)} keys}}", f"key {key!r} of a TimelineResult is "
                                    f"{short(d[key])}, not {type_name(hints[key])}", sep=": ")
        span, statuses = d["range"], d["statuses"]
        if not (isinstance(span, Mapping) and set(span) == {"from", "to", "every"}
                and all(conform(v, int)[0] for v in span.values())):
            raise ArgumentError("range", short(span), "is not {'from': K, 'to': L, 'every': N} (integers)", sep=": ")
        if not (isinstance(statuses, Mapping) and set(statuses) <= {"lb", "ub", "fim_logdet"}
                and all(is_status_json(v) for v in statuses.values())):
            raise ArgumentError("statuses", short(statuses), "is not a status per metric (lb, ub, fim_logdet)",
                                sep=": ")
        mono = d["monotonicity"]
        if not (isinstance(mono, Mapping) and all(isinstance(v, Mapping) for v in mono.values())):
            raise ArgumentError("monotonicity", short(mono), "is not a mapping metric -> scale -> monotonicity",
                                sep=": ")
        st = {k: Status.from_json(v) for k, v in statuses.items()}
        res = cls(**values, estimate=None if d["estimate"] is None else Estimate.from_dict(d["estimate"]),
                  every=span["every"], first=span["from"], last=span["to"],
                  rows=TimelineRows.from_dicts(d["rows"], d["estimate"] is not None),
                  lb_status=st.get("lb", OK), ub_status=st.get("ub", OK), fim_status=st.get("fim_logdet", OK),
                  monotonicity={m: {s: Monotonicity.from_dict(v) for s, v in x.items()} for m, x in mono.items()},
                  closure_table=ClosureTable.from_dicts(d["loop_closures"]))
        back = res.to_dict()
        for key in KEYS:
            if back[key] != d[key]:
                raise ArgumentError("d", f"{{... {len(d)} keys}}", f"key {key!r} of a TimelineResult contradicts the "
                                    "other keys (rows, statuses and top loop closures must agree)", sep=": ")
        return res

    def to_frame(self) -> pd.DataFrame:
        """One row per kept step (columns of the JSON rows, NaN where unavailable)."""
        import pandas as pd  # noqa: PLC0415 -- lazy: only for DataFrames

        r = self.rows
        cols: dict[str, Any] = {"poses": r.poses, "pose": r.pose, "edges": r.edges, "loop_closures": r.loop_closures,
                                "components": r.components}
        cols.update(r.metrics())
        cols["gain"] = r.gain
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
        return self.row_dicts(len(self.rows) - 1)[0] if len(self.rows) else {}

    def summary_rows(self) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        """The table view: per metric its final value (raw and per dimension) and its monotonicity
        (raw and per dimension: monotone, number of decreases, the first one), and the top loop
        closures (``LoopClosure.to_dict()`` with their rank)."""
        last = self.final()
        dims = self.q * (last["poses"] - 1) if last else 1
        metrics = []
        for name in self.rows.metrics():
            value = last.get(name)
            row: dict[str, Any] = {"metric": name, "final": value}
            if f"{name}_status" in last:
                row["final_status"] = last[f"{name}_status"]
            row["per_dimension"] = None if value is None else value / dims
            for scale, m in self.monotonicity.get(name, {}).items():
                row[f"{scale}_monotone"] = "n/a (nothing compared)" if m.monotone is None else m.monotone
                row[f"{scale}_decreases"] = m.decreases
                row[f"{scale}_first_break"] = None if m.first is None else f"{m.first['poses']} (id {m.first['pose']})"
            metrics.append(row)
        top = [{"rank": k + 1, **c.to_dict()} for k, c in enumerate(self.top_closures())]
        return metrics, top
