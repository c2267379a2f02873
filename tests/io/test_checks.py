"""The reader's checks (posecrb/io/reader.py) against straightforward references.

Positive definiteness is screened by a Gershgorin bound before eigenvalues are computed; the
screen may only skip blocks the eigenvalue test accepts, so every block must be decided, and
reported, as the eigenvalues of every block decide it. Ids become indices by an offset when they
are consecutive and by a search otherwise; both must give the indices and the errors of a search.
"""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import ParseError
from posecrb.io import parse_text
from posecrb.io.reader import _check_positive_definite
from posecrb.io.text import fmt_number

INFO2 = "10 1 0 20 0 5"


def _reference_positive_definite(block: np.ndarray) -> str | None:
    """The reason the eigenvalues of the unit-diagonal scaling give (every block computed), or None."""
    b = block.shape[-1]
    diag = np.diagonal(block, axis1=1, axis2=2)
    pos = (diag > 0).all(axis=1)
    d = np.where(diag > 0, diag, 1.0) ** -0.5
    eig = np.linalg.eigvalsh(block * d[:, :, None] * d[:, None, :])[:, 0]
    tol = 100 * b * np.finfo(float).eps
    if pos[0] and eig[0] > tol:
        return None
    if not pos[0]:
        j = int(np.argmin(diag[0]))
        return f"(diagonal entry {j + 1} is {fmt_number(diag[0, j])})"
    return "(singular to working precision)" if eig[0] > -tol else \
        f"(smallest eigenvalue {fmt_number(eig[0])} after scaling to unit diagonal)"


def _blocks(rng: np.random.Generator, b: int) -> list[np.ndarray]:
    """Well-conditioned, nearly singular (correlations 1 - 10^-k up to and past the rounding
    tolerance), indefinite, with a zero or negative diagonal entry, and diagonals over decades."""
    out = []
    for k in range(400):
        a = rng.standard_normal((b, b))
        spd = a @ a.T + 0.1 * np.eye(b)
        scale = np.diag(10.0 ** rng.uniform(-6, 12, b) if k % 3 else 10.0 ** rng.uniform(-150, 150, b))
        kind = k % 5
        if kind == 0:
            block = scale @ spd @ scale
        elif kind == 1 and b > 1:
            v = rng.standard_normal(b)
            eps = 10.0 ** -rng.uniform(0, 17)
            block = scale @ (np.outer(v, v) + eps * np.eye(b)) @ scale
        elif kind == 2:
            block = spd - rng.uniform(0, 2) * np.linalg.eigvalsh(spd)[-1] * np.eye(b)
        elif kind == 3:
            block = spd.copy()
            block[0, 0] = -rng.uniform(0, 1) if rng.random() < 0.5 else 0.0
        else:
            c = 1 - 10.0 ** -rng.uniform(5, 7)      # around the screen's own threshold
            block = np.full((b, b), c) + (1 - c) * np.eye(b)
        out.append((block + block.T) / 2)
    return out


@pytest.mark.parametrize("b", [1, 2, 3])
def test_positive_definiteness_decided_as_every_eigenvalue_decides(b):
    rng = np.random.default_rng(b)
    lines = np.array([7])
    for block in _blocks(rng, b):
        want = _reference_positive_definite(block[None])
        try:
            _check_positive_definite("f.g2o", lines, "EDGE", (np.array([1]), np.array([2])), "rotation", block[None])
            got = None
        except ParseError as exc:
            assert exc.line == 7
            got = str(exc).split("not positive definite ")[1]
        assert got == want, block


def test_the_first_bad_block_is_reported_whatever_the_screen_skipped():
    good = np.eye(2)
    bad_late, bad_early = np.array([[1.0, 2.0], [2.0, 1.0]]), np.array([[1.0, 1.0], [1.0, 1.0]])
    blocks = np.array([good, bad_early, good, bad_late])
    with pytest.raises(ParseError, match=r"EDGE 1 2: translation block .* \(singular to working precision\)") as exc:
        _check_positive_definite("f.g2o", np.array([3, 4, 5, 6]), "EDGE", (np.arange(4) * 0 + 1, np.arange(4) * 0 + 2),
                                 "translation", blocks)
    assert exc.value.line == 4


def _graph_text(ids: list[int], edges: list[tuple[int, int]], order: list[int] | None = None) -> str:
    order = list(range(len(ids))) if order is None else order
    vertices = "".join(f"VERTEX_SE2 {ids[k]} {k} 0 0\n" for k in order)
    return vertices + "".join(f"EDGE_SE2 {i} {j} 1 0 0 {INFO2}\n" for i, j in edges)


@pytest.mark.parametrize("consecutive", [True, False])
def test_ids_become_the_indices_a_search_gives(consecutive):
    rng = np.random.default_rng(5)
    for _ in range(20):
        n = int(rng.integers(2, 40))
        ids = (np.arange(n) + int(rng.integers(0, 1000))) if consecutive else np.sort(rng.choice(10 ** 6, n, False))
        ends = rng.integers(0, n, (3 * n, 2))
        ends = ends[ends[:, 0] != ends[:, 1]]
        edges = [(int(ids[i]), int(ids[j])) for i, j in ends]
        order = [int(k) for k in rng.permutation(n)]
        g = parse_text(_graph_text(ids.tolist(), edges, order), "ids.g2o")
        np.testing.assert_array_equal(g.ids, ids)
        np.testing.assert_array_equal(g.src, np.searchsorted(ids, [i for i, _ in edges]))
        np.testing.assert_array_equal(g.dst, np.searchsorted(ids, [j for _, j in edges]))
        np.testing.assert_array_equal(g.vertex_trans[:, 0], np.arange(n))   # each vertex kept its pose
        edges_only = parse_text(_graph_text([], edges), "e.g2o")
        np.testing.assert_array_equal(edges_only.ids, np.unique(np.array(edges)))
        np.testing.assert_array_equal(edges_only.src, np.searchsorted(edges_only.ids, [i for i, _ in edges]))


@pytest.mark.parametrize("ids", [[4, 5, 6, 7], [4, 9, 10, 30]])
@pytest.mark.parametrize("unknown", [3, 8, 31, 1000])
def test_an_undeclared_end_is_reported_at_its_first_line_i_before_j(ids, unknown):
    edges = [(ids[0], ids[1]), (ids[1], unknown), (unknown, ids[2]), (ids[2], ids[3])]
    if unknown in ids:
        pytest.skip("declared")
    with pytest.raises(ParseError, match=f"EDGE_SE2: edge to undeclared vertex id {unknown}$") as exc:
        parse_text(_graph_text(ids, edges), "u.g2o")
    assert exc.value.line == len(ids) + 3          # the edge whose i is unknown comes first
    with pytest.raises(ParseError) as exc:
        parse_text(_graph_text(ids, [edges[0], edges[1], edges[3]]), "u.g2o")
    assert exc.value.line == len(ids) + 2


def test_duplicate_vertex_ids_in_or_out_of_order():
    for order in ("VERTEX_SE2 1 0 0 0\nVERTEX_SE2 2 0 0 0\nVERTEX_SE2 2 0 0 0\n",
                  "VERTEX_SE2 2 0 0 0\nVERTEX_SE2 1 0 0 0\nVERTEX_SE2 2 0 0 0\n"):
        with pytest.raises(ParseError, match="duplicate vertex id 2$") as exc:
            parse_text(order + f"EDGE_SE2 1 2 1 0 0 {INFO2}\n", "d.g2o")
        assert exc.value.line == 3
