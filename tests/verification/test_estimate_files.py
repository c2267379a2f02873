"""Estimate files of every format read back the poses they were written from, to their digits;
bad files are ParseErrors naming file and line."""
from __future__ import annotations

import gzip

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posecrb.core.errors import ParseError
from posecrb.io import write_g2o
from posecrb.io.estimates import read_estimate_file
from posecrb.sim.random_graphs import random_graph

RNG_SEED = 7


def _graph(dim: int, n: int = 12):
    g = random_graph(np.random.default_rng(RNG_SEED + dim), n, n + 6, dim, id_gaps=True, scale=5.0)
    return g


def _quat_xyzw(rot: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(rot).as_quat()          # scipy: (x, y, z, w), an independent conversion


def _write(path, rows, header: str | None = None) -> str:
    text = ("" if header is None else header + "\n") + "\n".join(rows) + "\n"
    path.write_text(text)
    return str(path)


def _planar3(g):
    rot3 = np.zeros((g.n, 3, 3))
    rot3[:, :2, :2] = g.vertex_rot
    rot3[:, 2, 2] = 1.0
    return rot3, np.column_stack([g.vertex_trans, np.zeros(g.n)])


def _rows(g, fmt: str, digits: int = 17):
    f = f"%.{digits}g"
    if g.dim == 2 and fmt in ("tum", "kitti", "ceres3"):
        rot, trans = _planar3(g)
    else:
        rot, trans = g.vertex_rot, g.vertex_trans
    out = []
    for k in range(g.n):
        t = " ".join(f % x for x in trans[k])
        if fmt == "ceres2":
            out.append(f"{g.ids[k]} {t} {f % np.arctan2(rot[k][1, 0], rot[k][0, 0])}")
        elif fmt in ("ceres3", "tum"):
            q = " ".join(f % x for x in _quat_xyzw(rot[k]))
            key = str(g.ids[k]) if fmt == "ceres3" else "%.6f" % (1.6e9 + 0.1 * k)
            out.append(f"{key} {t} {q}")
        else:
            m = np.hstack([rot[k], trans[k][:, None]])
            out.append(" ".join(f % x for x in m.ravel()))
    return out


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("fmt", ["g2o", "ceres", "tum", "kitti"])
def test_every_format_reads_back_its_poses(tmp_path, dim, fmt):
    g = _graph(dim)
    if fmt == "g2o":
        path = str(tmp_path / "e.g2o")
        write_g2o(g, path)
    else:
        kind = {"ceres": f"ceres{dim}", "tum": "tum", "kitti": "kitti"}[fmt]
        path = _write(tmp_path / "e.txt", _rows(g, kind), "# timestamp tx ty tz qx qy qz qw" if fmt == "tum" else None)
    f = read_estimate_file(path)
    poses = f.poses_for(g)
    assert poses.format == fmt
    # 17 significant digits identify a double; the rotation conversions add a few ulps
    np.testing.assert_allclose(poses.trans, g.vertex_trans, rtol=0, atol=1e-12 * np.abs(g.vertex_trans).max())
    np.testing.assert_allclose(poses.rot, g.vertex_rot, rtol=0, atol=1e-14)


@pytest.mark.parametrize("fmt", ["tum", "kitti", "ceres3"])
def test_six_digits_are_projected_within_their_rounding(tmp_path, fmt, caplog):
    """GTSAM's writer prints 6 significant digits: rotations off by their rounding are projected."""
    g = _graph(3)
    path = _write(tmp_path / "e.txt", _rows(g, fmt, digits=6))
    poses = read_estimate_file(path).poses_for(g)
    assert np.abs(poses.rot @ np.swapaxes(poses.rot, 1, 2) - np.eye(3)).max() < 1e-14
    np.testing.assert_allclose(poses.rot, g.vertex_rot, atol=2e-5)
    np.testing.assert_allclose(poses.trans, g.vertex_trans, rtol=1e-5)


def test_tum_rows_follow_the_ids_or_the_timestamps(tmp_path):
    g = _graph(3)
    rows = _rows(g, "tum")
    f = read_estimate_file(_write(tmp_path / "t.txt", rows))
    assert f.format == "tum"
    with pytest.raises(ParseError, match="t.txt.*not an integer pose id"):
        f.poses_for(g, rows="timestamps")
    # integral timestamps that are the ids, in scrambled order: by timestamp they match
    by_id = [f"{g.ids[k]}.0 " + r.split(" ", 1)[1] for k, r in enumerate(rows)][::-1]
    f2 = read_estimate_file(_write(tmp_path / "t2.txt", by_id), format="tum")
    np.testing.assert_allclose(f2.poses_for(g, rows="timestamps").trans, g.vertex_trans, atol=1e-9)


def test_integer_first_column_is_ids_only_when_it_is_the_graphs(tmp_path):
    g = _graph(3)
    rows = _rows(g, "ceres3")
    f = read_estimate_file(_write(tmp_path / "c.txt", rows))
    assert f.poses_for(g).format == "ceres"
    # the same rows keyed 0..n-1 while the graph's ids have gaps: TUM timestamps in row order
    renum = [f"{k} " + r.split(" ", 1)[1] for k, r in enumerate(rows)]
    assert read_estimate_file(_write(tmp_path / "c2.txt", renum)).poses_for(g).format == "tum"


def test_a_graph_file_is_its_own_estimate_and_vertex_only_files_read(tmp_path):
    g = _graph(2)
    path = tmp_path / "g.g2o"
    write_g2o(g, str(path))
    vertices = [ln for ln in path.read_text().splitlines() if ln.startswith("VERTEX")]
    only = _write(tmp_path / "v.g2o", vertices)
    for p in (str(path), only):
        np.testing.assert_array_equal(read_estimate_file(p).poses_for(g).trans, g.vertex_trans)
    gz = tmp_path / "v.g2o.gz"
    gz.write_bytes(gzip.compress((tmp_path / "v.g2o").read_bytes()))
    assert read_estimate_file(str(gz)).rows == g.n


@pytest.mark.parametrize("case, text, where", [
    ("empty", "", "is empty"),
    ("comments only", "# nothing\n", "is empty"),
    ("ragged", "0 1 2 3\n1 1 2\n", ":2: has 3 fields"),
    ("wrong width", "0 1 2 3 4\n", ":1: 5 fields per line"),
    ("nan", "0 1 2 nan\n", ":1: pose: 'nan' is not a number"),
    ("overflow", "0 1 2 1e999\n", ":1: pose: non-finite value"),
    ("not a number", "0 1 x 3\n", ":1: pose: 'x' is not a number"),
    ("bad id", "-1 1 2 3\n", ":1: Ceres 2D line: pose id '-1'"),
    ("duplicate id", "0 1 2 3\n0 1 2 3\n", ":2: pose id 0 appears twice"),
    ("zero quaternion", "0 1 2 3 0 0 0 0\n", ":1: zero quaternion"),
    ("long quaternion", "0 1 2 3 0 0 0 2.0\n", ":1: quaternion of norm 2"),
    ("reflection", "1 0 0 0 0 1 0 0 0 0 -1 0\n", ":1: the 3x3 block is a reflection (determinant -1)"),
    ("scaled matrix", "2.0 0 0 0 0 2.0 0 0 0 0 2.0 0\n", ":1: the 3x3 block is not a rotation: max |R^T R - I| = 3"),
    ("unknown tag", "VERTEX_SE2 0 0 0 0\nFOO 1 2\n", ":2: unknown record 'FOO'"),
    ("mixed", "VERTEX_SE2 0 0 0 0\n1 2 3 4\n", ":2: a numeric line"),
    ("mixed dims", "VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n", ":2: mixes vertex records"),
    ("edges only", "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n", "has no VERTEX lines"),
    ("short vertex", "VERTEX_SE2 0 0 0\n", ":1: VERTEX_SE2 needs 4 numeric fields, found 3"),
])
def test_bad_files_name_file_and_line(tmp_path, case, text, where):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(ParseError) as info:
        read_estimate_file(str(path))
    assert str(path) in str(info.value) and where in str(info.value), (case, str(info.value))


def test_matching_errors(tmp_path):
    g = _graph(3)
    rows = _rows(g, "ceres3")
    with pytest.raises(ParseError, match="lacks 1 pose"):
        read_estimate_file(_write(tmp_path / "a.txt", rows[:-1]), format="ceres").poses_for(g)
    extra = rows + [f"{g.ids.max() + 5} 0 0 0 0 0 0 1"]
    with pytest.raises(ParseError, match=f"a.txt:{g.n + 1}: has 1 pose.*id {g.ids.max() + 5}"):
        read_estimate_file(_write(tmp_path / "a.txt", extra), format="ceres").poses_for(g)
    tum = _rows(g, "tum")
    with pytest.raises(ParseError, match=f"has {g.n - 1} TUM row.*{g.n} poses"):
        read_estimate_file(_write(tmp_path / "t.txt", tum[:-1])).poses_for(g)
    g2 = _graph(2)
    with pytest.raises(ParseError, match="2D poses; the graph is 3D"):
        read_estimate_file(_write(tmp_path / "c2.txt", _rows(g2, "ceres2"))).poses_for(g)


def test_a_2d_graph_takes_planar_rows_only(tmp_path):
    g = _graph(2)
    rows = _rows(g, "kitti")
    np.testing.assert_allclose(read_estimate_file(_write(tmp_path / "k.txt", rows)).poses_for(g).rot,
                               g.vertex_rot, atol=1e-14)
    tilt = np.hstack([Rotation.from_rotvec([0.1, 0, 0.2]).as_matrix(), np.zeros((3, 1))])
    tilted = rows[:3] + [" ".join(f"{x:.17g}" for x in tilt.ravel())] + rows[4:]
    with pytest.raises(ParseError, match="k2.txt:4: a 3D pose"):
        read_estimate_file(_write(tmp_path / "k2.txt", tilted)).poses_for(g)


def test_forcing_a_format(tmp_path):
    g = _graph(3)
    path = _write(tmp_path / "k.txt", _rows(g, "kitti"))
    with pytest.raises(ParseError, match="holds KITTI lines, not tum"):
        read_estimate_file(path, format="tum")
    ceres = _write(tmp_path / "c.txt", _rows(g, "ceres3"))
    assert read_estimate_file(ceres, format="tum").format == "tum"
