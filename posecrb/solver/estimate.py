"""Where a pose estimate comes from: the certified solver, the file's vertices, or another file.

Everything that needs an estimate (FIM at an estimate, CRLB, ``bounds`` FIM column)
calls ``get_estimate`` with ``source`` = ``"solve"`` (default: the certified global
optimum), ``"vertices"`` (the file's own VERTEX lines) or a path to a g2o/TORO file
whose vertices are used (same ids as the graph).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.errors import ArgumentError, ParseError, PosecrbError
from ..core.graph import PoseGraph
from ..core.result import Result, array_field, internal_field, status_field
from ..core.status import OK, Status
from ..io import load
from .poses import checked_poses
from .solve import solve

if TYPE_CHECKING:
    from .solve import SolveResult


@dataclass(frozen=True)
class Estimate(Result):
    """Poses at which the FIM, the bounds' FIM column and the CRLB are evaluated, and where they
    come from.

    ``to_dict()`` is the ``"estimate"`` object of the commands' JSON: ``source`` (``"solve"``:
    the certified solver; ``"vertices"``: the file's VERTEX lines; a path: another file's
    vertices; ``"given"``: poses passed by the caller), ``certified`` (the solver's certificate;
    None when the poses do not come from the solver) and ``objective`` (SE-Sync's objective
    there, solver only). The poses themselves are left out of the JSON.

    Attributes
    ----------
    rot : numpy.ndarray
        (n, d, d) rotations, row k for the pose with the k-th smallest id (empty after
        ``from_dict``: the JSON does not carry the poses). Checked on construction by
        ``posecrb.lie.so.check_rotations``: matrices off by rounding are replaced by the nearest
        rotations with a warning; scaled matrices, reflections and complex or non-finite values
        are an ``ArgumentError``.
    trans : numpy.ndarray
        (n, d) translations in the file's length units.
    source : str
        Where the poses come from.
    certified : bool or None
        Whether the solver certified them globally optimal (None: not from the solver).
    objective : float or None
        SE-Sync's objective at the poses (solver only).
    objective_status : Status
        The solver's ``duality_gap_status``: a warning when the certified relaxation is not exact
        on this graph, so the poses are within the duality gap of the optimum, not proven optimal
        (in the JSON only then).
    solve_time : float or None
        Seconds spent in the solver (not in the JSON).

    Examples
    --------
    >>> import numpy as np
    >>> import posecrb
    >>> est = posecrb.Estimate(np.tile(np.eye(2), (3, 1, 1)), np.zeros((3, 2)))
    >>> est.to_dict()
    {'source': 'given', 'certified': None, 'objective': None}
    """

    rot: np.ndarray = array_field()
    trans: np.ndarray = array_field()
    source: str = "given"
    certified: bool | None = None
    objective: float | None = None
    solve_time: float | None = internal_field()
    objective_status: Status = status_field("estimate duality gap")

    def __post_init__(self) -> None:
        rot, trans = checked_poses(self.rot, self.trans)
        object.__setattr__(self, "rot", rot)
        object.__setattr__(self, "trans", trans)

    @property
    def has_poses(self) -> bool:
        """Whether the poses are here (not after ``from_dict``)."""
        return bool(np.size(self.rot) and np.size(self.trans))

    def statuses(self) -> dict[str, Status]:
        """``{"estimate": ..., "estimate duality gap": ...}``: a warning when the solver did not
        certify the poses, and the solver's duality-gap status."""
        if self.certified is False:
            cert = Status.warning("the solver's estimate is NOT certified globally optimal")
        else:
            cert = OK
        return {"estimate": cert, "estimate duality gap": self.objective_status}


def from_vertices(graph: PoseGraph) -> Estimate:
    if graph.vertex_rot is None or graph.vertex_trans is None:  # not graph.has_vertices
        raise PosecrbError(f"{graph.path}: the file has no VERTEX lines to evaluate at; take the solver's "
                           "estimate or another file's vertices")
    return Estimate(graph.vertex_rot, graph.vertex_trans, "vertices")


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
    return Estimate(other.vertex_rot[pos], other.vertex_trans[pos], str(path))


def from_solve_result(res: SolveResult, solve_time: float | None = None) -> Estimate:
    """The poses of a solver result with its certificate, objective and duality-gap status."""
    return Estimate(res.rot, res.trans, "solve", bool(res.certified), float(res.objective), solve_time,
                    objective_status=res.duality_gap_status)


def from_solver(graph: PoseGraph, **options: Any) -> Estimate:

    t0 = time.perf_counter()
    res = solve(graph, **options)
    elapsed = time.perf_counter() - t0
    return from_solve_result(res, elapsed)


def get_estimate(graph: PoseGraph, source: str = "solve", **solver_options: Any) -> Estimate:
    if source == "solve":
        return from_solver(graph, **solver_options)
    if source == "vertices":
        return from_vertices(graph)
    if not source:
        raise ArgumentError("estimate", source, "is empty: give 'solve', 'vertices' or a file")
    return from_file(graph, source)
