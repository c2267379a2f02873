"""Render result rows (dicts, possibly nested) as a rich table, JSON, CSV or Markdown.

Nested dicts (``times``) are flattened to dotted columns for the tabular formats;
JSON keeps them nested. Floats keep full precision in JSON/CSV and are shown with
5 significant digits in the terminal table and Markdown. A value with a sibling
``<key>_status`` (``posecrb.core.status``) is shown as ``n/a (reason)`` when unavailable and
``value (warning)`` for a warning in the human formats (the reason goes to stderr); JSON/CSV
keep both keys.
"""
from __future__ import annotations

import csv
import io
import json
import math
import re
import sys
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

import click
import numpy as np

from ..core.errors import UsageError
from ..core.result import plain as _plain

if TYPE_CHECKING:
    from rich.table import Table



def render_statuses(row: dict[str, Any]) -> dict[str, Any]:
    """For the human formats: fold every ``<key>_status`` into ``<key>``'s cell (recursively)."""
    out: dict[str, Any] = {}
    for k, v in row.items():
        st = row.get(f"{k}_status")
        if isinstance(v, dict):
            v = render_statuses(v)
        if isinstance(st, dict) and st.get("status") in ("warning", "unavailable"):
            reason = st.get("reason") or ""
            v = f"n/a ({reason})" if st["status"] == "unavailable" else f"{fmt_value(v)} (warning)"
        if k.endswith("_status") and k[: -len("_status")] in row and isinstance(v, dict):
            continue
        out[k] = v
    return out


def flatten(row: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in row.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def key_value_rows(row: dict[str, Any]) -> list[dict[str, Any]]:
    """One ``{"field", "value"}`` row per (flattened) key, statuses folded in: the layout of the
    single-result commands' terminal output."""
    return [{"field": k, "value": v} for k, v in flatten(render_statuses(_plain(row))).items()]


def fmt_value(v: Any, digits: int = 5) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if v == 0 or not math.isfinite(v):
            return str(v)
        if 1e-3 <= abs(v) < 1e5:
            return f"{v:.{digits}g}"
        return f"{v:.{digits - 1}e}"
    if isinstance(v, (list, tuple)):
        return ",".join(fmt_value(x, digits) for x in v)
    return str(v)


def _columns(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None) -> list[str]:
    if columns:
        return list(columns)
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    return cols


def to_json(rows: Sequence[dict[str, Any]] | dict[str, Any], single: bool = False) -> str:
    data = _plain(rows[0] if single and len(rows) == 1 else rows) if isinstance(rows, list) else _plain(rows)
    return json.dumps(data, indent=2, allow_nan=False)


def to_json_long(obj: dict[str, Any], long_keys: Sequence[str]) -> str:
    """``obj`` (plain JSON values) as ``to_json`` prints it, except that the lists under
    ``long_keys`` hold one element per line, each written compactly: the same JSON value, and
    json's C encoder for the bulk (an indented dump runs json's pure-Python encoder, several times
    slower on a timeline's 10^4 rows: docs/decisions/fixed-costs.md)."""
    encode = json.JSONEncoder(allow_nan=False).encode      # one encoder for every element
    parts = []
    for key, value in obj.items():
        head = f"  {json.dumps(key)}: "
        if key in long_keys and isinstance(value, list) and value:
            items = ",\n".join("    " + encode(item) for item in value)
            parts.append(f"{head}[\n{items}\n  ]")
        else:
            parts.append(head + json.dumps(value, indent=2, allow_nan=False).replace("\n", "\n  "))
    return "{\n" + ",\n".join(parts) + "\n}"


def to_csv(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None = None) -> str:
    flat = [flatten(_plain(r)) for r in rows]
    cols = _columns(flat, columns)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in flat:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
    return buf.getvalue()


_MARKDOWN_SPECIAL = re.compile(r"([\\`*_\[\]<>|~])")


def markdown_escape(text: str) -> str:
    """``text`` as literal Markdown table-cell content: every character Markdown (CommonMark or
    GitHub's tables) gives a meaning is backslash-escaped, line breaks become spaces (a dataset named
    ``a|b`` or ``*x*`` is shown as written and never splits a row)."""
    return _MARKDOWN_SPECIAL.sub(r"\\\1", " ".join(str(text).splitlines()))


def to_markdown(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None = None,
                headers: dict[str, str] | None = None) -> str:
    flat = [flatten(render_statuses(_plain(r))) for r in rows]
    cols = _columns(flat, columns)
    headers = headers or {}
    lines = ["| " + " | ".join(markdown_escape(headers.get(c, c)) for c in cols) + " |",
             "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(markdown_escape(fmt_value(r.get(c))) for c in cols) + " |" for r in flat]
    return "\n".join(lines) + "\n"


def to_rich_table(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None = None,
                  title: str | None = None, headers: dict[str, str] | None = None,
                  caption: str | None = None) -> Table:
    from rich.table import Table  # noqa: PLC0415 -- lazy: start-up time (rich only for table output)
    from rich.text import Text  # noqa: PLC0415 -- lazy: start-up time (rich only for table output)

    # Text, never markup: a dataset named "[red]x" or a reason with brackets is shown as written.
    flat = [flatten(render_statuses(_plain(r))) for r in rows]
    cols = _columns(flat, columns)
    headers = headers or {}
    table = Table(title=None if title is None else Text(title), caption=None if caption is None else Text(caption),
                  show_lines=False)
    for c in cols:
        numeric = any(isinstance(r.get(c), (int, float)) and not isinstance(r.get(c), bool) for r in flat)
        table.add_column(Text(headers.get(c, c)), justify="right" if numeric else "left", overflow="fold")
    for r in flat:
        table.add_row(*(Text(fmt_value(r.get(c))) for c in cols))
    return table


def print_rows(rows: list[dict[str, Any]], fmt: str, columns: Sequence[str] | None = None,
               title: str | None = None, headers: dict[str, str] | None = None,
               single_json: bool = True, caption: str | None = None) -> None:
    """Write rows to stdout in ``fmt``; a single row is one JSON object, several a list."""

    if fmt == "json":
        click.echo(to_json(rows, single=single_json))
    elif fmt == "csv":
        click.echo(to_csv(rows, columns), nl=False)
    elif fmt == "markdown":
        click.echo(to_markdown(rows, columns, headers), nl=False)
    elif fmt == "table":
        from rich.console import Console  # noqa: PLC0415 -- lazy: start-up time (rich only for table output)

        # Piped output: no terminal width to respect, so never squeeze columns.
        width = None if sys.stdout.isatty() else 250
        Console(soft_wrap=False, width=width).print(to_rich_table(rows, columns, title, headers, caption))
    else:  # pragma: no cover - click validates choices
        raise UsageError(fmt)


def iter_keys(rows: Iterable[dict[str, Any]]) -> list[str]:
    return _columns(list(rows), None)
