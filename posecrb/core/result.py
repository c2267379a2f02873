"""The one protocol of every result of the public API (docs/design.md#results).

A result is a frozen dataclass whose fields, in declaration order, are the keys of the
command's ``--format json`` object. ``Result`` gives every such class the same methods:

* ``to_dict()``: that object, JSON-serialisable (numpy values as Python numbers and lists,
  NaN as ``None``, infinities as ``"inf"``/``"-inf"``), pose ids never internal indices;
* ``from_dict(d)``: the inverse on what the dict carries (``from_dict(d).to_dict() == d``);
  the big arrays the JSON leaves out (an estimate's poses, a FIM) come back empty;
* ``to_frame()``: a pandas DataFrame (one row of the scalar values unless the class has
  per-pose or per-edge data);
* ``save(path)`` / ``load(path)``: the dict and the big arrays in one ``.npz`` file;
* ``status``: the most severe ``Status`` of the result's numbers, ``statuses()`` each of them.

Field metadata (``field(metadata=...)``) tells the codec what a field is:

* ``array``: a big array, left out of the JSON and kept by ``save``;
* ``internal``: a value left out of the JSON and of the file (e.g. a time kept elsewhere);
* ``omit_none``: the key is left out of the JSON when the value is None (keys that exist for
  one model only);
* ``nested``: a ``Result`` class whose ``to_dict`` is the value of the key;
* ``codec``: a pair ``(encode, decode)`` of functions between the Python value and the JSON
  value;
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
from .errors import ArgumentError, ParseError, UsageError
from .outputs import atomic_write, check_output_file
from .status import OK, Status, worst

R = TypeVar("R", bound="Result")

# metadata keys
ARRAY = "array"
INTERNAL = "internal"
OMIT_NONE = "omit_none"
NESTED = "nested"
CODEC = "codec"
LABEL = "label"


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
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
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


def internal_field(default: Any = None) -> Any:
    """A value that is neither in the JSON nor in the file (its default after ``from_dict``)."""
    return dataclasses.field(default=default, compare=False, metadata={INTERNAL: True})


def optional_field(default: Any = None, **metadata: Any) -> Any:
    """A key present in the JSON only when the value is not None."""
    return dataclasses.field(default=default, metadata={OMIT_NONE: True, **metadata})


def status_field(label: str | None = None) -> Any:
    """The ``Status`` of the preceding number (``label``: the quantity, as stderr names it;
    default the number's key)."""
    return dataclasses.field(default=OK, metadata={} if label is None else {LABEL: label})


def pose_blocks_codec() -> tuple[Callable[[Any], Any], Callable[[Any], Any]]:
    """Per-pose matrices: ``{pose id: array}`` in Python, ``{"id": [[...]]}`` in JSON."""

    def encode(blocks: Mapping[int, np.ndarray] | None) -> Any:
        return None if blocks is None else {str(k): plain(np.asarray(v)) for k, v in blocks.items()}

    def decode(blocks: Mapping[str, Any] | None) -> Any:
        return None if blocks is None else {int(k): np.asarray(v, dtype=float) for k, v in blocks.items()}

    return encode, decode


class Result:
    """Base of every public result class (a frozen dataclass); see the module docstring."""

    # ---- dict ------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The command's ``--format json`` object (pose ids, never internal indices)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            if f.metadata.get(ARRAY) or f.metadata.get(INTERNAL):
                continue
            value = getattr(self, f.name)
            if isinstance(value, Status) and f.name.endswith("_status"):
                key = f.name[: -len("_status")]
                if not value.ok:
                    if not value.available:
                        out[key] = None
                    out[f.name] = value.as_json()
                continue
            if value is None and f.metadata.get(OMIT_NONE):
                continue
            codec = f.metadata.get(CODEC)
            out[f.name] = plain(codec[0](value) if codec else value)
        return out

    @classmethod
    def from_dict(cls: type[R], d: Mapping[str, Any]) -> R:
        """The result that ``to_dict`` gave ``d`` (arrays left out of the JSON are ``None``).

        Raises ``ArgumentError`` when ``d`` lacks a key the class needs."""
        if not isinstance(d, Mapping):
            raise ArgumentError("d", type(d).__name__, f"is not a mapping (a {cls.__name__} dict)", sep=": ")
        kwargs: dict[str, Any] = {}
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.metadata.get(ARRAY) or f.metadata.get(INTERNAL):
                continue
            if f.name.endswith("_status") and f.default is OK:
                kwargs[f.name] = Status.from_json(d[f.name]) if d.get(f.name) is not None else OK
                continue
            if f.name not in d:
                if f.metadata.get(OMIT_NONE) or f.default is not dataclasses.MISSING \
                        or f.default_factory is not dataclasses.MISSING:
                    continue
                raise ArgumentError("d", f"{{... {len(d)} keys}}", f"lacks the key {f.name!r} of a {cls.__name__}",
                                    sep=": ")
            value = d[f.name]
            nested = f.metadata.get(NESTED)
            codec = f.metadata.get(CODEC)
            if nested is not None and value is not None:
                value = nested.from_dict(value)
            elif codec is not None:
                value = codec[1](value)
            kwargs[f.name] = value
        return cls(**kwargs)

    # ---- statuses --------------------------------------------------------------------------
    def statuses(self) -> dict[str, Status]:
        """Every ``Status`` of the result by the quantity it is about (nested results included)."""
        out: dict[str, Status] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if isinstance(value, Status):
                out[f.metadata.get(LABEL, f.name.removesuffix("_status"))] = value
            elif isinstance(value, Result):
                out.update(value.statuses())
        return out

    @property
    def status(self) -> Status:
        """The most severe status of the result's numbers (``Status()``, ok, when all are)."""
        return worst(*self.statuses().values()) if self.statuses() else OK

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
        and the big arrays; ``load`` reads it back. Returns the path written."""
        check_output_argument("path", path)      # as given: not None, empty, a device or a directory
        target = npz_path(os.fspath(path))
        check_output_argument("path", target)
        payload = {"result": np.array(json.dumps(self.to_dict(), allow_nan=False)),
                   "result_type": np.array(type(self).__name__), **self.arrays()}
        with atomic_write(target, "wb") as fh:
            np.savez(fh, **payload)  # type: ignore[arg-type]
        return target

    @classmethod
    def load(cls: type[R], path: str | os.PathLike[str]) -> R:
        """The result ``save`` wrote to ``path`` (read through the input layer)."""
        data = read_npz(path)       # the input layer: capped inflation, no pickles, ParseError
        name = os.fspath(path)
        kind = str(data.pop("result_type", ""))
        if kind != cls.__name__ or "result" not in data:
            raise ParseError(name, None, f"holds a {kind or 'non-posecrb'} result, not a {cls.__name__}")
        result = cls.from_dict(json.loads(str(data.pop("result"))))
        return dataclasses.replace(result, **cls.from_arrays(data))  # type: ignore[type-var]


def check_output_argument(parameter: str, path: str | os.PathLike[str],
                          inputs: tuple[str | os.PathLike[str] | None, ...] = (), *,
                          extensions: tuple[str, ...] | None = None) -> str:
    """``posecrb.core.outputs.check_output_file`` for a library argument: the same checks (the
    extension among ``extensions`` included), before any work, with the error naming
    ``parameter`` (an ``ArgumentError``: ``save='x.npz': ...``; the command line shows
    ``--save x.npz: ...``). Returns the path as a string."""
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise ArgumentError(parameter, path, "is not a file name (a non-empty str or os.PathLike)")
    shown = os.fspath(path)
    try:
        check_output_file(shown, inputs, option=None, extensions=extensions)
    except UsageError as exc:
        text = str(exc)
        reason = text[len(shown):] if text.startswith(shown) else f": {text}"
        colon = reason.startswith(":")
        raise ArgumentError(parameter, shown, reason[1:].strip() if colon else reason.strip(),
                            sep=": " if colon else " ") from None
    return str(shown)


def npz_path(path: str) -> str:
    """The file ``save(path)`` writes: numpy's rule, ``.npz`` appended unless present."""
    return path if path.endswith(".npz") else path + ".npz"


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
