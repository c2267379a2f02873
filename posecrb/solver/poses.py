"""The one check of an estimate's poses where they enter the library: an ``Estimate`` built by
the caller, a ``SolveResult`` built by the solver or read by ``load`` (docs/design.md#lie-groups)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..core.errors import ArgumentError
from ..lie.so import NotRotations, check_rotations


def _described(value: Any) -> str:
    shape = getattr(value, "shape", None)
    return f"<array of shape {shape}>" if shape is not None else f"<{type(value).__name__}>"


def checked_poses(rot: Any, trans: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(rot, trans)`` of an estimate where poses enter the library (an ``Estimate``, a
    ``SolveResult`` built or loaded): ``rot`` through ``posecrb.lie.so.check_rotations`` (float64;
    matrices off by rounding projected with a warning), ``trans`` real and finite with one row of
    d per rotation. Both empty (a result rebuilt by ``from_dict``) pass as they are. Anything else
    is an ``ArgumentError`` naming ``rot`` or ``trans``."""
    if np.size(rot) == 0 and np.size(trans) == 0:
        return rot, trans
    try:
        rot, _ = check_rotations(rot, name="rotations")
    except NotRotations as exc:
        raise ArgumentError("rot", _described(rot), str(exc), sep=": ") from None
    if rot.ndim != 3:
        raise ArgumentError("rot", _described(rot), "expected (n, d, d) rotations", sep=": ")
    values = np.asarray(trans)
    if np.iscomplexobj(values) or values.dtype.kind not in "fiu":
        raise ArgumentError("trans", _described(trans), "translations are real numbers", sep=": ")
    if values.shape != rot.shape[:2]:
        raise ArgumentError("trans", _described(trans), f"expected {rot.shape[:2]} translations (n, d) for the "
                            f"{rot.shape} rotations", sep=": ")
    values = values.astype(np.float64, copy=False)
    if not np.isfinite(values).all():
        raise ArgumentError("trans", _described(trans), "translations with non-finite values", sep=": ")
    return rot, values
