"""Where a pose estimate comes from: the certified solver, the file's vertices, or another file.

Everything that needs an estimate (FIM at an estimate, CRLB, ``bounds`` FIM column)
calls ``get_estimate`` with ``source`` = ``"solve"`` (default: the certified global
optimum), ``"vertices"`` (the file's own VERTEX lines) or a path to a g2o/TORO file
whose vertices are used (same ids as the graph).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.errors import ParseError, PosecrbError, UsageError
from ..core.graph import PoseGraph
from ..io import load
from . import solve


@dataclass(frozen=True)
class Estimate:
    rot: np.ndarray            # (n, d, d)
    trans: np.ndarray          # (n, d)
    source: str                # "solve" | "vertices" | path
    certified: bool | None     # None when not from the solver
    objective: float | None    # SE-Sync objective at the estimate (solver only)
    solve_time: float | None   # seconds spent in the solver
    status: str = "ok"


def from_vertices(graph: PoseGraph) -> Estimate:
    if graph.vertex_rot is None or graph.vertex_trans is None:  # not graph.has_vertices
        raise PosecrbError(f"{graph.path}: the file has no VERTEX lines; use --estimate solve or --estimate FILE")
    return Estimate(graph.vertex_rot, graph.vertex_trans, "vertices", None, None, None)


def from_file(graph: PoseGraph, path: str) -> Estimate:

    other = load(path)
    if other.vertex_rot is None or other.vertex_trans is None:  # not other.has_vertices
        raise ParseError(path, None, "estimate file has no VERTEX lines")
    if other.dim != graph.dim:
        raise ParseError(path, None, f"estimate is {other.dim}D, the graph is {graph.dim}D")
    pos = np.searchsorted(other.ids, graph.ids)
    pos = np.minimum(pos, other.n - 1)
    missing = graph.ids[other.ids[pos] != graph.ids]
    if missing.size:
        raise ParseError(path, None, f"estimate lacks {missing.size} pose(s) of the graph, e.g. id {missing[0]}")
    return Estimate(other.vertex_rot[pos], other.vertex_trans[pos], str(path), None, None, None)


def from_solver(graph: PoseGraph, **options: Any) -> Estimate:

    t0 = time.perf_counter()
    res = solve(graph, **options)
    elapsed = time.perf_counter() - t0
    return Estimate(res.rot, res.trans, "solve", bool(res.certified), float(res.objective), elapsed,
                    "ok" if res.certified else "uncertified")


def get_estimate(graph: PoseGraph, source: str = "solve", **solver_options: Any) -> Estimate:
    if source == "solve":
        return from_solver(graph, **solver_options)
    if source == "vertices":
        return from_vertices(graph)
    if not source:
        raise UsageError("--estimate needs solve, vertices or a FILE")
    return from_file(graph, source)
