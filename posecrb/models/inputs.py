"""The files a result is computed from: its graph's file and an estimate's file (``Result.input_paths``).

Every writer given such a result refuses to write onto them (docs/design.md#results)."""
from __future__ import annotations

from ..core.graph import PoseGraph
from ..solver.estimate import Estimate

# Estimate sources that name no file (posecrb.solver.estimate.Estimate.source).
_NOT_FILES = ("solve", "vertices", "given")


def input_files(graph: PoseGraph, estimate: Estimate | None = None) -> tuple[str, ...]:
    """``graph.path`` (when it is a file, not ``posecrb.parse``'s ``"<string>"``) and the file the
    estimate's poses were read from."""
    out = [graph.path] if graph.path and graph.path != "<string>" else []
    if estimate is not None and estimate.source not in _NOT_FILES:
        out.append(str(estimate.source))
    return tuple(out)
