"""Noisy 2D/3D grid pose graphs (and 2D chains) for the scaling benchmarks, written as g2o files and cached.

A grid of N poses is the full lattice of side ceil(N^(1/d)) (so 10^5 2D poses -> 317^2 = 100,489,
2*10^4 3D poses -> 28^3 = 21,952) walked in boustrophedon order with a loop closure between every
pair of lattice neighbours (posecrb.sim.generators.grid), measurements perturbed by the paper's noise model
with translation std SIGMA and rotation angle std SIGMA (tau = 1/SIGMA^2, kappa = 1/(2 SIGMA^2),
as `posecrb datasets synth --noise SIGMA`), noise drawn from numpy.random.default_rng(SEED).
``--exact`` keeps the pose count as given (the walk is truncated). ``chain_file`` (``--chain``): a 2D
chain of N poses, odometry only (unit steps, heading a random walk of 0.1 rad steps), with the same
noise model: the longest sums of the timeline for its size.

Files go to $POSECRB_BENCH_CACHE or ~/.cache/posecrb-bench (written to a temporary name and
renamed by posecrb's g2o writer) and are reused when present.

Usage: python benchmarks/grids.py DIM POSES [--sigma 0.05] [--seed 0] [--exact | --chain] [--cache-dir DIR]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from _common import REPO  # noqa: F401  (puts this checkout first on sys.path)

DEFAULT_SIGMA = 0.05


def cache_dir(arg: str | os.PathLike | None = None) -> Path:
    if arg:
        return Path(arg)
    env = os.environ.get("POSECRB_BENCH_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "posecrb-bench"


def lattice_side(poses: int, dim: int) -> int:
    """Smallest s with s^dim >= poses (integer arithmetic)."""
    s = max(2, round(poses ** (1.0 / dim)))
    while s ** dim < poses:
        s += 1
    while s > 2 and (s - 1) ** dim >= poses:
        s -= 1
    return s


def grid_poses(dim: int, poses: int, exact: bool = False) -> int:
    return poses if exact else lattice_side(poses, dim) ** dim


def grid_file(dim: int, poses: int, sigma: float = DEFAULT_SIGMA, seed: int = 0, exact: bool = False,
              directory: str | os.PathLike | None = None) -> Path:
    """Path of the cached g2o file of this grid, generated first when absent."""
    side = lattice_side(poses, dim)
    n = poses if exact else side ** dim
    out_dir = cache_dir(directory)
    path = out_dir / f"grid{dim}d_n{n}_sigma{sigma:g}_seed{seed}.g2o"
    if path.is_file():
        return path
    import numpy as np

    from posecrb.io import write_g2o
    from posecrb.sim.generators import grid

    out_dir.mkdir(parents=True, exist_ok=True)
    graph = grid(dim, side, poses=n, tau=1.0 / sigma ** 2, kappa=1.0 / (2.0 * sigma ** 2), noise=True,
                 rng=np.random.default_rng(seed))
    write_g2o(graph, path)
    return path


def chain_file(poses: int, sigma: float = DEFAULT_SIGMA, seed: int = 0,
               directory: str | os.PathLike | None = None) -> Path:
    """Path of the cached g2o file of a noisy 2D chain of ``poses`` poses, generated first when absent."""
    out_dir = cache_dir(directory)
    path = out_dir / f"chain2d_n{poses}_sigma{sigma:g}_seed{seed}.g2o"
    if path.is_file():
        return path
    import numpy as np

    from posecrb.core.graph import PoseGraph
    from posecrb.core.noise import isotropic_information
    from posecrb.io import write_g2o
    from posecrb.lie.se import relative_poses
    from posecrb.lie.so import so2_exp
    from posecrb.sim.sampling import isotropic_noise

    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    yaw = np.cumsum(rng.normal(0.0, 0.1, poses))
    trans = np.cumsum(np.stack([np.cos(yaw), np.sin(yaw)], axis=1), axis=0)
    src, dst = np.arange(poses - 1), np.arange(1, poses)
    tau = np.full(poses - 1, 1.0 / sigma ** 2)
    rot, rel = relative_poses(so2_exp(yaw), trans, src, dst)
    rot, rel = isotropic_noise(rot, rel, tau, tau / 2.0, 2, rng)
    graph = PoseGraph(dim=2, ids=np.arange(poses), src=src, dst=dst, rot=rot, trans=rel,
                      info=isotropic_information(tau, tau / 2.0, 2), vertex_rot=so2_exp(yaw), vertex_trans=trans,
                      format="synthetic")
    write_g2o(graph, path)
    return path


def count_edges(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(1 for line in fh if line.startswith(b"EDGE"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dim", type=int, choices=(2, 3))
    ap.add_argument("poses", type=int)
    ap.add_argument("--sigma", type=float, default=DEFAULT_SIGMA)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--exact", action="store_true", help="exactly POSES poses (truncated walk)")
    ap.add_argument("--chain", action="store_true", help="a 2D chain of POSES poses instead (DIM must be 2)")
    ap.add_argument("--cache-dir", default=None)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.chain:
        if args.dim != 2:
            ap.error("--chain makes 2D chains")
        path = chain_file(args.poses, args.sigma, args.seed, args.cache_dir)
    else:
        path = grid_file(args.dim, args.poses, args.sigma, args.seed, args.exact, args.cache_dir)
    n = args.poses if args.chain else grid_poses(args.dim, args.poses, args.exact)
    print(f"{path}  ({n} poses, {count_edges(path)} edges, "
          f"{path.stat().st_size / 2**20:.1f} MiB; {time.perf_counter() - t0:.2f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main() if len(sys.argv) > 1 else main(["2", "100"]))
