"""Options and helpers shared by subcommands."""
from __future__ import annotations

import click

from .. import datasets
from ..graph import PoseGraph
from ..io import load
from ..report import FORMATS
from ..timing import timed


def format_option(choices=FORMATS, default="table"):
    return click.option("--format", "fmt", type=click.Choice(list(choices)), default=default,
                        show_default=True, help="Output format (results on stdout).")


data_dir_option = click.option(
    "--data-dir", type=click.Path(file_okay=False), default=None,
    help="Directory searched first for bare dataset names.")

anchor_option = click.option(
    "--anchor", type=int, default=None,
    help="Pose id (as in the file) anchored to the origin; default: the smallest id.")

repeat_option = click.option(
    "--repeat", type=click.IntRange(1, 1000), default=3, show_default=True,
    help="Timing: warm-up once, then the median of K runs.")


def load_dataset(name_or_path: str, data_dir: str | None = None, repeat: int = 1) -> tuple[PoseGraph, float]:
    """Resolve a path or bare name and parse it; returns the graph and the median parse time."""
    path = datasets.resolve(name_or_path, data_dir)
    return timed(lambda: load(path), repeat=repeat)
