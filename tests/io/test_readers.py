"""Readers: content sniffing, id remapping, skipped tags, and a corpus of malformed files;
robustness of the reader (line ends, ids, number syntax, magnitudes) and atomic writes."""
import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from posecrb import load
from posecrb.cli import main
from posecrb.core.errors import ParseError
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
    from posecrb.core.errors import UsageError

    with pytest.raises(ParseError, match="zero quaternion"):
        parse_text(f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 0 {INFO3}\n", "z.g2o", quaternions="raw")
    with pytest.raises(UsageError, match="quaternions"):
        parse_text(f"EDGE_SE2 0 1 1 2 0.5 {INFO2}\n", quaternions="normalise")


# ---- robustness of the reader ----------------------------------------------------------------

def test_lines_end_at_lf_crlf_and_cr_only():
    text = f"# a\r\n{E}\rEDGE_SE2 1 2 1 0 0 {INFO2}\n\nEDGE_SE2 2 3 1 0 0 {INFO2}\r\n"
    g = parse_text(text, "le.g2o")
    assert list(g.edge_lines) == [2, 3, 5]


@pytest.mark.parametrize("sep", ["\f", "\v", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029"])
def test_a_commented_out_edge_stays_commented_whatever_separator_it_contains(sep):
    # str.splitlines() breaks at each of these: the tail of the comment became an edge (0, 2)
    text = f"{E}\nEDGE_SE2 1 2 1 0 0 {INFO2}\n# off:{sep}EDGE_SE2 0 2 5 5 1 {INFO2}\nEDGE_SE2 1 2 1 0 0 {INFO2} 9\n"
    with pytest.raises(ParseError) as exc:
        parse_text(text, "c.g2o")
    assert exc.value.line == 4                       # later line numbers are not shifted
    g = parse_text(text.rsplit("\n", 2)[0] + "\n", "c.g2o")
    assert g.m == 2 and g.skipped == {"#": 1}


def test_ids_are_integers_not_floats(tmp_path):
    a, b, top = 2 ** 53, 2 ** 53 + 1, 2 ** 63 - 1       # a and b are the same float64
    g = parse_text(f"EDGE_SE2 {a} {b} 1 0 0 {INFO2}\nEDGE_SE2 {b} {top} 1 0 0 {INFO2}\n", "i.g2o")
    assert g.ids.tolist() == [a, b, top] and g.ids.dtype == np.int64
    out = tmp_path / "o.g2o"
    write_g2o(g.with_vertices(np.repeat(np.eye(2)[None], 3, 0), np.zeros((3, 2))), out)
    assert f"VERTEX_SE2 {b} " in out.read_text() and f"EDGE_SE2 {a} {b} " in out.read_text()
    assert load(out).ids.tolist() == [a, b, top]
    with pytest.raises(ParseError, match=r"'9223372036854775808' is not a non-negative integer id") as exc:
        parse_text(f"{E}\nEDGE_SE2 1 {2 ** 63} 1 0 0 {INFO2}\n", "i.g2o")
    assert exc.value.line == 2


@pytest.mark.parametrize("token, where", [("1_0", "id"), ("+1", "id"), ("1e0", "id"), ("\u0661", "id"),
                                          ("1_0", "value"), ("\u0661", "value"), ("0x10", "value"),
                                          ("1.0.0", "value")])
def test_python_number_extensions_are_not_numbers(token, where):
    # int() and float() accept underscores and non-ASCII digits; a g2o file does not
    line = f"EDGE_SE2 {token} 2 1 0 0 {INFO2}" if where == "id" else f"EDGE_SE2 1 2 {token} 0 0 {INFO2}"
    with pytest.raises(ParseError, match="not a non-negative integer id" if where == "id" else "not a number") as exc:
        parse_text(f"{E}\n{line}\n", "n.g2o")
    assert exc.value.line == 2


@pytest.mark.parametrize("q", ["1e308 1e308 0 0", "-1e308 -1e308 0 0", "1e-320 1e-320 0 0", "3e200 3e200 0 0"])
def test_quaternion_normalised_after_scaling_never_the_identity(q):
    # q/|q| overflowed to 0 -> identity (1e308), or was rejected as "zero" (1e-320)
    g = parse_text(f"EDGE_SE3:QUAT 0 1 0 0 0 {q} {INFO3}\n", "q.g2o")
    c = parse_text(f"EDGE_SE3:QUAT 0 1 0 0 0 0.70710678118654752 0.70710678118654752 0 0 {INFO3}\n", "q.g2o")
    np.testing.assert_allclose(g.rot[0], c.rot[0], rtol=0, atol=4 * np.finfo(float).eps)
    # 180 degrees about (1, 1, 0)/sqrt 2: R = 2 n n^T - I
    np.testing.assert_allclose(g.rot[0], [[0, 1, 0], [1, 0, 0], [0, 0, -1]], rtol=0, atol=1e-15)


def test_raw_quaternion_too_large_to_use_unnormalised_is_an_error():
    with pytest.raises(ParseError, match="quaternion norm 1.41421e\\+308 is too large"):
        parse_text(f"EDGE_SE3:QUAT 0 1 0 0 0 1e308 1e308 0 0 {INFO3}\n", "q.g2o", quaternions="raw")


@pytest.mark.parametrize("line, reason", [
    ("EDGE_SE2 1 2 1 0 0 1e200 0 0 1e200 0 1e200", "information entry 1e+200 exceeds 1e+100"),
    ("EDGE_SE2 1 2 1 0 0 1e308 0 0 1e308 0 1e308", "information entry 1e+308 exceeds 1e+100"),
    (f"EDGE_SE2 1 2 1e308 0 0 {INFO2}", "translation component 1e+308 exceeds 1e+50"),
    ("EDGE_SE2 1 2 1 0 0 1e-300 0 0 1e-300 0 5", "translation precision tau = 0 is outside [1e-100, 1e+100]"),
    ("EDGE_SE2 1 2 1 0 0 10 0 0 10 0 1e-120", "rotation concentration kappa = 1e-120 is outside"),
    (f"EDGE_SE3:QUAT 1 2 0 0 0 0 0 0 1 {INFO3.rsplit(' ', 6)[0]} 1e-60 0 0 1e-60 0 1e-60",
     "rotation weight omega(kappa)/3 (eq. 59) = 8.33333e-122 is outside"),
])
def test_values_that_would_overflow_downstream_are_rejected_with_file_line(line, reason):
    first = E if line.startswith("EDGE_SE2") else f"EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 {INFO3}"
    with pytest.raises(ParseError) as exc:
        parse_text(f"{first}\n{line}\n", "o.g2o")
    assert exc.value.line == 2 and reason in exc.value.reason, exc.value.reason


def test_vertex_translation_that_would_overflow_is_rejected():
    with pytest.raises(ParseError, match="VERTEX_SE2: translation component -1e\\+300 exceeds") as exc:
        parse_text(f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 -1e300 0 0\n{E}\n", "v.g2o")
    assert exc.value.line == 2


def test_positive_definiteness_is_scale_aware():
    a, c = 1e12, 1e-3
    g = parse_text(f"EDGE_SE2 0 1 1 0 0 {a:g} 0 0 {c:g} 0 1000\n", "pd.g2o")
    assert g.tau[0] == pytest.approx(2 * a * c / (a + c), rel=1e-15)   # tau = 2 / trace(inv(I_tt))
    g3 = parse_text("EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 1e12 0 0 0 0 0 1e-3 0 0 0 0 1 0 0 0 "
                    "1e9 0 0 1e-4 0 1\n", "pd3.g2o")
    assert g3.m == 1
    cases = {"1 1 0 1 0 5": "(singular to working precision)",
             "1 2 0 1 0 5": "(smallest eigenvalue -1 after scaling to unit diagonal)",
             "0 0 0 1 0 5": "(diagonal entry 1 is 0)",
             "1e12 0 0 -1e-3 0 5": "(diagonal entry 2 is -0.001)"}
    for info, why in cases.items():
        with pytest.raises(ParseError) as exc:
            parse_text(f"{E}\nEDGE_SE2 1 2 1 0 0 {info}\n", "pd.g2o")
        msg = str(exc.value)
        assert exc.value.line == 2 and "translation block of the information matrix is not positive definite" in msg
        assert msg.endswith(why) and "np." not in msg


def test_messages_show_plain_numbers():
    for text in (f"EDGE_SE2 -1 2 1 0 0 {INFO2}\n", f"EDGE_SE2 1 1 1 0 0 {INFO2}\n",
                 "EDGE_SE2 1 2 1 0 0 -1 0 0 1 0 1\n"):
        with pytest.raises(ParseError) as exc:
            parse_text(text, "m.g2o")
        assert "np." not in str(exc.value) and "float64" not in str(exc.value)


@pytest.mark.timeout(60)
def test_only_regular_files_are_read(tmp_path):
    d = tmp_path / "d.g2o"
    d.mkdir()
    fifo = tmp_path / "f.g2o"
    os.mkfifo(fifo)          # open() would block until a writer appears
    for path, kind in ((d, "a directory"), (fifo, "a FIFO (named pipe)"), ("/dev/zero", "a character device"),
                       (tmp_path / "none.g2o", None)):
        with pytest.raises(ParseError) as exc:
            load(path)
        assert exc.value.reason == (f"is {kind}, not a regular file" if kind else "no such file")


# ---- atomic writes ------------------------------------------------------------------------------

def test_write_g2o_leaves_a_users_tmp_file_alone(tmp_path, random_graph):
    g = random_graph(np.random.default_rng(1), n=5)
    out = tmp_path / "out.g2o"
    (tmp_path / "out.g2o.tmp").write_text("mine\n")      # write_g2o used to write (and leave) OUT.tmp
    write_g2o(g, out)
    assert (tmp_path / "out.g2o.tmp").read_text() == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.g2o", "out.g2o.tmp"]


@pytest.mark.parametrize("exc_type", [RuntimeError, KeyboardInterrupt])
def test_failed_write_keeps_the_previous_file_and_no_temporary(tmp_path, exc_type):
    from posecrb.core.outputs import atomic_write

    f = tmp_path / "result.txt"
    f.write_text("previous\n")
    with pytest.raises(exc_type):
        with atomic_write(f) as fh:
            fh.write("partial")
            raise exc_type("stop")
    assert f.read_text() == "previous\n" and [p.name for p in tmp_path.iterdir()] == ["result.txt"]


def test_result_npz_write_failure_keeps_the_previous_file(tmp_path, monkeypatch):
    import scipy.sparse as sp

    from posecrb.core import result
    from posecrb.models.results import FimResult

    target = tmp_path / "f.npz"
    target.write_bytes(b"previous")

    def broken_savez(file, **arrays):      # numpy's savez killed half-way (disk full, SIGKILL, ...)
        if isinstance(file, (str, os.PathLike)):
            file = open(str(file) if str(file).endswith(".npz") else f"{file}.npz", "wb")
        file.write(b"PK partial")
        file.flush()
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(result.np, "savez", broken_savez)
    fim = FimResult(dataset="g", model="paper", dim=2, poses=2, edges=1, components=1, anchors=[0], layout="blocks",
                    size=3, nnz=3, logdet=0.0, trace=3.0, rank=3, nullity=0, frame="mixed",
                    matrix=sp.eye(3), row_ids=np.arange(3), row_coord=np.zeros(3),
                    coordinate_names=["x"])
    # a full disk is the system's answer, reported with the path (exit 1), not an internal error
    from posecrb.core.errors import OutputError

    with pytest.raises(OutputError, match=r"cannot write .*f\.npz: No space left on device"):
        fim.save(str(tmp_path / "f"))
    assert target.read_bytes() == b"previous" and [p.name for p in tmp_path.iterdir()] == ["f.npz"]


def test_atomic_write_permissions(tmp_path):
    from posecrb.core.outputs import write_text

    new = write_text(tmp_path / "new.txt", "x")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(new.stat().st_mode) == 0o666 & ~umask
    old = tmp_path / "old.txt"
    old.write_text("y")
    old.chmod(0o640)
    write_text(old, "z")
    assert stat.S_IMODE(old.stat().st_mode) == 0o640 and old.read_text() == "z"


@pytest.mark.timeout(120)
def test_sigterm_during_a_write_removes_the_temporary(tmp_path):
    """SIGTERM (what `kill` and job schedulers send) is turned into an exception in the CLI,
    so the temporary of a write in progress is removed and the previous file kept."""
    script = tmp_path / "killed.py"
    target = tmp_path / "out" / "result.g2o"
    target.parent.mkdir()
    target.write_text("previous\n")
    script.write_text(
        "import os, signal, sys, time\n"
        "from posecrb.cli import main\n"
        "import posecrb.cli.commands.info as info\n"
        "from posecrb.core.outputs import atomic_write\n"
        "def slow(graph):\n"
        f"    with atomic_write({str(target)!r}) as fh:\n"
        "        fh.write('partial')\n"
        "        fh.flush()\n"
        "        os.kill(os.getpid(), signal.SIGTERM)\n"
        "        time.sleep(30)\n"
        "info.graph_info = slow\n"
        "sys.exit(main(sys.argv[1:]))\n")
    g = tmp_path / "g.g2o"
    g.write_text(f"{E}\n")
    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(repo)}
    res = subprocess.run([sys.executable, str(script), "info", str(g)], capture_output=True, text=True,
                         env=env, timeout=60)
    assert res.returncode == 128 + signal.SIGTERM, res.stderr
    assert "terminated" in res.stderr and "Traceback" not in res.stderr
    assert target.read_text() == "previous\n"
    assert [p.name for p in target.parent.iterdir()] == ["result.g2o"]


def test_ctrl_c_during_a_write_exits_130_and_removes_the_temporary(tmp_path, monkeypatch, capsys):
    import posecrb.cli.commands.info as info
    from posecrb.core.outputs import atomic_write

    target = tmp_path / "out" / "result.txt"
    target.parent.mkdir()

    def interrupted(graph):
        with atomic_write(target) as fh:
            fh.write("partial")
            raise KeyboardInterrupt

    monkeypatch.setattr(info, "graph_info", interrupted)
    g = tmp_path / "g.g2o"
    g.write_text(f"{E}\n")
    assert main(["info", str(g)]) == 130
    assert "interrupted" in capsys.readouterr().err
    assert list(target.parent.iterdir()) == []
