"""Exception hierarchy (docs/design.md#errors). The CLI maps these to exit codes in one place
(``posecrb.cli.main``): ``UsageError`` -> 2, any other ``PosecrbError`` -> 1, anything else (a bug,
``InternalError`` included) -> 1 with "internal error ... please report it".

    PosecrbError
    ├── UsageError (also a ValueError)   an argument the caller can fix
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


class PosecrbError(Exception):
    """Base class: a data or solver error (exit code 1)."""


class ParseError(PosecrbError):
    def __init__(self, path: str, line: int | None, reason: str):
        self.path, self.line, self.reason = str(path), line, reason
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {reason}")


class OutputError(PosecrbError):
    """A result file cannot be written (disk full, permission denied, read-only file system):
    the path and the system's reason (exit 1). Nothing was written: the previous file, if any,
    is intact (``posecrb.core.files.atomic_write``)."""

    def __init__(self, path: str, reason: str):
        self.path, self.reason = str(path), reason
        super().__init__(f"cannot write {self.path}: {reason}")


class DatasetNotFound(PosecrbError):
    def __init__(self, name: str, searched: list[str]):
        self.name, self.searched = name, searched
        hint = "; searched: " + ", ".join(searched) if searched else ""
        super().__init__(
            f"dataset {name!r} not found{hint}. "
            f"Pass a path, set --data-dir or $POSECRB_DATA, or run `posecrb datasets fetch {shlex.quote(name)}`."
        )


class UsageError(PosecrbError, ValueError):
    """A usage error the library detects (exit code 2), e.g. an anchor id not in the graph.

    Also a ValueError, so library callers that catch ValueError for a bad argument keep working."""


class NumericalError(PosecrbError):
    """A computation that cannot give a trustworthy number (reported, never a silent value)."""


class InternalError(RuntimeError):
    """A broken internal invariant: a bug in posecrb, not a problem with the data or the options."""


class NotPositiveDefinite(NumericalError):
    """A matrix that must be symmetric positive definite is not (reported, never a silent NaN)."""

    def __init__(self, matrix: str, reason: str, column: int | None = None):
        self.matrix, self.reason, self.column = matrix, reason, column
        col = f" (pivot failed at column {column})" if column is not None else ""
        super().__init__(f"{matrix} is not positive definite{col}: {reason}")


@dataclass(frozen=True)
class ComponentSummary:
    size: int
    sample_ids: tuple[int, ...]


class DisconnectedGraph(PosecrbError):
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
    """The solver could not produce a certified estimate."""


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
