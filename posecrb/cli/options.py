"""Options, option types and helpers shared by subcommands."""
from __future__ import annotations

import logging
import math
import os
import re
import shlex
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import click

from ..core.choices import (
    ESTIMATE_SOURCES,
    ESTIMATE_SOURCES_OR_NONE,
    FIM_VARIANTS,
    FORMATS,
    FRAMES,
    MODELS,
    ORDERINGS,
    ROTATION_WEIGHTS,
)
from ..core.errors import ArgumentError, PosecrbError, UsageError
from ..core.integers import INT64_MAX, IntegerError, check_int, parse_int, shown
from ..core.timing import AUTO, Repeat, measure
from ..datasets import search as datasets
from .paths import InputDir, InputFile

if TYPE_CHECKING:
    from ..core.graph import PoseGraph

log = logging.getLogger("posecrb")

# What click.option(...) returns: a decorator of command functions.
OptionDecorator = Callable[[Callable[..., Any]], Callable[..., Any]]

_PLAIN_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


class FiniteFloat(click.FloatRange):
    """A float option that is a plain decimal number, finite, and inside [min, max].

    click's FLOAT/FloatRange accept ``nan`` (every comparison with NaN is false, so the
    range check passes), ``inf`` and Python's ``1_0``; a NaN tolerance made the solver loop
    forever. Every float option of posecrb uses this type: a bad value is a usage error
    (exit 2) naming the option.
    """

    name = "float"

    def convert(self, value, param, ctx):
        if isinstance(value, str):
            text = value.strip()
            if _PLAIN_NUMBER.fullmatch(text) is None:
                low = text.lower().lstrip("+-")
                what = "not a finite number" if low in ("nan", "inf", "infinity") else "not a number"
                self.fail(f"{value!r} is {what}", param, ctx)
            value = float(text)
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            value = float(value)
        if isinstance(value, float) and not math.isfinite(value):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return super().convert(value, param, ctx)


class PlainInt(click.IntRange):
    """An integer option written as plain decimal digits (an optional sign), inside [min, max].

    click's INT/IntRange take what Python's ``int`` takes: ``1_0`` (ten), non-ASCII digits and
    surrounding Unicode spaces. Every integer option of posecrb uses this type."""

    name = "integer"

    def convert(self, value, param, ctx):
        if isinstance(value, str):
            try:
                value = parse_int(value)          # int64 (no int() of thousands of digits); click checks the range
            except IntegerError as exc:
                self.fail(f"{shown(value)} {exc}", param, ctx)
        return super().convert(value, param, ctx)


class PoseId(click.ParamType):
    """A pose id as in the files: a non-negative integer that fits int64 (digits only)."""

    name = "ID"

    def convert(self, value, param, ctx):
        try:
            if isinstance(value, int) and not isinstance(value, bool):
                return check_int(value, lo=0, hi=INT64_MAX)
            return parse_int(str(value), lo=0, hi=INT64_MAX, what="a pose id")
        except IntegerError:
            self.fail(f"{shown(value)} is not a pose id (a non-negative integer up to 2^63-1)", param, ctx)


POSE_ID = PoseId()


def format_option(choices=FORMATS, default="table"):
    return click.option("--format", "fmt", type=click.Choice(list(choices)), default=default,
                        show_default=True, help="Output format (results on stdout).")


data_dir_option = click.option(
    "--data-dir", type=InputDir(), default=None,
    help="Directory searched first for bare dataset names (must exist).")

# Seeds go to numpy.random.SeedSequence (any non-negative integer) and are recorded in run.json and
# in int64 arrays: non-negative and within int64.
SEED_RANGE = PlainInt(0, 2 ** 63 - 1)

anchor_option = click.option(
    "--anchor", type=POSE_ID, default=None,
    help="Pose id (as in the file) anchored to the origin; default: the smallest id.")


class RepeatCount(click.ParamType):
    """``auto`` or a whole number of timed runs from 1 to 1000."""

    name = "auto|K"

    def convert(self, value, param, ctx):
        if value == AUTO:
            return AUTO
        try:
            if isinstance(value, int) and not isinstance(value, bool):
                return check_int(value, lo=1, hi=1000)
            if str(value).strip().lower() == AUTO:
                return AUTO
            return parse_int(str(value), lo=1, hi=1000)
        except IntegerError:
            self.fail(f"{shown(value)} is neither 'auto' nor a whole number from 1 to 1000", param, ctx)


repeat_option = click.option(
    "--repeat", type=RepeatCount(), default=AUTO, show_default=True,
    help="Timing of each stage: auto = one run when it takes >= 1 s, else a warm-up and the median of "
         "the runs that fit in about 2 s (at most 5); K = a warm-up, then the median of K runs; "
         "1 = one run. The JSON's runs says how many runs each time is the median of.")


def load_dataset(name_or_path: str, data_dir: str | None = None, repeat: Repeat = 1, *,
                 quaternions: str = "normalize") -> tuple[PoseGraph, float]:
    """Resolve a path or bare name and parse it (``quaternions`` as ``posecrb.load``); returns the
    graph and the median parse time (``posecrb.core.timing.measure``)."""
    from ..io import load  # noqa: PLC0415 -- lazy: start-up time (numpy)

    path = datasets.resolve(name_or_path, data_dir)
    timing = measure(lambda: load(path, quaternions=quaternions), repeat=repeat)
    return timing.value, timing.seconds


def parse_pose_ids(text: str) -> bool | list[int]:
    """``--poses``: ``all`` (True) or pose ids and id ranges, ``0,5,10-12`` -> ``[0, 5, 10, 11, 12]``
    (the library's ``poses=``)."""
    text = text.strip()
    if text.lower() == "all":
        return True
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        # digits only (int() would take 1_0 and non-ASCII digits), at most 19 of them (int64)
        if re.fullmatch(r"[0-9]{1,19}(?:-[0-9]{1,19})?", part) is None or max(map(int, part.split("-"))) > INT64_MAX:
            raise ArgumentError("poses", part, "is not a pose id or an id range a-b")
        lo, hi = (int(x) for x in part.split("-")) if "-" in part else (int(part), int(part))
        if hi < lo or hi - lo > 10 ** 7:     # (a huge range would exhaust memory)
            raise ArgumentError("poses", part, "is not a pose id or an id range a-b")
        out.extend(range(lo, hi + 1))
    return out


def repeatable_datasets(names: tuple[str, ...], data_dir: str | None, option: str = "--datasets") -> list[str]:
    """The datasets of a repeatable option that posecrb 0.1 split at commas (``tables`` and ``regress``
    ``--datasets a,b,c``): a value that is a name or a path is taken whole (a path may contain a
    comma); otherwise, when every comma-separated part is one, it is split, with a deprecation
    warning naming the repeatable form; otherwise it is a usage error saying the option repeats.
    A value without a comma is taken as it is (not found, it is reported as such)."""
    out: list[str] = []
    for value in names:
        if "," not in value or _resolves(value, data_dir):
            out.append(value)
            continue
        parts = [p.strip() for p in value.split(",")]
        if all(p and _resolves(p, data_dir) for p in parts):
            log.warning("%s %s: the comma-separated form is deprecated; repeat the option: %s", option, value,
                        " ".join(f"{option} {shlex.quote(p)}" for p in parts))
            out += parts
            continue
        raise UsageError(f"{option} {value}: no dataset or file of that name; {option} is repeatable and takes one "
                         f"name or path each ({option} A {option} B), and not every part of {value!r} is one")
    return out


def _resolves(name: str, data_dir: str | None) -> bool:
    try:
        datasets.resolve(name, data_dir)
    except PosecrbError:
        return False
    return True


def executor_settings(executor: str, jobs: int, scheduler: str | None) -> dict:
    if scheduler and executor != "dask":
        raise UsageError("--scheduler needs --executor dask")
    kind = "dask" if executor == "dask" else ("local" if jobs > 1 else "serial")
    return {"executor": kind, "jobs": jobs, "scheduler": scheduler}


def plot_target(plot_path: str | None, out_dir: str | os.PathLike | None, name: str) -> str | None:
    """Where the figure goes: ``--plot``, else NAME.png in the folder being written for ``--out DIR``
    (``posecrb.core.folders.output_folder``)."""
    if plot_path:
        return plot_path
    if not out_dir:
        return None
    return os.path.join(out_dir, f"{name}.png")



ordering_option = click.option(
    "--ordering", type=click.Choice(ORDERINGS), default="auto", show_default=True,
    help="Fill-reducing ordering of the sparse Cholesky factorizations (cost only: the numbers agree "
         "to rounding). amd: CHOLMOD's AMD. colamd: true COLAMD (the paper's Algorithm 1; CHOLMOD "
         "would apply AMD to a symmetric matrix, so COLAMD's permutation of A A^T is computed and passed "
         "in; more fill than AMD here). metis, nesdis: nested dissection of the pose graph, expanded to "
         "each pose's rows. auto: amd, but metis for the FIM/ub/CRLB of 3D graphs with >= 10000 poses "
         "and 2D graphs with >= 50000, where it needs fewer flops and was measured faster (the "
         "documentation's how-to guide 'Choose a fill-reducing ordering'). The JSON key 'ordering' "
         "says what was used.")


model_option = click.option(
    "--model", type=click.Choice(MODELS), default="paper", show_default=True,
    help="paper: Chen et al. on (R^d x SO(d))^n, isotropic noise, anchored (eq. 42/64); "
         "sed: Bertini's right-invariant model on SE(d)^n with full information matrices.")


def make_estimate_option(dest: str = "estimate_source", *, allow_none: bool = False) -> OptionDecorator:
    """``--estimate``: where the poses come from; ``allow_none`` adds ``none`` (graph-only columns)."""
    return click.option(
        "--estimate", dest, default="solve", show_default=True,
        type=InputFile(ESTIMATE_SOURCES_OR_NONE if allow_none else ESTIMATE_SOURCES),
        metavar="solve|vertices|none|FILE" if allow_none else "solve|vertices|FILE",
        help="Where the poses (at which the FIM is evaluated) come from: the certified solver (global "
             "optimum), the file's own VERTEX lines, "
             + ("another g2o/TORO FILE with the same ids, or none (graph-only columns)." if allow_none
                else "or another g2o/TORO FILE with the same ids."))


estimate_option = make_estimate_option()


def make_rotation_weight_option(default: str | None = "eq59") -> OptionDecorator:
    """``--rotation-weight``; ``default=None`` lets a command tell "not given" from eq59 (shown as the default)."""
    return click.option(
        "--rotation-weight", "rotation_weight", type=click.Choice(ROTATION_WEIGHTS), default=default,
        show_default=default is not None,
        help="Paper model, 3D rotation weight: eq. (59), or table2 = 0.5515*kappa^2, an EMPIRICAL fit "
             "reproducing the paper's printed Table II (not eq. 59)." + ("" if default else "  [default: eq59]"))


rotation_weight_option = make_rotation_weight_option()


fim_variant_option = click.option(
    "--fim-variant", "fim_variant", type=click.Choice(FIM_VARIANTS), default=None,
    help="Paper model, 3D: consistent is the Fisher information of the model the data follow "
         "(rotation coupling -w R_i^T R_j; the bound the Monte Carlo MSE reaches); eq64 is eq. (64) "
         "exactly as printed (coupling -w I), labelled fim_variant=eq64 in every output. Same matrix "
         "in 2D.  [default: consistent]")


frame_option = click.option(
    "--frame", type=click.Choice(FRAMES), default=None,
    help="sed model: coordinates of the FIM and of every per-pose number. world: the thesis' X_i -> Exp(-delta) X_i, "
         "about the world origin, rotation first (omega, v). body: GTSAM's and g2o's X_i -> X_i Exp(xi), "
         "in GTSAM's order (Pose2 x, y, theta; Pose3 rotation, translation), comparable with "
         "gtsam.Marginals / a GTSAM Hessian. Not for --model paper (its own coordinates, JSON "
         "coordinates_description).  [default: world]")


def model_settings_options(command):
    """--rotation-weight, --fim-variant, --frame (in this order): the model settings of fim and crlb."""
    for option in (frame_option, fim_variant_option, rotation_weight_option):   # click applies bottom-up
        command = option(command)
    return command
