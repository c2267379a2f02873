"""Status of a computed number: ok, a warning, or not available, always with its reason.

A quantity that can be numerically doubtful (an ill-conditioned inverse, an approximation
outside its domain, an eigenvalue below the resolution of double precision) is returned
together with a ``Status``. It is rendered the same way everywhere (``posecrb.report.render``):

* JSON / CSV: the value (``null`` when unavailable) and, when the state is not ``ok``, a
  sibling key ``<name>_status`` = ``{"status": "warning" | "unavailable", "reason": ...,
  "hint": ...}``;
* terminal tables / Markdown: ``n/a (reason)`` in place of an unavailable value, and
  ``value (warning)`` for a warning (its reason is on stderr);
* stderr: one ``posecrb: warning:`` line per doubtful quantity (``log_status``).
"""
from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

from .errors import InternalError

STATES = ("ok", "warning", "unavailable")


@dataclass(frozen=True)
class Status:
    """``state`` is one of ``STATES``; ``reason`` says why (which quantity, what went wrong);
    ``hint`` says what the user can do about it."""

    state: str = "ok"
    reason: str | None = None
    hint: str | None = None

    def __post_init__(self) -> None:
        if self.state not in STATES:
            raise InternalError(f"status must be one of {STATES}, got {self.state!r}")
        if self.state != "ok" and not self.reason:
            raise InternalError("a warning or an unavailable status needs a reason")

    @classmethod
    def warning(cls, reason: str, hint: str | None = None) -> Status:
        return cls("warning", reason, hint)

    @classmethod
    def unavailable(cls, reason: str, hint: str | None = None) -> Status:
        return cls("unavailable", reason, hint)

    @property
    def ok(self) -> bool:
        return self.state == "ok"

    @property
    def available(self) -> bool:
        return self.state != "unavailable"

    def as_json(self) -> dict:
        out: dict = {"status": self.state, "reason": self.reason}
        if self.hint:
            out["hint"] = self.hint
        return out

    @classmethod
    def from_json(cls, d: dict) -> Status:
        """The inverse of ``as_json`` (rows carry statuses in that form across processes)."""
        return cls(d["status"], d.get("reason"), d.get("hint"))

    def message(self, quantity: str) -> str:
        """One line for stderr: which quantity, why, what to do."""
        what = "not available" if self.state == "unavailable" else "doubtful"
        hint = f"; {self.hint}" if self.hint else ""
        return f"{quantity} {what}: {self.reason}{hint}"


OK = Status()


def worst(*statuses: Status) -> Status:
    """The most severe of ``statuses`` (the first one of that severity)."""
    rank = {s: k for k, s in enumerate(STATES)}
    best = OK
    for s in statuses:
        if rank[s.state] > rank[best.state]:
            best = s
    return best


def put(row: dict, key: str, value: object, status: Status) -> None:
    """``row[key] = value`` (None when unavailable) plus ``row[key + "_status"]`` unless ok."""
    row[key] = value if status.available else None
    if not status.ok:
        row[f"{key}_status"] = status.as_json()


def log_status(logger: logging.Logger, quantity: str, status: Status) -> None:
    """One stderr line for a status that is not ok (warning level for both kinds)."""
    if not status.ok:
        logger.warning("%s", status.message(quantity))


def log_statuses(logger: logging.Logger, name: str, statuses: Mapping[str, Status]) -> None:
    """``log_status`` for each of a result's ``statuses()``, the quantity prefixed by ``name``."""
    for quantity, status in statuses.items():
        log_status(logger, f"{name}: {quantity}", status)
