"""Plot the information timeline of a pose graph with the library (posecrb.incremental).

Usage: python examples/timeline_plot.py [FILE_OR_DATASET] [OUT.png]

Without an argument: intel from $POSECRB_DATA when it is there, otherwise a noisy synthetic 2D grid
of 400 poses. Writes the figure of ``posecrb timeline --plot`` (lb-ub band raw and per dimension,
the gain of every step's loop closures) and prints the five loop closures with the largest gains
and where the per-dimension lower bound fell the most.
"""
from __future__ import annotations

import sys

from posecrb import load
from posecrb.core.errors import DatasetNotFound
from posecrb.datasets.search import resolve
from posecrb.incremental import timeline
from posecrb.report.plots import plot_timeline
from posecrb.sim.generators import grid


def main(argv: list[str]) -> int:
    source = argv[1] if len(argv) > 1 else "intel"
    out = argv[2] if len(argv) > 2 else "timeline.png"
    try:
        graph = load(resolve(source))
    except DatasetNotFound:
        if len(argv) > 1:
            raise
        graph = grid(2, 20, noise=True, rng=0)          # no dataset at hand: a noisy 20 x 20 grid
    res = timeline(graph, estimate="none")               # graph only: no solve needed
    top = res.closures_frame().nlargest(5, "gain")
    for row in top.itertuples():
        older = row.source if row.target == row.pose else row.target
        print(f"{row.poses:6d} poses: pose {row.pose} closes to pose {older}, gain {row.gain:.2f}")
    drop = res.monotonicity["lb"]["per_dimension"].largest
    if drop is not None:
        print(f"largest fall of lb per dimension: {drop['change']:.3g} at {drop['poses']} poses")
    print(f"wrote {plot_timeline(res, out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
