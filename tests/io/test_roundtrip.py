"""Property test of the writers and the reader: write -> read gives back the graph, g2o and TORO.

Graphs are drawn by hypothesis (2D and 3D, ids with gaps, parallel edges, edges in both
directions, full information matrices, with or without vertices). What must survive the round
trip exactly: ids, edge order and endpoints, translations and information matrices (written with
17 significant digits, which identify a double uniquely). Rotations go through an angle (2D) or
a unit quaternion (g2o 3D) or Euler angles (TORO 3D) and come back to within a few ulps.
"""
from __future__ import annotations

import os
import tempfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from posecrb.core.graph import PoseGraph
from posecrb.io import FORMATS, load, save, write_g2o
from posecrb.lie.so import so2_exp, so3_exp

EPS = np.finfo(float).eps
MAX_ID = 2 ** 53  # largest vertex id drawn

PROPERTY = settings(derandomize=True, max_examples=40, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

_finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


def _vectors(k: int, count: int, elements=_finite) -> st.SearchStrategy[np.ndarray]:
    return st.lists(st.lists(elements, min_size=k, max_size=k), min_size=count, max_size=count).map(
        lambda rows: np.array(rows, dtype=float).reshape(count, k))


def _rotations(draw, dim: int, count: int) -> np.ndarray:
    """Rotations of every angle up to pi (the writer's angle / quaternion must cover all of SO(d))."""
    if dim == 2:
        return so2_exp(draw(_vectors(1, count, st.floats(-np.pi, np.pi)))[:, 0])
    return so3_exp(draw(_vectors(3, count, st.floats(-1.8, 1.8))))


def _information(draw, q: int, count: int) -> np.ndarray:
    """Symmetric positive definite (count, q, q) matrices L L^T with a well-conditioned L, so that
    the reader's positive-definiteness checks pass; off-diagonal terms couple translation and rotation."""
    diag = draw(_vectors(q, count, st.floats(0.5, 30.0)))
    off = draw(_vectors(q * q, count, st.floats(-1.0, 1.0))).reshape(count, q, q)
    low = np.tril(off, -1) + np.einsum("ki,ij->kij", diag, np.eye(q))
    scale = draw(st.sampled_from([1e-2, 1.0, 1e3]))
    info = scale * low @ np.swapaxes(low, 1, 2)
    return 0.5 * (info + np.swapaxes(info, 1, 2))   # exactly symmetric, as a file's matrix is


@st.composite
def pose_graphs(draw) -> PoseGraph:
    dim = draw(st.sampled_from([2, 3]))
    q = 3 if dim == 2 else 6
    n = draw(st.integers(2, 9))
    ids = np.array(sorted(draw(st.sets(st.integers(0, MAX_ID), min_size=n, max_size=n))), dtype=np.int64)
    # a spanning chain in random order (every pose appears in an edge) plus extra and parallel edges
    order = np.array(draw(st.permutations(range(n))), dtype=np.int64)
    src, dst = list(order[:-1]), list(order[1:])
    for _ in range(draw(st.integers(0, 6))):
        i, j = draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))
        if i != j:
            src.append(i)
            dst.append(j)
    if draw(st.booleans()):
        src.append(src[0])
        dst.append(dst[0])
    flip = draw(st.lists(st.booleans(), min_size=len(src), max_size=len(src)))
    src_a = np.array([d if f else s for s, d, f in zip(src, dst, flip)], dtype=np.int64)
    dst_a = np.array([s if f else d for s, d, f in zip(src, dst, flip)], dtype=np.int64)
    m = src_a.size
    with_vertices = draw(st.booleans())
    return PoseGraph(
        dim=dim, ids=ids, src=src_a, dst=dst_a, rot=_rotations(draw, dim, m), trans=draw(_vectors(dim, m)),
        info=_information(draw, q, m),
        vertex_rot=_rotations(draw, dim, n) if with_vertices else None,
        vertex_trans=draw(_vectors(dim, n)) if with_vertices else None,
        path=None, format="synthetic",
    )


def _round_trip(graph: PoseGraph, fmt: str = "g2o") -> PoseGraph:
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "graph" + FORMATS[fmt].suffixes[0])
        if fmt == "g2o":
            write_g2o(graph, path)
        else:
            save(graph, path)   # by suffix
        return load(path)


@pytest.mark.parametrize("fmt", ["g2o", "toro"])
@PROPERTY
@given(graph=pose_graphs())
def test_write_then_read_gives_back_the_graph(fmt, graph):
    back = _round_trip(graph, fmt)
    assert back.dim == graph.dim and back.format == fmt and back.skipped == {}
    np.testing.assert_array_equal(back.ids, graph.ids)
    np.testing.assert_array_equal(back.src, graph.src)
    np.testing.assert_array_equal(back.dst, graph.dst)
    np.testing.assert_array_equal(back.trans, graph.trans)   # %.17g is exact for doubles
    np.testing.assert_array_equal(back.info, graph.info)
    # rotation -> angle / unit quaternion -> rotation: a few ulps per entry (entries are <= 1)
    np.testing.assert_allclose(back.rot, graph.rot, rtol=0, atol=16 * EPS)
    assert back.has_vertices == graph.has_vertices
    if graph.has_vertices:
        np.testing.assert_array_equal(back.vertex_trans, graph.vertex_trans)
        np.testing.assert_allclose(back.vertex_rot, graph.vertex_rot, rtol=0, atol=16 * EPS)


@pytest.mark.parametrize("fmt", ["g2o", "toro"])
@PROPERTY
@given(graph=pose_graphs())
def test_second_round_trip_is_stable(fmt, graph):
    """Reading what was written and writing it again changes rotations by at most a few ulps more."""
    once = _round_trip(graph, fmt)
    twice = _round_trip(once, fmt)
    np.testing.assert_array_equal(twice.info, once.info)
    np.testing.assert_array_equal(twice.trans, once.trans)
    np.testing.assert_allclose(twice.rot, once.rot, rtol=0, atol=16 * EPS)
