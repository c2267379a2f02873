"""The options of ``solve``: one typed dataclass, the preconditioner one typed choice (docs/design.md#solver)."""
from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, Literal, get_args

import numpy as np

from ..core.errors import UsageError
from .trust_region import TROptions

# Which preconditioner the staircase uses (docs/decisions/solver-preconditioners.md).
Preconditioner = Literal["auto", "tangent", "base", "none"]
PRECONDITIONER_CHOICES: tuple[str, ...] = get_args(Preconditioner)

# The base factor: "schur", SE-Sync's (Q + delta I)^{-1} through a factor of M_red(delta); "rotation",
# (C + delta I)^{-1} of the rotation block C alone; "auto", the size rule of
# posecrb.solver.preconditioners.base_preconditioner_kind.
BaseFactorKind = Literal["auto", "schur", "rotation"]
BASE_PRECONDITIONERS: tuple[str, ...] = get_args(BaseFactorKind)

# TROptions fields a caller may set through SolverOptions.trust_region (max_iterations is a
# SolverOptions field of its own).
_TR_TUNING = frozenset(f.name for f in fields(TROptions)) - {"max_iterations"}


def check_base_kind(name: str) -> None:
    """UsageError unless ``name`` is one of ``BASE_PRECONDITIONERS``."""
    if name not in BASE_PRECONDITIONERS:
        raise UsageError(f"unknown base preconditioner {name!r}; choose from {', '.join(BASE_PRECONDITIONERS)}")


@dataclass(frozen=True, kw_only=True)
class PreconditionerSettings:
    """Expert settings of the solver's preconditioners; the defaults are what ``solve`` is tuned for.

    Parameters
    ----------
    base : {"auto", "schur", "rotation"}
        The base factor: SE-Sync's ``(Q + delta I)^{-1}`` through a factor of ``M_red(delta)``
        ("schur"), the rotation block's ``(C + delta I)^{-1}`` ("rotation"), or by size ("auto":
        "rotation" on 3D graphs from 10,000 poses, whose factorizations are threaded).
    max_condition : float
        Cap on the base factor's condition number: ``delta = lambda_max bound / max_condition``
        (SE-Sync's regularised Cholesky). Above 1.
    adaptive_shift : float or None
        The shift ``s`` of ``(Q - Lambda + s I)^{-1}`` relative to the Gershgorin bound on
        ``lambda_max(Q)``; None keeps the base factor throughout and turns off the tangent and
        split preconditioners, which rest on it.
    refactor_hvps : int or None
        Refactor ``(Q - Lambda + s I)^{-1}`` at an iterate once a truncated-CG run needed more than
        this many Hessian-vector products; None: at every accepted iterate.
    split_after_escape : bool
        After an escape from the first level, precondition with that level's tangent factor
        in-plane and ``(Q - Lambda + sigma I)^{-1}`` on the new column.

    Examples
    --------
    >>> from posecrb.solver import PreconditionerSettings, SolverOptions
    >>> SolverOptions(preconditioner_settings=PreconditionerSettings(base="rotation")).preconditioner_settings.base
    'rotation'
    """

    base: BaseFactorKind = "auto"
    max_condition: float = 1e6
    adaptive_shift: float | None = 1e-10
    refactor_hvps: int | None = 30
    split_after_escape: bool = True

    def __post_init__(self) -> None:
        check_base_kind(self.base)
        if not (_real(self.max_condition) and self.max_condition > 1):
            raise UsageError(f"max_condition must be a finite number above 1, got {self.max_condition!r}")
        if self.adaptive_shift is not None and not (_real(self.adaptive_shift) and self.adaptive_shift >= 0):
            raise UsageError(f"adaptive_shift must be None or a finite number >= 0, got {self.adaptive_shift!r}")
        if self.refactor_hvps is not None and not (isinstance(self.refactor_hvps, int | np.integer)
                                                   and not isinstance(self.refactor_hvps, bool)
                                                   and self.refactor_hvps >= 0):
            raise UsageError(f"refactor_hvps must be None or an integer >= 0, got {self.refactor_hvps!r}")
        if not isinstance(self.split_after_escape, bool | np.bool_):
            raise UsageError(f"split_after_escape must be True or False, got {self.split_after_escape!r}")


def _real(value: object) -> bool:
    """Whether ``value`` is a finite real number (not a bool)."""
    return (isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
            and math.isfinite(value))


@dataclass(frozen=True, kw_only=True)
class SolverOptions:
    """Options of :func:`posecrb.solver.solve`; the defaults are SE-Sync's settings.

    Parameters
    ----------
    r0, rmax : int
        First (default d + 1) and last rank of the Riemannian staircase. The start's zero
        padding is filled by escapes before the rank grows past r0.
    init : {"chordal", "vertices"} or numpy.ndarray
        The initial rotations: the chordal relaxation, the file's own vertices, or an
        (n, d, d) array.
    anchor : int or None
        Internal index of the pose put at the identity (default 0).
    max_iterations : int
        Trust-region iterations per staircase level.
    certificate_tol : float
        Accept ``lambda_min(Q - Lambda) >= -certificate_tol`` as the certificate.
    verbose : bool
        Log each staircase level at INFO.
    seed : int
        Seed of the verification's random Lanczos start (the solver is deterministic).
    preconditioner : {"auto", "tangent", "base", "none"}
        "auto": the first level takes the tangent space's inverse Hessian in 2D, and in 3D the
        base factor until a truncated-CG run needs more than 20 products, then the tangent one;
        later levels ``(Q - Lambda + s I)^{-1}``, split after an escape from the first level.
        "tangent": the tangent one from the start in 3D too. "base": never the tangent one (the
        base factor and ``(Q - Lambda + s I)^{-1}``). "none": no preconditioner.
    preconditioner_settings : PreconditionerSettings
        Expert settings of those preconditioners.
    trust_region : Mapping of str to Any
        Other :class:`~posecrb.solver.trust_region.TROptions` fields (``theta``,
        ``decrement_tol``, ``exact_decrement_tol``, ...).

    Examples
    --------
    >>> from posecrb.solver import SolverOptions
    >>> SolverOptions.from_keywords(anchor=3, theta=1.0).trust_region
    {'theta': 1.0}
    >>> SolverOptions(preconditioner="base").preconditioner_settings.base
    'auto'
    """

    r0: int | None = None
    rmax: int = 10
    init: str | np.ndarray = "chordal"
    anchor: int | None = None
    max_iterations: int = 500
    certificate_tol: float = 1e-3
    verbose: bool = False
    seed: int = 0
    preconditioner: Preconditioner = "auto"
    preconditioner_settings: PreconditionerSettings = field(default_factory=PreconditionerSettings)
    trust_region: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.preconditioner not in PRECONDITIONER_CHOICES:
            raise UsageError(f"unknown preconditioner {self.preconditioner!r}; "
                             f"choose from {', '.join(PRECONDITIONER_CHOICES)}")
        if not isinstance(self.preconditioner_settings, PreconditionerSettings):
            raise UsageError("preconditioner_settings must be a PreconditionerSettings, "
                             f"got {type(self.preconditioner_settings).__name__}")
        unknown = set(self.trust_region) - _TR_TUNING
        if unknown:
            raise UsageError(f"unknown trust-region option(s) {', '.join(sorted(unknown))}; "
                             f"choose from {', '.join(sorted(_TR_TUNING))}")

    @classmethod
    def from_keywords(cls, base: SolverOptions | None = None, **keywords: Any) -> SolverOptions:
        """``base`` (default: the defaults) with ``keywords`` applied: SolverOptions fields by name,
        TROptions fields into ``trust_region``, the preconditioner keywords of earlier versions
        translated with a DeprecationWarning; any other name is a UsageError."""
        base = cls() if base is None else base
        keywords = _translate_deprecated(base, keywords)
        own = {f.name for f in fields(cls)} - {"trust_region"}
        tuning = {k: v for k, v in keywords.items() if k not in own}
        unknown = set(tuning) - _TR_TUNING
        if unknown:
            raise UsageError(f"unknown solver option(s) {', '.join(sorted(unknown))}")
        return replace(base, **{k: v for k, v in keywords.items() if k in own},
                       trust_region={**base.trust_region, **tuning})


# The preconditioner keywords of earlier versions that map onto PreconditionerSettings fields.
_DEPRECATED_SETTINGS = {"base_precond": "base", "precond_max_cond": "max_condition",
                        "adaptive_precond": "adaptive_shift", "refactor_hvps": "refactor_hvps",
                        "split_precond": "split_after_escape"}
# tangent_precond's values as the preconditioner choice that replaces them.
_DEPRECATED_TANGENT: dict[bool | None, Preconditioner] = {None: "auto", True: "tangent", False: "base"}


def _translate_deprecated(base: SolverOptions, keywords: dict[str, Any]) -> dict[str, Any]:
    """``keywords`` with ``precondition``, ``tangent_precond`` and the keys of ``_DEPRECATED_SETTINGS``
    replaced by ``preconditioner`` and ``preconditioner_settings``, each with a DeprecationWarning
    naming its new form. A deprecated keyword given with its replacement is a UsageError."""
    old = {k: keywords[k] for k in (*_DEPRECATED_SETTINGS, "precondition", "tangent_precond") if k in keywords}
    if not old:
        return keywords
    new = {k: v for k, v in keywords.items() if k not in old}
    if "precondition" in old or "tangent_precond" in old:
        if "preconditioner" in new:
            raise UsageError("give preconditioner= alone, without precondition= or tangent_precond=")
        choice: Preconditioner = base.preconditioner
        if "tangent_precond" in old:
            if old["tangent_precond"] not in _DEPRECATED_TANGENT:
                raise UsageError(f"tangent_precond must be None, True or False, got {old['tangent_precond']!r}")
            choice = _DEPRECATED_TANGENT[old["tangent_precond"]]
        if "precondition" in old:
            choice = "none" if not old["precondition"] else "auto" if choice == "none" else choice
        for name in ("precondition", "tangent_precond"):
            if name in old:
                _warn(f"{name}={old[name]!r}", f"preconditioner={choice!r}")
        new["preconditioner"] = choice
    settings = {_DEPRECATED_SETTINGS[k]: v for k, v in old.items() if k in _DEPRECATED_SETTINGS}
    if settings:
        if "preconditioner_settings" in new:
            raise UsageError("give preconditioner_settings= alone, without "
                             f"{', '.join(k for k in old if k in _DEPRECATED_SETTINGS)}")
        for key, value in old.items():
            if key in _DEPRECATED_SETTINGS:
                _warn(f"{key}={value!r}", "preconditioner_settings=posecrb.solver.PreconditionerSettings("
                                          f"{_DEPRECATED_SETTINGS[key]}={value!r})")
        new["preconditioner_settings"] = replace(base.preconditioner_settings, **settings)
    return new


def _warn(old: str, new: str) -> None:
    # stacklevel: the caller of solve() (this, _translate_deprecated, from_keywords, solve)
    warnings.warn(f"solve({old}) is deprecated; use solve({new})", DeprecationWarning, stacklevel=5)
