"""Options, option types and helpers shared by subcommands."""
from __future__ import annotations

import math
import re

import click

from ..core.graph import PoseGraph
from ..core.timing import timed
from ..datasets import search as datasets
from ..io import load
from ..report.render import FORMATS

_PLAIN_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
INT64_MAX = 2 ** 63 - 1


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


class PoseId(click.ParamType):
    """A pose id as in the files: a non-negative integer that fits int64 (digits only)."""

    name = "ID"

    def convert(self, value, param, ctx):
        if isinstance(value, int) and not isinstance(value, bool):
            text = str(value)
        else:
            text = str(value).strip()
        if re.fullmatch(r"[0-9]+", text) is None or int(text) > INT64_MAX:
            self.fail(f"{value!r} is not a pose id (a non-negative integer up to 2^63-1)", param, ctx)
        return int(text)


POSE_ID = PoseId()


def format_option(choices=FORMATS, default="table"):
    return click.option("--format", "fmt", type=click.Choice(list(choices)), default=default,
                        show_default=True, help="Output format (results on stdout).")


data_dir_option = click.option(
    "--data-dir", type=click.Path(file_okay=False), default=None,
    help="Directory searched first for bare dataset names.")

anchor_option = click.option(
    "--anchor", type=POSE_ID, default=None,
    help="Pose id (as in the file) anchored to the origin; default: the smallest id.")

repeat_option = click.option(
    "--repeat", type=click.IntRange(1, 1000), default=3, show_default=True,
    help="Timing: warm-up once, then the median of K runs.")


def estimate_inputs(source: str | None) -> list[str]:
    """The input file named by an --estimate value (none for solve/vertices/none)."""
    return [] if source in (None, "", "solve", "vertices", "none") else [source]


def load_dataset(name_or_path: str, data_dir: str | None = None, repeat: int = 1) -> tuple[PoseGraph, float]:
    """Resolve a path or bare name and parse it; returns the graph and the median parse time."""
    path = datasets.resolve(name_or_path, data_dir)
    return timed(lambda: load(path), repeat=repeat)
