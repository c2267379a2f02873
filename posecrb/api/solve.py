"""``posecrb.solve``: the certified maximum-likelihood estimate of a pose graph."""
from __future__ import annotations

import math
import numbers
import os
from dataclasses import fields, replace
from typing import TYPE_CHECKING, Any

from ..core.arguments import choice, flag
from ..core.choices import INITS, Init
from ..core.errors import ArgumentError
from ..core.graph import PoseGraph
from ..core.jsontypes import conform, type_hints, type_name
from . import arguments as arg
from .arguments import Source, public

if TYPE_CHECKING:
    from ..solver.solve import SolveResult


@public(out="write the estimate with posecrb.io.write_g2o(graph, path, res.rot, res.trans)")
def solve(source: Source, *, r0: int | None = None, rmax: int = 10, init: Init = "chordal",
          anchor: int | None = None, certificate_tol: float = 1e-3, sesync_compat: bool = False,
          data_dir: str | os.PathLike[str] | None = None, **options: Any) -> SolveResult:
    """The certified maximum-likelihood estimate of a pose graph (SE-Sync's Riemannian staircase).

    Parameters
    ----------
    source : PoseGraph, str or os.PathLike
        A graph, a path or a dataset name (see ``load``).
    r0, rmax : int
        First (default d + 1) and last rank of the staircase (2..100).
    init : {"chordal", "vertices"}
        Initial rotations: the chordal relaxation, or the file's own vertices.
    anchor : int, optional
        Pose id put at the identity; default the smallest id.
    certificate_tol : float
        Accept ``lambda_min(Q - Lambda) >= -certificate_tol`` as the certificate (> 0).
    sesync_compat : bool
        Read 3D quaternions as SE-Sync does (unnormalised) to reproduce its objective values.
    data_dir : str or os.PathLike, optional
        Directory searched first for a bare dataset name.
    **options
        Further ``posecrb.solver.SolverOptions`` fields (``max_iterations``, ``seed``, ...), each
        checked against its type (numbers finite, counts and seeds non-negative).

    Returns
    -------
    SolveResult
        The estimate, its objective and certificate. An uncertified estimate is returned too
        (``certified`` False, ``status`` a warning); the command line exits 1 then. Write the
        estimate as g2o with ``posecrb.io.write_g2o(graph, path, res.rot, res.trans)``.

    Raises
    ------
    DisconnectedGraph
        The graph is not connected.
    ArgumentError
        An argument out of range, an anchor that is not a pose id.

    Examples
    --------
    >>> import posecrb
    >>> res = posecrb.solve("intel")
    >>> res.certified, res.rank
    (True, 3)
    >>> round(res.objective, 6)
    52.348227
    """
    from ..solver import SolverOptions  # noqa: PLC0415 -- lazy: start-up time
    from ..solver import solve as run_solver  # noqa: PLC0415 -- lazy: start-up time

    flag("sesync_compat", sesync_compat)
    quaternions = "raw" if sesync_compat else "normalize"
    if isinstance(source, PoseGraph) and source.quaternions != quaternions:
        raise ArgumentError("sesync_compat", sesync_compat, f"does not match the graph, read with "
                            f"quaternions={source.quaternions!r}: pass its path or name instead")
    r0 = None if r0 is None else arg.integer("r0", r0, 2, 100)
    rmax = arg.integer("rmax", rmax, 2, 100)
    choice("init", init, INITS)
    certificate_tol = arg.finite("certificate_tol", certificate_tol, 0.0, low_open=True)
    ids = arg.one_anchor(anchor)
    _check_options(SolverOptions, options)
    graph, times = arg.load_graph(source, data_dir, quaternions=quaternions)
    opts = SolverOptions.from_keywords(r0=r0, rmax=rmax, init=init, anchor=graph.anchor_index(ids[0] if ids else None),
                                       certificate_tol=certificate_tol, **options)
    res = run_solver(graph, opts)
    return replace(res, times=solve_times(res.times, times.get("parse")))


def solve_times(times: dict[str, float], parse: float | None) -> dict[str, float]:
    """The solve's ``times`` with the parse first and in the total, when the call read the file."""
    if parse is None:
        return dict(times)
    return {"parse": parse, **{k: v for k, v in times.items() if k != "total"}, "total": parse + times["total"]}


# Options whose value is a count or a seed: non-negative integers (max_iterations at least 1).
_COUNTS = {"max_iterations": 1, "seed": 0, "refactor_hvps": 0}


def _check_options(options_type: type, options: dict[str, Any]) -> None:
    """``**options`` against the solver options' own field types: a value of another type, a number
    that is not finite or a negative count or seed is an ``ArgumentError`` naming the keyword (the
    names themselves are checked by ``SolverOptions.from_keywords``)."""
    hints = type_hints(options_type)
    names = {f.name for f in fields(options_type)}
    for name, value in options.items():
        if name in names and name != "trust_region":
            if not conform(value, hints[name])[0]:
                raise ArgumentError(name, value, f"is not {type_name(hints[name])}")
        if isinstance(value, numbers.Real) and not isinstance(value, numbers.Integral) \
                and not math.isfinite(float(value)):
            raise ArgumentError(name, value, "is not a finite number")
        if name in _COUNTS and isinstance(value, numbers.Integral):
            arg.integer(name, value, _COUNTS[name])
