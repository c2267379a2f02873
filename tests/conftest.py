"""Shared fixtures: the real datasets ($POSECRB_DATA) and small random pose graphs."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from posecrb.core.graph import PoseGraph
from posecrb.lie.so import so2_exp, so3_exp


@pytest.fixture(scope="session")
def shared_datasets() -> Path:
    """The first directory of $POSECRB_DATA: the real datasets (see README, Setup); skip without it."""
    first = os.environ.get("POSECRB_DATA", "").split(os.pathsep)[0]
    if not first or not Path(first).is_dir():
        pytest.skip("real-data tests need $POSECRB_DATA pointing at the datasets directory")
    return Path(first)


def random_rotations(rng: np.random.Generator, k: int, dim: int) -> np.ndarray:
    if dim == 2:
        return so2_exp(rng.uniform(-np.pi, np.pi, k))
    return so3_exp(rng.normal(size=(k, 3)))


def random_spd(rng: np.random.Generator, k: int, q: int, scale: float = 10.0) -> np.ndarray:
    a = rng.normal(size=(k, q, q))
    return scale * (a @ a.transpose(0, 2, 1) / q + 0.5 * np.eye(q))


def make_random_graph(rng: np.random.Generator, n: int = 8, extra: int = 6, dim: int = 2,
                      parallel: int = 2, sparse_ids: bool = True, block_isotropic: bool = False) -> PoseGraph:
    """A connected random graph: a random spanning tree + random extra edges + parallel copies,
    anisotropic information (unless block_isotropic), ids with gaps, vertices attached."""
    src = [int(rng.integers(0, k)) for k in range(1, n)]
    dst = list(range(1, n))
    for _ in range(extra):
        i, j = rng.choice(n, 2, replace=False)
        src.append(int(i))
        dst.append(int(j))
    for _ in range(parallel):
        k = int(rng.integers(0, len(src)))
        src.append(src[k])
        dst.append(dst[k])
    src, dst = np.array(src), np.array(dst)
    m, q = src.size, dim + (1 if dim == 2 else 3)
    info = random_spd(rng, m, q)
    if block_isotropic:
        info[:, :dim, dim:] = 0
        info[:, dim:, :dim] = 0
    ids = np.sort(rng.choice(10 * n, n, replace=False)) if sparse_ids else np.arange(n)
    return PoseGraph(
        dim=dim, ids=ids, src=src, dst=dst, rot=random_rotations(rng, m, dim),
        trans=rng.normal(size=(m, dim)) * 2.0, info=info,
        vertex_rot=random_rotations(rng, n, dim), vertex_trans=rng.normal(size=(n, dim)) * 3.0,
        path=None, format="synthetic",
    )


@pytest.fixture
def random_graph():
    return make_random_graph
