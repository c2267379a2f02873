"""JSON values checked against the Python type of the field they fill (docs/design.md#results).

``Result.from_dict`` reads a dict that may come from anywhere (a file, another program, a user):
each value is checked here against its field's annotation (``int``, ``float``, ``str``, ``bool``,
``Literal``, unions with None, ``list[...]``, ``dict[str, ...]``, ``Status``, nested results) and
converted back where ``plain`` changed it (``"inf"`` and None of a float: infinity and NaN).
"""
from __future__ import annotations

import math
import numbers
import types
import typing
from collections.abc import Mapping
from typing import Any

from .status import STATES, Status

_HINTS: dict[type, dict[str, Any]] = {}


def type_hints(cls: type) -> dict[str, Any]:
    """The resolved annotations of a dataclass's fields (computed once per class)."""
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


def is_status_json(value: Any) -> bool:
    """Whether ``value`` is ``Status.as_json()`` of a status that is not ok: ``{"status": "warning" or
    "unavailable", "reason": text[, "hint": text]}`` and nothing else."""
    return (isinstance(value, Mapping) and value.get("status") in STATES and value.get("status") != "ok"
            and isinstance(value.get("reason"), str) and bool(value["reason"])
            and isinstance(value.get("hint", ""), (str, type(None))) and set(value) <= {"status", "reason", "hint"})


def short(value: Any) -> str:
    """``repr(value)`` cut to 60 characters (for a message)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def conform(value: Any, tp: Any, nested: Any = None) -> tuple[bool, Any]:
    """``(True, value)`` (converted where JSON changed it) when ``value`` is of type ``tp`` as JSON
    gives it, ``(False, value)`` otherwise. ``nested(cls, value)`` builds a nested result."""
    if tp is Any or tp is object:
        return True, value
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is type(None) or tp is None:
        return value is None, value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return True, None
        for a in args:
            ok, got = conform(value, a, nested)
            if ok:
                return True, got
        return False, value
    if origin is typing.Literal:
        return value in args and not isinstance(value, bool), value
    if tp is bool:
        return isinstance(value, bool), value
    if tp is int:
        return isinstance(value, numbers.Integral) and not _is_bool(value), value
    if tp is float:
        if value is None:
            return True, math.nan
        if isinstance(value, str) and value in ("inf", "-inf"):
            return True, float(value)
        return isinstance(value, numbers.Real) and not _is_bool(value), value
    if tp is str:
        return isinstance(value, str), value
    if tp is Status:
        return is_status_json(value), Status.from_json(value) if is_status_json(value) else value
    if origin in (list, tuple) or tp in (list, tuple):
        return _items(value, args[0] if args else Any, nested)
    if origin in (dict, Mapping) or tp is dict:
        return _mapping(value, args[1] if len(args) == 2 else Any, nested)
    if isinstance(tp, type) and hasattr(tp, "from_dict") and nested is not None:
        return isinstance(value, Mapping), nested(tp, value) if isinstance(value, Mapping) else value
    return isinstance(tp, type) and isinstance(value, tp), value


def _is_bool(value: Any) -> bool:
    return isinstance(value, bool) or type(value).__name__ in ("bool_", "bool")


def _items(value: Any, item: Any, nested: Any) -> tuple[bool, Any]:
    if not isinstance(value, list):
        return False, value
    out = []
    for v in value:
        ok, got = conform(v, item, nested)
        if not ok:
            return False, value
        out.append(got)
    return True, out


def _mapping(value: Any, item: Any, nested: Any) -> tuple[bool, Any]:
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        return False, value
    out = {}
    for k, v in value.items():
        ok, got = conform(v, item, nested)
        if not ok:
            return False, value
        out[k] = got
    return True, out


def type_name(tp: Any) -> str:
    """``tp`` in words, for a message (``"a number or None"``)."""
    names = {int: "an integer", float: "a number", str: "a text", bool: "True or False", type(None): "None",
             Status: "a status"}
    if tp in names:
        return names[tp]
    args = typing.get_args(tp)
    origin = typing.get_origin(tp)
    if origin is typing.Literal:
        return "one of " + ", ".join(map(repr, args))
    if origin in (typing.Union, types.UnionType):
        return " or ".join(type_name(a) for a in args)
    if origin in (list, tuple):
        return "a list" + (f" of {type_name(args[0]).split(' ', 1)[-1]}s" if args and args[0] is not Any else "")
    if origin in (dict, Mapping):
        return "an object" + (f" of {type_name(args[1])}" if len(args) == 2 and args[1] is not Any else "")
    return "a " + getattr(tp, "__name__", str(tp))
