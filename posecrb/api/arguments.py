"""The arguments of the public functions, checked once, in Python terms.

Every check raises ``ArgumentError`` naming the keyword as the caller wrote it
(``anchor=-1 is not a pose id ...``); the command line shows the same error with its option
(``--anchor -1 ...``). Library keywords are the command-line options in snake case, so the
checks here are the library's side of the options' click types; they take Python values, never
the command line's spellings (a sequence of pose ids, not ``"0,5,10-12"``; ``0.2``, not
``"20%"``), which the command line parses (``posecrb.cli.options``).
"""
from __future__ import annotations

import functools
import inspect
import math
import numbers
import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Literal, TypeAlias, TypeVar

import numpy as np

from ..core.arguments import check_input_argument
from ..core.choices import ESTIMATE_SOURCES, EstimateSource
from ..core.errors import ArgumentError, UsageError
from ..core.graph import PoseGraph
from ..core.inputs import check_input_file
from ..core.integers import IntegerError, check_int
from ..core.timing import Repeat, measure
from ..datasets import search
from ..io import load as read_graph
from ..io import parse_bytes, parse_text

if TYPE_CHECKING:
    from ..solver.estimate import Estimate
    from ..solver.solve import SolveResult

INT64_MAX = 2 ** 63 - 1
F = TypeVar("F", bound=Callable[..., Any])

#: A pose graph, the path of a g2o or TORO file, or a bare dataset name.
Source: TypeAlias = "PoseGraph | str | os.PathLike[str]"
#: Where the poses come from: the certified solver, the file's vertices, another file, a solve's
#: result or given poses.
EstimateSpec: TypeAlias = "EstimateSource | str | os.PathLike[str] | SolveResult | Estimate"
#: The same, or no estimate (graph-only results): None or ``"none"``.
OptionalEstimateSpec: TypeAlias = "EstimateSpec | Literal['none'] | None"
#: Per-pose blocks: none (None or False), every pose (True or ``"all"``), or these pose ids.
PoseSelection: TypeAlias = "bool | Literal['all'] | Sequence[int] | None"


def public(**removed: str) -> Callable[[F], F]:
    """A public function's call checked as a whole: a keyword it does not have, or a positional
    argument too many, is an ``ArgumentError`` (not Python's ``TypeError``); a keyword in
    ``removed`` (one the library had before) says what to call instead."""

    def decorate(fn: F) -> F:
        signature = inspect.signature(fn)
        params = signature.parameters
        open_keywords = any(p.kind is p.VAR_KEYWORD for p in params.values())

        @functools.wraps(fn)
        def call(*args: Any, **kwargs: Any) -> Any:
            for name in kwargs.keys() & removed.keys():
                raise ArgumentError(name, kwargs[name], f"is no longer a keyword of {fn.__name__}(): "
                                    f"{removed[name]}", sep=": ")
            for name in kwargs:
                if name not in params and not open_keywords:
                    raise ArgumentError(name, kwargs[name], f"is not a keyword of {fn.__name__}() (see "
                                        f"help(posecrb.{fn.__name__}))")
            try:
                signature.bind(*args, **kwargs)
            except TypeError as exc:
                # the call's shape, not its values: an argument's repr may be long (a graph's arrays)
                shown = f"{len(args)} positional argument(s) and keywords {sorted(kwargs)}"
                raise ArgumentError(fn.__name__, shown, f"{exc} (see help(posecrb.{fn.__name__}))",
                                    sep=": ") from None
            return fn(*args, **kwargs)

        return call  # type: ignore[return-value]

    return decorate


def integer(parameter: str, value: Any, low: int, high: int = INT64_MAX) -> int:
    """``value`` when it is an integer (not a bool, not a float such as 1.5) in [low, high]."""
    try:
        return check_int(value, lo=low, hi=high)
    except IntegerError as exc:
        raise ArgumentError(parameter, value, str(exc)) from None


def finite(parameter: str, value: Any, low: float, high: float = math.inf, *, low_open: bool = False) -> float:
    """``value`` when it is a finite real number in [low, high] (``(low, high]`` with ``low_open``)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ArgumentError(parameter, value, "is not a number")
    try:
        x = float(value)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise ArgumentError(parameter, value, "is not a finite number")
    if x < low or (low_open and x == low) or x > high:
        span = f"{'(' if low_open else '['}{low:g}, {high:g}]"
        raise ArgumentError(parameter, value, f"is not in {span}")
    return x


def path_or_none(parameter: str, value: Any) -> str | None:
    """A non-empty ``str`` / ``os.PathLike`` (without NUL characters) as a string, or None."""
    return None if value is None else check_input_argument(parameter, value)


# ---- graphs -----------------------------------------------------------------------------
def _shown(value: Any) -> Any:
    """A short form of a long value for a message (the first bytes of a file's content)."""
    if isinstance(value, (bytes, bytearray, memoryview)):
        data = bytes(value)
        return data[:24] + (b"..." if len(data) > 24 else b"")
    if isinstance(value, str) and len(value) > 60:
        return value[:40] + "..."
    if (isinstance(value, (list, tuple)) or _vector(value)) and len(value) > 8:
        return f"[{', '.join(map(str, list(value)[:4]))}, ... ({len(value)} items)]"
    return value


def _vector(value: Any) -> bool:
    return isinstance(value, np.ndarray) and value.ndim == 1


def resolve_source(source: Any, data_dir: Any = None) -> str:
    """The file a path or a bare dataset name names, resolved as the command line does: an
    existing path as is, else the name on the search path (``data_dir``, ``$POSECRB_DATA``,
    ``./datasets``, ``~/.cache/posecrb``) and the manifest's names."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        raise ArgumentError("source", _shown(source), "is bytes: pass a path or a dataset name, or the "
                            "file's content to posecrb.parse")
    if not isinstance(source, (str, os.PathLike)) or not isinstance(os.fspath(source), str) or not os.fspath(source):
        raise ArgumentError("source", _shown(source), "is not a pose graph, a path or a dataset name")
    text = check_input_argument("source", source)
    directory = path_or_none("data_dir", data_dir)
    return str(search.resolve(text, directory))


def load_graph(source: Any, data_dir: Any = None, *, quaternions: str = "normalize",
               repeat: Repeat = 1) -> tuple[PoseGraph, dict[str, float]]:
    """``(graph, times)``: ``source`` itself when it is a ``PoseGraph`` (no time), else the file
    it names read with ``quaternions``, and ``{"parse": seconds}`` (``load_graph_timed``)."""
    graph, times, _ = load_graph_timed(source, data_dir, quaternions=quaternions, repeat=repeat)
    return graph, times


def load_graph_timed(source: Any, data_dir: Any = None, *, quaternions: str = "normalize",
                     repeat: Repeat = 1) -> tuple[PoseGraph, dict[str, float], dict[str, int]]:
    """``(graph, times, runs)`` as ``load_graph``; the parse time is the median of ``runs["parse"]``
    runs by the timing protocol (``posecrb.core.timing.measure``)."""
    directory = path_or_none("data_dir", data_dir)
    if isinstance(source, PoseGraph):
        return source, {}, {}
    path = resolve_source(source, directory)
    parsed = measure(lambda: read_graph(path, quaternions=quaternions), repeat)
    return parsed.value, {"parse": parsed.seconds}, {"parse": parsed.runs}


def repeat_setting(value: Any) -> Repeat:
    """``repeat``: ``"auto"`` (the adaptive protocol) or a number of runs from 1 to 1000."""
    if isinstance(value, str) and value == "auto":
        return "auto"
    return integer("repeat", value, 1, 1000)


def parse_content(text: Any) -> PoseGraph:
    """A pose graph from a file's content: ``str`` or ``bytes`` (UTF-8)."""
    if isinstance(text, str):
        return parse_text(text)
    if isinstance(text, (bytes, bytearray, memoryview)):
        return parse_bytes(bytes(text))
    raise ArgumentError("text", _shown(text), "is not a file's content (str or bytes)")


# ---- poses ------------------------------------------------------------------------------
def anchor_ids(value: Any) -> tuple[int, ...]:
    """``anchor``: None, a pose id, or a sequence of pose ids -> a tuple of ids (types checked;
    membership is checked against the graph by ``PoseGraph.index_of``)."""
    if value is None:
        return ()
    items = list(value) if isinstance(value, (list, tuple)) or _vector(value) else [value]
    if isinstance(value, np.ndarray) and value.ndim == 0:
        items = [value.item()]
    for a in items:
        if isinstance(a, (bool, np.bool_)) or not isinstance(a, numbers.Integral):
            raise ArgumentError("anchor", _shown(value), "is not a pose id or a sequence of pose ids (integers)")
    return tuple(int(a) for a in items)


def one_anchor(anchor: Any) -> tuple[int, ...]:
    """``anchor_ids`` of a call that takes one anchor (empty: the default)."""
    ids = anchor_ids(anchor)
    if len(ids) > 1:
        raise ArgumentError("anchor", anchor, "is several pose ids; this call takes one")
    return ids


def check_anchors(graph: PoseGraph, anchors: Sequence[int]) -> None:
    """Every id in ``anchors`` is a pose id of ``graph`` (``ArgumentError`` naming ``anchor``)."""
    for a in anchors:
        graph.index_of(a, "anchor")


def pose_selection(value: Any) -> bool | list[int]:
    """``poses``: None or False (no per-pose blocks), True or ``"all"`` (every pose), or a sequence
    of pose ids (membership is checked against the graph by the model). The command line's text
    (``"0,5,10-12"``) is refused with what to pass instead."""
    if value is None or value is False or isinstance(value, np.bool_) and not value:
        return False
    if value is True or isinstance(value, np.bool_) or (isinstance(value, str) and value == "all"):
        return True
    if isinstance(value, str):
        raise ArgumentError("poses", _shown(value), "is text: pass True (or 'all') or a sequence of pose ids, "
                            "e.g. [0, 5, *range(10, 13)] for the command line's 0,5,10-12")
    if isinstance(value, (list, tuple, range)) or _vector(value):
        ids = list(value)
        for p in ids:
            if isinstance(p, (bool, np.bool_)) or not isinstance(p, numbers.Integral):
                raise ArgumentError("poses", _shown(value), "is not 'all' or a sequence of pose ids (integers)")
        return [int(p) for p in ids]
    raise ArgumentError("poses", _shown(value), "is not True, 'all' or a sequence of pose ids")


# ---- estimates --------------------------------------------------------------------------
def is_pose_object(value: Any) -> bool:
    """Whether ``value`` carries poses itself (a ``SolveResult`` or an ``Estimate``)."""
    from ..solver.estimate import Estimate  # noqa: PLC0415 -- lazy: start-up time (scipy)
    from ..solver.solve import SolveResult  # noqa: PLC0415 -- lazy: start-up time (scipy)

    return isinstance(value, (SolveResult, Estimate))


def estimate_spec(value: Any, *, allow_none: bool = False) -> str:
    """``estimate`` given as text: ``"solve"``, ``"vertices"``, a path (a readable regular file,
    as the command line checks ``--estimate`` even where it is not used), or (``allow_none``)
    None / ``"none"`` -> ``"none"``."""
    if value is None and allow_none:
        return "none"
    if isinstance(value, (str, os.PathLike)) and isinstance(os.fspath(value), str) and os.fspath(value):
        text = str(os.fspath(value))
        if text in ESTIMATE_SOURCES or (text == "none" and allow_none):
            return text
        if text != "none":
            check_input_file(check_input_argument("estimate", text))
            return text
    raise ArgumentError("estimate", _shown(value), "is not 'solve', 'vertices', a path, a SolveResult or an "
                        "Estimate" + (" (or None)" if allow_none else ""))


def resolve_estimate(graph: PoseGraph, estimate: Any, *, allow_none: bool = False,
                     solver_options: dict[str, Any] | None = None) -> Estimate | None:
    """The poses ``estimate`` names: ``"solve"`` (the certified solver, with ``solver_options``),
    ``"vertices"`` (the file's VERTEX lines), a path (another file's vertices with the same
    ids), a ``SolveResult`` or an ``Estimate`` of this graph; ``None`` / ``"none"`` when
    ``allow_none`` (graph-only results)."""
    from ..solver.estimate import Estimate, from_solve_result, get_estimate  # noqa: PLC0415 -- lazy: start-up
    from ..solver.solve import SolveResult  # noqa: PLC0415 -- lazy: start-up time (scipy)

    if estimate is None or (isinstance(estimate, str) and estimate == "none"):
        if allow_none:
            return None
        raise ArgumentError("estimate", estimate, "is not 'solve', 'vertices', a path, a SolveResult or an Estimate")
    if isinstance(estimate, SolveResult):
        if estimate.rot.size == 0:
            raise ArgumentError("estimate", f"SolveResult of {estimate.dataset}", "carries no poses (it was rebuilt "
                                "from a dict); SolveResult.load of a saved result has them", sep=": ")
        if estimate.ids.size and not np.array_equal(estimate.ids, graph.ids):
            raise ArgumentError("estimate", f"SolveResult of {estimate.dataset}",
                                f"is the estimate of another graph (its pose ids are not those of {graph.name})",
                                sep=": ")
        return _checked(graph, from_solve_result(estimate))
    if isinstance(estimate, Estimate):
        if not estimate.has_poses:
            raise ArgumentError("estimate", f"Estimate from {estimate.source}", "carries no poses", sep=": ")
        return _checked(graph, estimate)
    if isinstance(estimate, (str, os.PathLike)) and os.fspath(estimate):
        source = str(os.fspath(estimate))
        if source == "solve":
            return get_estimate(graph, "solve", **(solver_options or {}))
        return get_estimate(graph, source)
    raise ArgumentError("estimate", _shown(estimate),
                        "is not 'solve', 'vertices', a path, a SolveResult or an Estimate")


def _checked(graph: PoseGraph, estimate: Estimate) -> Estimate:
    """``estimate`` with its poses as float arrays of the graph's shapes (``check_estimate``),
    without a solve time (this call did not run the solver)."""
    from ..solver.estimate import Estimate  # noqa: PLC0415 -- lazy: start-up time (scipy)

    try:
        rot, trans = graph.check_estimate(estimate.rot, estimate.trans)
    except UsageError as exc:
        raise ArgumentError("estimate", f"Estimate from {estimate.source}", str(exc), sep=": ") from None
    return Estimate(rot, trans, estimate.source, estimate.certified, estimate.objective,
                    objective_status=estimate.objective_status)


def estimate_times(estimate: Estimate | None) -> dict[str, float]:
    """``{"solve": seconds}`` when the call ran the solver, else ``{}`` (the commands' ``times``)."""
    return {} if estimate is None or estimate.solve_time is None else {"solve": float(estimate.solve_time)}
