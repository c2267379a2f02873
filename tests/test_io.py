"""Readers: content sniffing, id remapping, skipped tags, and a corpus of malformed files."""
import numpy as np
import pytest

from posecrb import load
from posecrb.cli import main
from posecrb.errors import ParseError
from posecrb.io import parse_text, write_g2o

INFO2 = "10 1 0 20 0 5"            # g2o upper triangle: I11 I12 I13 I22 I23 I33
INFO3 = " ".join(["100 0 0 0 0 0", "100 0 0 0 0", "100 0 0 0", "50 0 0", "50 0", "50"])


def test_g2o_2d_ids_remapped_in_increasing_order_and_vertices_follow():
    text = f"""VERTEX_SE2 30 3 0 0.3
VERTEX_SE2 10 1 0 0.1

VERTEX_SE2 20 2 0 0.2
EDGE_SE2 10 20 1 0 0.1 {INFO2}
EDGE_SE2 20 30 1 0 0.1 {INFO2}
EDGE_SE2 30 10 -2 0 -0.2 {INFO2}
"""
    g = parse_text(text, "mem.g2o")
    assert (g.ids == [10, 20, 30]).all() and g.dim == 2 and g.m == 3
    assert (g.src == [0, 1, 2]).all() and (g.dst == [1, 2, 0]).all()
    np.testing.assert_allclose(g.vertex_trans[:, 0], [1, 2, 3])
    np.testing.assert_allclose(np.arctan2(g.vertex_rot[:, 1, 0], g.vertex_rot[:, 0, 0]), [0.1, 0.2, 0.3])
    np.testing.assert_allclose(g.info[0], [[10, 1, 0], [1, 20, 0], [0, 0, 5]])
    assert list(g.edge_lines) == [5, 6, 7]


def test_edges_only_file_uses_ids_the_edges_mention():
    g = parse_text(f"EDGE_SE2 5 9 1 0 0 {INFO2}\nEDGE_SE2 9 12 1 0 0 {INFO2}\n", "e.g2o")
    assert list(g.ids) == [5, 9, 12] and not g.has_vertices


def test_skipped_tags_are_counted(caplog):
    text = f"# comment\nFIX 0\nEQUIV 0 1\nEDGE_SE2 0 1 1 0 0 {INFO2}\nVERTEX_XY 7 1 2\n"
    with caplog.at_level("WARNING", logger="posecrb"):
        g = parse_text(text, "s.g2o")
    assert g.skipped == {"#": 1, "FIX": 1, "EQUIV": 1, "VERTEX_XY": 1}
    assert sum("skipped" in r.getMessage() for r in caplog.records) == 1


def test_toro_edge2_information_order():
    # TORO: I11 I12 I22 I33 I13 I23 ; g2o: I11 I12 I13 I22 I23 I33
    toro = parse_text("EDGE2 0 1 1 2 0.5 11 12 22 33 13 23\n", "t.graph")
    g2o = parse_text("EDGE_SE2 0 1 1 2 0.5 11 12 13 22 23 33\n", "t.g2o")
    np.testing.assert_array_equal(toro.info, g2o.info)
    assert toro.format == "toro" and g2o.format == "g2o"


def test_toro_edge3_euler_convention():
    roll, pitch, yaw = 0.1, -0.2, 0.3
    g = parse_text(f"EDGE3 0 1 1 2 3 {roll} {pitch} {yaw} {INFO3}\n", "t.graph")
    c, s = np.cos, np.sin
    rx = np.array([[1, 0, 0], [0, c(roll), -s(roll)], [0, s(roll), c(roll)]])
    ry = np.array([[c(pitch), 0, s(pitch)], [0, 1, 0], [-s(pitch), 0, c(pitch)]])
    rz = np.array([[c(yaw), -s(yaw), 0], [s(yaw), c(yaw), 0], [0, 0, 1]])
    np.testing.assert_allclose(g.rot[0], rz @ ry @ rx, atol=1e-14)


def test_g2o_quaternion_is_normalised():
    g = parse_text(f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 2 2 {INFO3}\n", "q.g2o")  # unnormalised (0,0,1,1)
    np.testing.assert_allclose(g.rot[0], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_write_then_load_round_trip(tmp_path, random_graph, dim):
    g = random_graph(np.random.default_rng(4), n=7, dim=dim)
    f = tmp_path / "rt.g2o"
    write_g2o(g, f)
    h = load(f)
    assert (h.ids == g.ids).all() and (h.src == g.src).all() and (h.dst == g.dst).all()
    np.testing.assert_allclose(h.rot, g.rot, atol=1e-12)
    np.testing.assert_allclose(h.trans, g.trans, atol=1e-12)
    np.testing.assert_allclose(h.info, g.info, rtol=1e-12)
    np.testing.assert_allclose(h.vertex_rot, g.vertex_rot, atol=1e-12)


E = f"EDGE_SE2 0 1 1 0 0 {INFO2}"
MALFORMED = {
    "field_count": (f"{E}\nEDGE_SE2 1 2 1 0 0 10 1 0 20 0\n", 2, "needs 11 numeric fields"),
    "non_numeric": (f"{E}\nEDGE_SE2 1 2 1 abc 0 {INFO2}\n", 2, "not a number"),
    "nan": (f"{E}\nEDGE_SE2 1 2 1 nan 0 {INFO2}\n", 2, "non-finite"),
    "inf": (f"EDGE_SE2 1 2 1 0 inf {INFO2}\n", 1, "non-finite"),
    "not_pd": (f"{E}\n{E}\nEDGE_SE2 1 2 1 0 0 -1 0 0 20 0 5\n", 3, "not positive definite"),
    "rot_not_pd": ("EDGE_SE2 1 2 1 0 0 10 1 0 20 0 0\n", 1, "rotation block"),
    "unknown_vertex": (f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\n{E}\nEDGE_SE2 1 7 1 0 0 {INFO2}\n", 4,
                       "undeclared vertex id 7"),
    "self_loop": (f"{E}\nEDGE_SE2 3 3 1 0 0 {INFO2}\n", 2, "self-loop"),
    "duplicate_vertex": ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nVERTEX_SE2 0 1 1 1\n" + E + "\n", 3,
                         "duplicate vertex id 0"),
    "mixed_dims": (f"{E}\nEDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 {INFO3}\n", 2, "mixed 2D and 3D"),
    "mixed_formats": (f"{E}\nEDGE2 0 1 1 0 0 1 0 1 1 0 0\n", 2, "mixed g2o and TORO"),
    "unknown_tag": (f"{E}\nFOO 1 2 3\n", 2, "unknown record type 'FOO'"),
    "zero_quaternion": (f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 0 {INFO3}\n", 1, "zero quaternion"),
    "negative_id": (f"EDGE_SE2 -1 2 1 0 0 {INFO2}\n", 1, "non-negative integer id"),
    "fractional_id": (f"EDGE_SE2 1.5 2 1 0 0 {INFO2}\n", 1, "non-negative integer id"),
    "empty": ("", None, "no pose-graph edges"),
    "only_vertices": ("VERTEX_SE2 0 0 0 0\n", None, "no pose-graph edges"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_give_file_line_and_reason(tmp_path, case):
    text, line, reason = MALFORMED[case]
    f = tmp_path / f"{case}.g2o"
    f.write_text(text)
    with pytest.raises(ParseError) as exc:
        load(f)
    assert exc.value.line == line
    assert reason in str(exc.value)
    expected = f"{f}:{line}" if line else str(f)
    assert expected in str(exc.value)


def test_binary_file_is_a_parse_error(tmp_path):
    f = tmp_path / "bin.g2o"
    f.write_bytes(b"EDGE_SE2 0 1\n\xff\xfe\x00")
    with pytest.raises(ParseError, match="not a text file"):
        load(f)


@pytest.mark.parametrize("case", ["field_count", "not_pd", "self_loop", "empty", "mixed_dims"])
@pytest.mark.parametrize("command", ["info", "bounds"])
def test_cli_exit_code_one_without_traceback(tmp_path, capfd, case, command):
    text, line, _ = MALFORMED[case]
    f = tmp_path / f"{case}.g2o"
    f.write_text(text)
    rc = main([command, str(f)])
    err = capfd.readouterr().err
    assert rc == 1
    assert "Traceback" not in err
    assert (f"{f}:{line}" if line else str(f)) in err


def test_cli_usage_errors_exit_two(capfd, tmp_path):
    f = tmp_path / "ok.g2o"
    f.write_text(f"{E}\nEDGE_SE2 1 2 1 0 0 {INFO2}\n")
    assert main(["bounds"]) == 2
    assert main(["bounds", str(f), "--format", "yaml"]) == 2
    assert main(["bounds", str(f), "--anchor", "99"]) == 2
    assert main(["bounds", str(f), "--anchor", "1"]) == 0
    assert main(["nosuchcommand"]) == 2


@pytest.mark.parametrize("name", ["kitti_00.g2o", "toro/w100.graph", "toro/w10000.graph", "cubicle.g2o"])
def test_real_files_with_pitfalls_load(shared_datasets, name):
    g = load(shared_datasets / name)
    counts = {"kitti_00.g2o": (4541, 4677), "toro/w100.graph": (100, 300),
              "toro/w10000.graph": (10000, 64311), "cubicle.g2o": (5750, 16869)}[name]
    assert (g.n, g.m) == counts
    assert g.n_components == 1
    assert np.isfinite(g.tau).all() and np.isfinite(g.kappa).all()


# ---- quaternions="raw": SE-Sync's reading of 3D edge quaternions ----------------------------

def _eigen_rotation(qx, qy, qz, qw):
    """Eigen's Quaternion<double>(qw, qx, qy, qz).toRotationMatrix(), transcribed term by term
    (Eigen/src/Geometry/Quaternion.h); it never normalises."""
    tx, ty, tz = 2.0 * qx, 2.0 * qy, 2.0 * qz
    twx, twy, twz = tx * qw, ty * qw, tz * qw
    txx, txy, txz = tx * qx, ty * qx, tz * qx
    tyy, tyz, tzz = ty * qy, tz * qy, tz * qz
    return np.array([[1.0 - (tyy + tzz), txy - twz, txz + twy],
                     [txy + twz, 1.0 - (txx + tzz), tyz - twx],
                     [txz - twy, tyz + twx, 1.0 - (txx + tyy)]])


def test_raw_quaternions_follow_eigen_and_normalize_is_a_rotation(tmp_path):
    q = (0.1, -0.25, 0.3, 0.93)            # |q|^2 = 1.0074: as unnormalised as 2-digit files get
    text = (f"VERTEX_SE3:QUAT 0 0 0 0 {q[0]} {q[1]} {q[2]} {q[3]}\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n"
            f"EDGE_SE3:QUAT 0 1 1 2 3 {q[0]} {q[1]} {q[2]} {q[3]} {INFO3}\n")
    f = tmp_path / "q.g2o"
    f.write_text(text)
    raw, norm = load(f, quaternions="raw"), load(f)
    # entries of size <= 1 from a few products and sums (another operation order or FMA moves
    # each by a few ulps): 10 x 4 eps
    atol = 40 * np.finfo(float).eps
    np.testing.assert_allclose(raw.rot[0], _eigen_rotation(*q), rtol=0, atol=atol)
    nq = np.array(q) / np.linalg.norm(q)
    np.testing.assert_allclose(norm.rot[0], _eigen_rotation(*nq), rtol=0, atol=atol)
    np.testing.assert_allclose(norm.rot[0] @ norm.rot[0].T, np.eye(3), rtol=0, atol=atol)
    # Eigen's matrix of an unnormalised q is s R(q/|q|) + (1 - s) I with s = |q|^2: not orthogonal.
    s = float(np.dot(q, q))
    np.testing.assert_allclose(raw.rot[0], s * norm.rot[0] + (1 - s) * np.eye(3), rtol=0, atol=atol)
    assert np.abs(raw.rot[0] @ raw.rot[0].T - np.eye(3)).max() > 1e-3
    # Vertices are estimates, not measurements (SE-Sync ignores them): normalised either way.
    np.testing.assert_array_equal(raw.vertex_rot, norm.vertex_rot)
    np.testing.assert_array_equal(raw.trans, norm.trans)
    np.testing.assert_array_equal(raw.info, norm.info)
    assert parse_text(text, "q.g2o", quaternions="raw").rot[0].tolist() == raw.rot[0].tolist()


def test_raw_quaternions_leave_2d_and_toro_alone():
    text2 = f"EDGE_SE2 0 1 1 2 0.5 {INFO2}\n"
    np.testing.assert_array_equal(parse_text(text2, quaternions="raw").rot, parse_text(text2).rot)
    text3 = f"EDGE3 0 1 1 2 3 0.1 -0.2 0.3 {INFO3}\n"
    np.testing.assert_array_equal(parse_text(text3, quaternions="raw").rot, parse_text(text3).rot)


def test_raw_quaternions_still_reject_zero_and_bad_mode():
    from posecrb.errors import UsageError

    with pytest.raises(ParseError, match="zero quaternion"):
        parse_text(f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 0 {INFO3}\n", "z.g2o", quaternions="raw")
    with pytest.raises(UsageError, match="quaternions"):
        parse_text(f"EDGE_SE2 0 1 1 2 0.5 {INFO2}\n", quaternions="normalise")
