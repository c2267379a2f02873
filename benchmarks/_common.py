"""Shared by the benchmark scripts: the timing protocol and the dataset list."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from posecrb import datasets
from posecrb.timing import timed


def median_time(fn, repeat: int) -> float:
    """Median wall time of ``fn`` over ``repeat`` runs after one warm-up (posecrb.timing)."""
    return timed(fn, max(repeat, 2))[1]


def dataset_args(description: str, repeat: int) -> tuple[argparse.Namespace, list[Path]]:
    """Parse ``[--repeat K] [NAME ...]`` and resolve the datasets (all found when none named)."""
    logging.getLogger("posecrb").setLevel(logging.ERROR)
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("names", nargs="*")
    ap.add_argument("--repeat", type=int, default=repeat)
    args = ap.parse_args()
    files = [datasets.resolve(n) for n in args.names] if args.names else datasets.discover()
    return args, files
