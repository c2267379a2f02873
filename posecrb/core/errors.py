"""Exception hierarchy (docs/design.md#errors). The CLI maps these to exit codes in one place
(``posecrb.cli.main``): ``UsageError`` -> 2, any other ``PosecrbError`` -> 1, anything else (a bug,
``InternalError`` included) -> 1 with "internal error ... please report it".

    PosecrbError
    ├── UsageError (also a ValueError)   an argument the caller can fix
    │   └── ArgumentError                one named argument: ``anchor=5 is not a pose id of g.g2o``
    ├── ParseError                       file:line and reason
    ├── OutputError                      a result cannot be written: path and reason
    ├── DatasetNotFound
    ├── NumericalError
    │   └── NotPositiveDefinite
    ├── DisconnectedGraph
    └── SolverError
    InternalError (a RuntimeError, deliberately not a PosecrbError): a broken invariant

Every error a user can cause through data carries enough context to act on it:
file and line for parse errors, matrix name and reason for factorization failures,
component sizes for disconnected graphs.
"""
from __future__ import annotations

import shlex
from dataclasses import dataclass

from .integers import shown, shown_text


class PosecrbError(Exception):
    """Base class of every error posecrb raises on purpose (a data, solver or usage error).

    The command line exits 1 for it (2 for a ``UsageError``). A bug is anything else.

    Examples
    --------
    >>> import posecrb
    >>> try:
    ...     posecrb.load("no-such-dataset")
    ... except posecrb.PosecrbError as exc:
    ...     print(type(exc).__name__)
    DatasetNotFound
    """


class ParseError(PosecrbError):
    """A file cannot be read, or its content is malformed: ``path:line: reason``.

    Attributes
    ----------
    path : str
        The file (``"<string>"`` for ``posecrb.parse``).
    line : int or None
        The 1-based line, when the error has one.
    reason : str
        What is wrong.

    Examples
    --------
    >>> import posecrb
    >>> try:
    ...     posecrb.parse("EDGE_SE2 0 1 1 0\\n")
    ... except posecrb.ParseError as exc:
    ...     print(exc.path, exc.line)
    <string> 1
    """

    def __init__(self, path: str, line: int | None, reason: str):
        self.path, self.line, self.reason = str(path), line, reason
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {reason}")


class OutputError(PosecrbError):
    """A result file cannot be written (disk full, permission denied, read-only file system):
    the path and the system's reason (exit 1). Nothing was written: the previous file, if any,
    is intact (``posecrb.core.outputs.atomic_write``)."""

    def __init__(self, path: str, reason: str):
        self.path, self.reason = str(path), reason
        super().__init__(f"cannot write {self.path}: {reason}")


class DatasetNotFound(PosecrbError):
    """A bare dataset name found nowhere on the search path; the message lists the directories
    searched and what else to do: fetch the dataset when the manifest knows the name (``advice``
    replaces that hint for a name that cannot be fetched).

    Attributes
    ----------
    name : str
        The name asked for.
    searched : list of str
        The directories searched.

    Examples
    --------
    >>> import posecrb
    >>> try:
    ...     posecrb.load("no-such-dataset")
    ... except posecrb.DatasetNotFound as exc:
    ...     print(exc.name)
    no-such-dataset
    """

    def __init__(self, name: str, searched: list[str], advice: str | None = None):
        self.name, self.searched = name, searched
        hint = "; searched: " + ", ".join(searched) if searched else ""
        advice = advice or f"run `posecrb datasets fetch {shlex.quote(name)}`"
        super().__init__(f"dataset {name!r} not found{hint}. "
                         f"Pass a path, set --data-dir or $POSECRB_DATA, or {advice}.")


class UsageError(PosecrbError, ValueError):
    """A request that cannot be honoured as asked (exit code 2 on the command line).

    Also a ``ValueError``, so that code catching ``ValueError`` for a bad argument catches it.

    Examples
    --------
    >>> import posecrb
    >>> issubclass(posecrb.UsageError, ValueError)
    True
    """


# Keywords that cannot be spelled as their option: ``from`` is a Python keyword (``timeline``).
_CLI_SPELLING = {"start": "--from", "stop": "--to"}


class ArgumentError(UsageError):
    """One argument of a library call is wrong; the message names it in Python terms.

    ``str(exc)`` is ``parameter=value`` followed by the reason, e.g.
    ``anchor=5 is not a pose id of shifted.g2o (ids 100..1827)``. The command line shows the
    same error with its option instead (``--anchor 5 is not a pose id ...``, ``cli_message``):
    library keywords are the command-line options in snake_case.

    Parameters
    ----------
    parameter : str
        The keyword (or positional parameter) of the library call.
    value : object
        The value given.
    reason : str
        What is wrong with it, as a predicate (``"is not a pose id of g.g2o"``) or, with
        ``sep=": "``, a sentence.
    sep : str
        What separates ``parameter=value`` from ``reason``.

    Examples
    --------
    >>> import posecrb
    >>> exc = posecrb.ArgumentError("anchor", 5, "is not a pose id of shifted.g2o")
    >>> str(exc)
    'anchor=5 is not a pose id of shifted.g2o'
    >>> exc.cli_message()
    '--anchor 5 is not a pose id of shifted.g2o'
    >>> isinstance(exc, posecrb.UsageError)
    True
    """

    def __init__(self, parameter: str, value: object, reason: str, *, sep: str = " "):
        self.parameter, self.value, self.reason, self.sep = parameter, value, reason, sep
        super().__init__(f"{parameter}={shown(value)}{sep}{reason}")    # (repr of a huge int raises)

    def cli_message(self) -> str:
        """The message with the command-line spelling: ``--max-iter 0 ...`` for ``max_iter=0``;
        ``source`` (the file argument) as ``FILE``; ``start``/``stop`` as ``--from``/``--to``."""
        if self.parameter == "source":
            return f"FILE {shown_text(self.value)}{self.sep}{self.reason}"
        flag = _CLI_SPELLING.get(self.parameter) or "--" + self.parameter.replace("_", "-")
        if isinstance(self.value, bool):   # a flag: given or not
            return f"{flag}{self.sep}{self.reason}"
        return f"{flag} {shown_text(self.value)}{self.sep}{self.reason}"


class NumericalError(PosecrbError):
    """A computation that cannot give a trustworthy number (reported, never a silent value).

    Examples
    --------
    >>> import posecrb
    >>> issubclass(posecrb.NotPositiveDefinite, posecrb.NumericalError)
    True
    """


class InternalError(RuntimeError):
    """A broken internal invariant: a bug in posecrb, not a problem with the data or the options."""


class NotPositiveDefinite(NumericalError):
    """A matrix that must be symmetric positive definite is not (reported, never a silent NaN).

    Attributes
    ----------
    matrix : str
        Which matrix (``"paper FIM"``, ``"reduced rotation Laplacian L_w"``, ...).
    reason : str
        What the factorization found.
    column : int or None
        The column where the Cholesky pivot failed.

    Examples
    --------
    >>> import posecrb
    >>> str(posecrb.NotPositiveDefinite("paper FIM", "a zero pivot", 4))
    'paper FIM is not positive definite (pivot failed at column 4): a zero pivot'
    """

    def __init__(self, matrix: str, reason: str, column: int | None = None):
        self.matrix, self.reason, self.column = matrix, reason, column
        col = f" (pivot failed at column {column})" if column is not None else ""
        super().__init__(f"{matrix} is not positive definite{col}: {reason}")


@dataclass(frozen=True)
class ComponentSummary:
    size: int
    sample_ids: tuple[int, ...]


class DisconnectedGraph(PosecrbError):
    """An anchored quantity asked of a disconnected graph; the message gives each component's
    size and some of its pose ids.

    Attributes
    ----------
    path : str or None
        The graph's file.
    components : list of ComponentSummary
        Size and sample ids of each component, largest first.

    Examples
    --------
    >>> import posecrb
    >>> g = posecrb.parse("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\\n")
    >>> try:
    ...     posecrb.bounds(g)
    ... except posecrb.DisconnectedGraph as exc:
    ...     print([c.size for c in exc.components])
    [2, 2]
    """

    def __init__(self, path: str | None, components: list[ComponentSummary]):
        self.path, self.components = path, components
        parts = "; ".join(
            f"#{k}: {c.size} poses (ids {', '.join(map(str, c.sample_ids))}"
            f"{', ...' if c.size > len(c.sample_ids) else ''})"
            for k, c in enumerate(components[:6])
        )
        more = f"; ... {len(components) - 6} more" if len(components) > 6 else ""
        src = f"{path}: " if path else ""
        super().__init__(
            f"{src}the pose graph is disconnected ({len(components)} components): {parts}{more}. "
            "Anchored quantities need a connected graph."
        )


class SolverError(PosecrbError):
    """The solver could not produce a certified estimate (the command line's exit 1 for ``solve``;
    the library returns the uncertified ``SolveResult`` with a warning status instead).

    Examples
    --------
    >>> import posecrb
    >>> issubclass(posecrb.SolverError, posecrb.PosecrbError)
    True
    """


def status_of(exc: BaseException) -> str:
    """Short status word for a failed row in a multi-dataset report."""
    if isinstance(exc, DatasetNotFound):
        return "not found"
    if isinstance(exc, DisconnectedGraph):
        return "disconnected"
    if isinstance(exc, ParseError):
        return "parse error"
    if isinstance(exc, NotPositiveDefinite):
        return "not positive definite"
    if isinstance(exc, SolverError):
        return "uncertified"
    if isinstance(exc, NumericalError):
        return "numerical error"
    return "error"
