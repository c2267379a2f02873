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
from typing import Any

from .errors import InternalError

STATES = ("ok", "warning", "unavailable")


@dataclass(frozen=True)
class Status:
    """The status of a computed number: ok, a warning, or unavailable, with its reason.

    Every result's ``status`` is one of these (the most severe of its numbers'); in the JSON a
    number that is not ok carries ``<key>_status`` = ``as_json()``, and an unavailable number is
    ``null``.

    Parameters
    ----------
    state : {"ok", "warning", "unavailable"}
        How far the number can be trusted.
    reason : str, optional
        Why (required unless ok): which quantity, what went wrong.
    hint : str, optional
        What the user can do about it.

    Examples
    --------
    >>> import posecrb
    >>> st = posecrb.Status.warning("lambda_min(L_w) is only known to lie in [0.1, 0.2]")
    >>> st.ok, st.available, st.as_json()["status"]
    (False, True, 'warning')
    >>> posecrb.Status.from_json(st.as_json()) == st
    True
    """

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

    def as_json(self) -> dict[str, Any]:
        """``{"status": state, "reason": ...[, "hint": ...]}``: how every JSON output writes it."""
        out: dict[str, Any] = {"status": self.state, "reason": self.reason}
        if self.hint:
            out["hint"] = self.hint
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Status:
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


def put(row: dict[str, Any], key: str, value: object, status: Status) -> None:
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
