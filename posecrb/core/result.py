"""The one protocol of every result of the public API (docs/design.md#results).

A result is a frozen dataclass whose fields, in declaration order, give the keys of the
command's ``--format json`` object. ``Result`` gives every such class the same methods:

* ``to_dict()``: that object, JSON-serialisable (numpy values as Python numbers and lists,
  NaN as ``None``, infinities as ``"inf"``/``"-inf"``), pose ids never internal indices;
* ``from_dict(d)``: the inverse on what the dict carries (``from_dict(d).to_dict() == d``), each
  value checked against its field's type (a missing key, an unknown key, a value of another type
  or a malformed status is an ``ArgumentError``); the big arrays the JSON leaves out (an
  estimate's poses, a FIM) come back empty;
* ``to_frame()``: a pandas DataFrame (one row of the scalar values unless the class has
  per-pose or per-edge data);
* ``save(path)`` / ``load(path)``: the dict and the big arrays in one ``.npz`` file; ``save``
  refuses the files the result was computed from (``input_paths``);
* ``status``: the most severe ``Status`` of the result's numbers, ``statuses()`` each of them.

A result with natural parts holds them as typed parts, themselves ``Result`` s: ``part_field``
inlines a part's keys into the parent's JSON (the graph-only bounds in ``BoundsResult``), a
``NESTED`` field makes it the value of one key (the ``estimate`` object).

Field metadata (``field(metadata=...)``) tells the codec what a field is:

* ``array``: a big array, left out of the JSON and kept by ``save``;
* ``internal``: a value left out of the JSON and of the file (e.g. the files a result came from);
* ``omit_none``: the key is left out of the JSON when the value is None (keys that exist for
  one model only);
* ``nested``: a ``Result`` class whose ``to_dict`` is the value of the key;
* ``inline``: a ``Result`` class whose keys are the parent's (None: none of its keys);
* ``derived``: a function of the result that gives the value (not an argument of the class; what
  the JSON shows of it is not read back);
* ``key``: the JSON key when it differs from the field's name;
* ``codec``: a pair ``(encode, decode)`` of functions between the Python value and the JSON value
  (per-pose blocks: ``posecrb.models.results.pose_blocks_codec``);
* ``status_of``: the name of the attribute holding the ``Status`` of this number, when several
  numbers share one (they are rendered as a ``<key>_status`` field is);
* ``label``: for a ``Status`` field, the quantity it is about, as the command line names it
  on stderr.

A field of type ``Status`` named ``<key>_status`` follows ``<key>`` and is rendered as
``posecrb.core.status.put`` does: absent when ok, ``Status.as_json()`` otherwise, and
``<key>`` is ``None`` when the number is unavailable.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import numpy as np

from .archives import read_npz
from .arguments import check_input_argument, check_output_argument
from .errors import ArgumentError, ParseError
from .jsontypes import conform, is_status_json, short, type_hints, type_name
from .outputs import atomic_write
from .status import OK, Status, worst

R = TypeVar("R", bound="Result")

# metadata keys
ARRAY = "array"
INTERNAL = "internal"
OMIT_NONE = "omit_none"
NESTED = "nested"
INLINE = "inline"
DERIVED = "derived"
KEY = "key"
CODEC = "codec"
STATUS_OF = "status_of"
LABEL = "label"


# Values that are their own JSON form (floats are not: NaN and infinities are replaced).
_PLAIN_SCALARS = frozenset({int, str, bool, type(None)})


def plain(value: Any) -> Any:
    """``value`` with numpy arrays and scalars as Python lists and numbers, NaN as None and
    infinities as ``"inf"`` / ``"-inf"`` (what ``json.dumps(..., allow_nan=False)`` accepts)."""
    if isinstance(value, Result):
        return value.to_dict()
    if isinstance(value, Status):
        return value.as_json()
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        if all(type(v) in _PLAIN_SCALARS for v in value):     # already plain (ids, positions): no walk
            return list(value)
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "iub":                            # integers: nothing to replace
            return value.tolist()
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return plain(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def _no_array() -> np.ndarray:
    return np.empty(0)


def array_field(default: Any = dataclasses.MISSING) -> Any:
    """A big array: not in the JSON, kept by ``save``; empty (size 0) after ``from_dict``
    unless ``default`` says otherwise."""
    if default is dataclasses.MISSING:
        return dataclasses.field(default_factory=_no_array, repr=False, compare=False, metadata={ARRAY: True})
    return dataclasses.field(default=default, repr=False, compare=False, metadata={ARRAY: True})


def internal_field(default: Any = None, *, factory: Callable[[], Any] | None = None) -> Any:
    """A value that is neither in the JSON nor in the file (its default, or ``factory()``, after
    ``from_dict``)."""
    if factory is not None:
        return dataclasses.field(default_factory=factory, compare=False, repr=False, metadata={INTERNAL: True})
    return dataclasses.field(default=default, compare=False, repr=False, metadata={INTERNAL: True})


def inputs_field() -> Any:
    """The files the result was computed from (graph, estimate file): refused by ``save`` and by
    every writer given the result; not in the JSON."""
    return internal_field(())


def optional_field(default: Any = None, **metadata: Any) -> Any:
    """A key present in the JSON only when the value is not None."""
    return dataclasses.field(default=default, metadata={OMIT_NONE: True, **metadata})


def part_field(cls: type[Result], *, optional: bool = False) -> Any:
    """A typed part whose keys are inlined into the parent's JSON (``optional``: None, and then
    none of its keys, when absent)."""
    if optional:
        return dataclasses.field(default=None, metadata={INLINE: cls})
    return dataclasses.field(metadata={INLINE: cls})


def derived_field(compute: Callable[[Any], Any], *, key: str | None = None, omit_none: bool = False) -> Any:
    """A key computed from the other fields (``compute(result)``) when the result is made."""
    meta: dict[str, Any] = {DERIVED: compute, OMIT_NONE: omit_none}
    if key is not None:
        meta[KEY] = key
    return dataclasses.field(init=False, compare=False, repr=False, metadata=meta)


def status_field(label: str | None = None, *, key: str | None = None) -> Any:
    """The ``Status`` of the preceding number (``label``: the quantity, as stderr names it;
    default the number's key; ``key``: the JSON key, ``<number's key>_status``, when it differs from
    the field's name)."""
    meta: dict[str, Any] = {} if label is None else {LABEL: label}
    if key is not None:
        meta[KEY] = key
    return dataclasses.field(default=OK, metadata=meta)


def shared_status_field(status_of: str, default: Any = dataclasses.MISSING, *, omit_none: bool = False) -> Any:
    """A number whose ``Status`` is the attribute ``status_of`` (shared with other numbers)."""
    meta = {STATUS_OF: status_of, OMIT_NONE: omit_none}
    return dataclasses.field(default=default, metadata=meta)


def _key(f: dataclasses.Field[Any]) -> str:
    return str(f.metadata.get(KEY, f.name))


def _is_status_field(f: dataclasses.Field[Any]) -> bool:
    return _key(f).endswith("_status") and f.default is OK


class Result:
    """Base of every public result class (a frozen dataclass); see the module docstring."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            compute = f.metadata.get(DERIVED)
            if compute is not None:
                object.__setattr__(self, f.name, compute(self))

    # ---- dict ------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The command's ``--format json`` object (pose ids, never internal indices)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            if f.metadata.get(ARRAY) or f.metadata.get(INTERNAL):
                continue
            value = getattr(self, f.name)
            key = _key(f)
            if f.metadata.get(INLINE) is not None:
                if value is not None:
                    out.update(value.to_dict())
                continue
            if isinstance(value, Status) and _is_status_field(f):
                _put_status(out, key[: -len("_status")], value)
                continue
            shared = getattr(self, f.metadata[STATUS_OF]) if f.metadata.get(STATUS_OF) else OK
            if value is None and f.metadata.get(OMIT_NONE) and shared.ok:
                continue
            codec = f.metadata.get(CODEC)
            out[key] = plain(codec[0](value) if codec else value)
            _put_status(out, key, shared)
        return out

    @classmethod
    def from_dict(cls: type[R], d: Mapping[str, Any]) -> R:
        """The result that ``to_dict`` gave ``d``, each value checked against its field's type.

        Raises ``ArgumentError`` when ``d`` is not a mapping, lacks a key the class needs, has a
        key it does not have, or holds a value of another type (a malformed status included)."""
        if not isinstance(d, Mapping):
            raise ArgumentError("d", type(d).__name__, f"is not a mapping (a {cls.__name__} dict)", sep=": ")
        unknown = [k for k in d if k not in cls.json_keys()]
        if unknown:
            raise _bad(cls, d, f"has keys a {cls.__name__} does not have: {', '.join(map(repr, unknown[:5]))}")
        res = cls._from_mapping(d)
        back = res.to_dict()
        if back != dict(d):    # a key derived from others, or a status that contradicts them
            missing = object()
            key = next(k for k in (*d, *back) if back.get(k, missing) != d.get(k, missing))
            raise _bad(cls, d, f"key {key!r} of a {cls.__name__} is {short(d.get(key))}, which contradicts the "
                               f"other keys (they give {short(back.get(key))})")
        return res

    @classmethod
    def _restore(cls, kwargs: dict[str, Any], d: Mapping[str, Any]) -> None:
        """Set in ``kwargs`` the fields that ``from_dict`` reads from keys other than their own
        (a status that several numbers share); nothing by default."""

    @classmethod
    def _from_mapping(cls: type[R], d: Mapping[str, Any]) -> R:
        kwargs: dict[str, Any] = {}
        hints = type_hints(cls)
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.metadata.get(ARRAY) or f.metadata.get(INTERNAL) or not f.init:
                continue
            key = _key(f)
            part = f.metadata.get(INLINE)
            if part is not None:
                if f.default is None and not any(k in d for k in part.json_keys()):
                    continue
                kwargs[f.name] = part._from_mapping(d)
                continue
            if _is_status_field(f):
                if d.get(key) is not None:
                    kwargs[f.name] = _status(cls, d, key, d[key])
                continue
            if key not in d:
                if f.metadata.get(OMIT_NONE) or f.default is not dataclasses.MISSING \
                        or f.default_factory is not dataclasses.MISSING:
                    continue
                raise _bad(cls, d, f"lacks the key {key!r} of a {cls.__name__}")
            value = d[key]
            nested = f.metadata.get(NESTED)
            codec = f.metadata.get(CODEC)
            if nested is not None and value is not None:
                value = nested.from_dict(value)
            elif codec is not None:
                try:
                    value = codec[1](value)
                except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
                    raise _bad(cls, d, f"key {key!r} of a {cls.__name__} is malformed ({exc})") from None
            else:
                value = _checked(cls, d, key, value, hints[f.name])
            if f.metadata.get(STATUS_OF) is not None and d.get(f"{key}_status") is not None:
                _status(cls, d, f"{key}_status", d[f"{key}_status"])
            kwargs[f.name] = value
        cls._restore(kwargs, d)
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as exc:
            raise _bad(cls, d, f"does not make a {cls.__name__} ({exc})") from None

    @classmethod
    def json_keys(cls) -> frozenset[str]:
        """Every key the class's JSON may have (inlined parts' included)."""
        return _json_keys(cls)

    # ---- statuses --------------------------------------------------------------------------
    def statuses(self) -> dict[str, Status]:
        """Every ``Status`` of the result by the quantity it is about (parts included)."""
        out: dict[str, Status] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if isinstance(value, Status):
                out[f.metadata.get(LABEL, _key(f).removesuffix("_status"))] = value
            elif isinstance(value, Result):
                out.update(value.statuses())
        return out

    @property
    def status(self) -> Status:
        """The most severe status of the result's numbers (``Status()``, ok, when all are)."""
        return worst(*self.statuses().values()) if self.statuses() else OK

    # ---- inputs ----------------------------------------------------------------------------
    def input_paths(self) -> tuple[str, ...]:
        """The files the result was computed from (its graph, an estimate file), as far as it
        knows them: ``save`` and every writer given the result refuse to write onto them."""
        out: list[str] = []
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if f.name == "inputs" and f.metadata.get(INTERNAL):
                out += [str(v) for v in value or () if v]
            elif isinstance(value, Result):
                out += value.input_paths()
        return tuple(dict.fromkeys(out))

    # ---- frame -----------------------------------------------------------------------------
    def to_frame(self) -> Any:
        """One row of the result's scalar values (nested dicts as dotted columns), as a pandas
        DataFrame; classes with per-pose or per-edge data return those instead."""
        import pandas as pd  # noqa: PLC0415 -- lazy: start-up time (pandas only for frames)

        return pd.DataFrame([_scalars(self.to_dict())])

    # ---- npz -------------------------------------------------------------------------------
    def arrays(self) -> dict[str, np.ndarray]:
        """The big arrays ``save`` writes next to the dict (by field name)."""
        out: dict[str, np.ndarray] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if f.metadata.get(ARRAY) and value is not None and np.size(value):
                out[f.name] = np.asarray(value)
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> dict[str, Any]:
        """The fields ``arrays`` (as written by ``arrays``) give back."""
        names = {f.name for f in dataclasses.fields(cls) if f.metadata.get(ARRAY)}  # type: ignore[arg-type]
        return {k: v for k, v in arrays.items() if k in names}

    def save(self, path: str | os.PathLike[str]) -> str:
        """Write the result to ``path`` (``.npz`` appended unless present), atomically.

        The file holds ``to_dict()`` as JSON (key ``result``), the class name (``result_type``)
        and the big arrays; ``load`` reads it back. The path is checked first as every output is
        (``ArgumentError``): not empty, in an existing writable directory, not one of the files
        the result was computed from (``input_paths``). Returns the path written."""
        target = check_output_argument("path", path, self.input_paths(), extensions=(".npz",), append=".npz")
        payload = {"result": np.array(json.dumps(self.to_dict(), allow_nan=False)),
                   "result_type": np.array(type(self).__name__), **self.arrays()}
        with atomic_write(target, "wb") as fh:
            np.savez(fh, **payload)  # type: ignore[arg-type]
        return target

    @classmethod
    def load(cls: type[R], path: str | os.PathLike[str]) -> R:
        """The result ``save`` wrote to ``path`` (read through the input layer: capped inflation, no
        pickles).

        Raises ``ParseError`` (the path and the reason) for a file that is not such a result,
        and ``ArgumentError`` for a path that is not one."""
        name = check_input_argument("path", path)
        data = read_npz(name)
        kind = str(data.pop("result_type", ""))
        if kind != cls.__name__ or "result" not in data:
            raise ParseError(name, None, f"holds a {kind or 'non-posecrb'} result, not a {cls.__name__}")
        try:
            d = json.loads(str(data.pop("result")))
            result = cls.from_dict(d)
            return dataclasses.replace(result, **cls.from_arrays(data))  # type: ignore[type-var]
        except (ValueError, TypeError, KeyError, IndexError) as exc:   # ArgumentError is a ValueError
            raise ParseError(name, None, f"a malformed {cls.__name__} ({exc})") from None


def _put_status(out: dict[str, Any], key: str, status: Status) -> None:
    """``posecrb.core.status.put`` on a key already written: None when unavailable, the status after it."""
    if not status.ok:
        if not status.available:
            out[key] = None
        out[f"{key}_status"] = status.as_json()


def _bad(cls: type, d: Mapping[str, Any], reason: str) -> ArgumentError:
    return ArgumentError("d", f"{{... {len(d)} keys}}", reason, sep=": ")


def _status(cls: type, d: Mapping[str, Any], key: str, value: Any) -> Status:
    """A status from its JSON form, checked (``posecrb.core.jsontypes.is_status_json``)."""
    if not is_status_json(value):
        raise _bad(cls, d, f"key {key!r} of a {cls.__name__} is not a status ({{'status': 'warning' or "
                           f"'unavailable', 'reason': text}}): {short(value)}")
    return Status.from_json(value)


def _checked(cls: type, d: Mapping[str, Any], key: str, value: Any, tp: Any) -> Any:
    """``value`` if it is of type ``tp`` as JSON gives it (``posecrb.core.jsontypes.conform``), else
    ``ArgumentError`` naming the key."""
    ok, got = conform(value, tp, lambda c, v: c.from_dict(v))
    if not ok:
        raise _bad(cls, d, f"key {key!r} of a {cls.__name__} is {short(value)}, not {type_name(tp)}")
    return got


_JSON_KEYS: dict[type, frozenset[str]] = {}


def _json_keys(cls: type[Result]) -> frozenset[str]:
    if cls in _JSON_KEYS:
        return _JSON_KEYS[cls]
    keys: set[str] = set()
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.metadata.get(ARRAY) or f.metadata.get(INTERNAL):
            continue
        part = f.metadata.get(INLINE)
        if part is not None:
            keys |= part.json_keys()
        elif _is_status_field(f):
            keys |= {_key(f), _key(f)[: -len("_status")]}
        else:
            keys.add(_key(f))
            if f.metadata.get(STATUS_OF) is not None:
                keys.add(f"{_key(f)}_status")
    _JSON_KEYS[cls] = frozenset(keys)
    return _JSON_KEYS[cls]


def _scalars(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, Mapping):
            out.update(_scalars(v, f"{prefix}{k}."))
        elif isinstance(v, list):
            if all(not isinstance(x, (list, Mapping)) for x in v) and len(v) <= 16:
                out[f"{prefix}{k}"] = ",".join(map(str, v))
        else:
            out[f"{prefix}{k}"] = v
    return out


@dataclasses.dataclass(frozen=True, kw_only=True)
class GraphKeys(Result):
    """The first keys of the result of one graph file: its name, file, the file's sha256, d, n and m."""

    dataset: str
    path: str | None
    sha256: str | None
    dim: int
    poses: int
    edges: int
