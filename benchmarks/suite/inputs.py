"""The inputs of every benchmark: the SE-Sync datasets and noisy grids, at two sizes of suite.

The size comes from ``$POSECRB_BENCH`` (``quick`` or ``full``, default ``full``): ``make
bench-quick`` runs every benchmark once on small inputs (a broken benchmark fails CI), ``make
bench`` the whole suite.

Datasets are g2o files of SE-Sync's benchmark suite in the data directory (the first entry of
``$POSECRB_DATA``); a benchmark whose dataset is absent is skipped (asv shows it as n/a).

Grids are made by posecrb's own public generator, ``posecrb datasets synth grid2d|grid3d``: the
full lattice of side ceil(N^(1/d)) (so 10^5 2D poses -> 317^2 = 100,489), a loop closure between
every pair of lattice neighbours, measurement noise of std 0.05 in translation and rotation angle
(tau = 400, kappa = 200), seed 0. They are written once to ``$POSECRB_BENCH_CACHE`` (default
``~/.cache/posecrb-bench``) and reused. ``python benchmarks/suite/inputs.py grid3d-20000`` prints
the path of one (generating it first).

Chains (``chain2d-N``): a 2D odometry chain of N poses, unit steps with the heading a random walk of
0.1 rad steps, the same noise model (std 0.05, seed 0): the longest sums the timeline's drift check
compares for its size (the timeline of 2,000,000 poses against one ``bounds`` of the same file).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

SIGMA = 0.05
SEED = 0

# The 16 g2o files of the SE-Sync benchmark suite, 2D then 3D, each group by size.
SESYNC_DATASETS = ("CSAIL", "MIT", "intel", "kitti_05", "manhattan", "kitti_02", "kitti_00", "city10000",
                   "ais2klinik", "tinyGrid3D", "smallGrid3D", "parking-garage", "sphere2500",
                   "sphere_bignoise_vertex3", "torus3D", "cubicle")
# Files without VERTEX lines (the commands at the file's vertices do not apply).
EDGES_ONLY = frozenset({"CSAIL", "manhattan", "kitti_00", "kitti_02", "kitti_05"})

_GRID = re.compile(r"^grid([23])d-(\d+)$")
_CHAIN = re.compile(r"^chain2d-(\d+)$")


def size() -> str:
    """``quick`` or ``full`` (``$POSECRB_BENCH``)."""
    value = os.environ.get("POSECRB_BENCH", "full")
    if value not in ("quick", "full"):
        raise ValueError(f"POSECRB_BENCH={value!r}: choose quick or full")
    return value


QUICK = size() == "quick"

# Scaling grids: 2D 10^3 .. 10^5 poses, 3D 10^3 .. 2*10^4 (full); one small grid each (quick).
GRID_2D_SMALL, GRID_3D_SMALL = "grid2d-400", "grid3d-125"
GRIDS_2D = (GRID_2D_SMALL,) if QUICK else ("grid2d-1000", "grid2d-10000", "grid2d-30000", "grid2d-100000")
GRIDS_3D = (GRID_3D_SMALL,) if QUICK else ("grid3d-1000", "grid3d-5000", "grid3d-20000")
GRIDS = GRIDS_2D + GRIDS_3D
DATASETS = ("intel",) if QUICK else SESYNC_DATASETS
WITH_VERTICES = tuple(name for name in DATASETS if name not in EDGES_ONLY)


def lattice_side(poses: int, dim: int) -> int:
    """Smallest s with s^dim >= poses (integer arithmetic)."""
    side = max(2, round(poses ** (1.0 / dim)))
    while side ** dim < poses:
        side += 1
    while side > 2 and (side - 1) ** dim >= poses:
        side -= 1
    return side


def grid_spec(name: str) -> tuple[int, int] | None:
    """(dim, poses of the full lattice) of a grid's name such as ``grid2d-100000``, else None."""
    match = _GRID.match(name)
    if not match:
        return None
    dim, requested = int(match.group(1)), int(match.group(2))
    return dim, lattice_side(requested, dim) ** dim


def cache_dir() -> Path:
    env = os.environ.get("POSECRB_BENCH_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "posecrb-bench"


def data_dir() -> Path | None:
    """The first entry of ``$POSECRB_DATA``, when it is a directory."""
    first = os.environ.get("POSECRB_DATA", "").split(os.pathsep)[0]
    return Path(first) if first and Path(first).is_dir() else None


def posecrb_argv() -> list[str]:
    """The command that runs this interpreter's posecrb (no console-script shim in front)."""
    return [sys.executable, "-m", "posecrb"]


def posecrb_env() -> dict[str, str]:
    """This process's environment with the directory of the posecrb it imports first on
    PYTHONPATH, so that a child process runs the same posecrb (asv drops PYTHONPATH)."""
    import posecrb

    home = str(Path(posecrb.__file__).resolve().parents[1])
    rest = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p and p != home]
    return {**os.environ, "PYTHONPATH": os.pathsep.join([home, *rest])}


def grid_file(dim: int, poses: int) -> Path:
    """The cached g2o file of the noisy grid of ``poses`` poses (a full lattice), made first when absent."""
    path = cache_dir() / f"grid{dim}d_n{poses}_sigma{SIGMA:g}_seed{SEED}.g2o"
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([*posecrb_argv(), "-q", "datasets", "synth", f"grid{dim}d", "--poses", str(poses),
                        "--noise", str(SIGMA), "--seed", str(SEED), "--out", str(path)],
                       check=True, stdout=subprocess.DEVNULL, env=posecrb_env())
    return path


def chain_file(poses: int) -> Path:
    """The cached g2o file of the noisy 2D chain of ``poses`` poses (module docstring), made first when
    absent: measurements drawn with numpy alone (translation N(0, SIGMA^2), angle N(0, SIGMA^2)), the
    information ``diag(1/SIGMA^2, 1/SIGMA^2, 1/SIGMA^2)`` written with every edge."""
    import numpy as np

    path = cache_dir() / f"chain2d_n{poses}_sigma{SIGMA:g}_seed{SEED}.g2o"
    if path.is_file():
        return path
    rng = np.random.default_rng(SEED)
    turn = rng.normal(0.0, 0.1, poses - 1)
    dx = 1.0 + rng.normal(0.0, SIGMA, poses - 1)
    dy = rng.normal(0.0, SIGMA, poses - 1)
    dth = turn + rng.normal(0.0, SIGMA, poses - 1)
    info = 1.0 / SIGMA ** 2
    ids = np.arange(poses - 1)
    rows = np.column_stack([ids, ids + 1, dx, dy, dth])
    text = "\n".join(f"EDGE_SE2 {int(a)} {int(b)} {x:.17g} {y:.17g} {t:.17g} {info:g} 0 0 {info:g} 0 {info:g}"
                     for a, b, x, y, t in rows.tolist())
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text + "\n")
    tmp.replace(path)
    return path


def path(name: str) -> Path:
    """The file of an input: a grid or a chain (generated when absent) or a dataset of the data directory.

    Raises ``NotImplementedError`` (asv's "skip this benchmark") for a dataset that is not there."""
    spec = grid_spec(name)
    if spec is not None:
        return grid_file(*spec)
    chain = _CHAIN.match(name)
    if chain is not None:
        return chain_file(int(chain.group(1)))
    directory = data_dir()
    if directory is None:
        raise NotImplementedError(f"{name}: no data directory (set POSECRB_DATA)")
    file = directory / f"{name}.g2o"
    if not file.is_file():
        raise NotImplementedError(f"{name}: not in {directory}")
    return file


def dimension(name: str) -> int:
    """2 or 3: a grid's from its name, a dataset's from its first EDGE line."""
    spec = grid_spec(name)
    if spec is not None:
        return spec[0]
    if _CHAIN.match(name):
        return 2
    with open(path(name), "rb") as fh:
        for line in fh:
            if line.startswith(b"EDGE_SE3") or line.startswith(b"VERTEX_SE3"):
                return 3
            if line.startswith(b"EDGE_SE2") or line.startswith(b"VERTEX_SE2"):
                return 2
    raise ValueError(f"{name}: no SE2/SE3 line")


def poses(name: str) -> int | None:
    """The number of poses of a grid (None for a dataset)."""
    spec = grid_spec(name)
    return None if spec is None else spec[1]


def main(argv: list[str]) -> int:
    for name in argv or ["grid2d-1000"]:
        print(path(name))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
