"""Every command keeps the promises of the first ones: each defect found by trying every command as
a new user and as an adversary would, as a test named by what it protects.

Outputs never destroy data and are checked before the work; inputs are read through the input
layer; options are checked against what the code can honour; a regression run that checked
nothing fails; doubtful numbers carry a status; dataset names resolve to what they claim;
messages are right and safe to paste.
"""
from __future__ import annotations

import gzip
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from posecrb.cli import main

from ..hostile.corpus import INFO2, graph2, text

REPO = Path(__file__).resolve().parents[2]


def run(args, capsys) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err, err
    return rc, out, err


def grid(tmp: Path, name: str = "g.g2o", poses: int = 25) -> Path:
    """A noisy 2D grid with loop closures (candidates for selection), written by the synth command."""
    path = tmp / name
    assert main(["-q", "datasets", "synth", "grid2d", "--poses", str(poses), "--noise", "0.05", "--seed", "3",
                 "--out", str(path), "--format", "json"]) == 0
    return path


def listing(d: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(d)): (p.read_bytes() if p.is_file() and not p.is_symlink() else os.readlink(p)
                                     if p.is_symlink() else None) for p in sorted(d.rglob("*"))}


# ---------------------------------------------------------------- outputs never destroy data
def test_select_out_onto_the_input_graph_is_refused(tmp_path, capsys):
    """`select intel.g2o --budget 50% --out intel.g2o` replaced the input graph with the pruned one."""
    g = grid(tmp_path, "intel.g2o")
    before = listing(tmp_path)
    rc, _, err = run(["select", g, "--budget", "50%", "--out", g], capsys)
    assert rc == 2 and f"--out {g} is the input file" in err
    assert listing(tmp_path) == before


def test_sparsify_plot_onto_the_input_graph_is_refused(tmp_path, capsys):
    """`experiment sparsify G --plot G` wrote a PNG over the input graph."""
    g = grid(tmp_path)
    before = listing(tmp_path)
    rc, _, err = run(["experiment", "sparsify", g, "--quick", "--plot", g], capsys)
    assert rc == 2 and "--plot" in err
    assert listing(tmp_path) == before


@pytest.mark.timeout(300)
def test_sparsify_plot_never_writes_through_a_predictable_temporary(tmp_path, capsys):
    """sparsify wrote through PATH.tmp and followed a symbolic link planted there."""
    g = grid(tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "fig.png"
    (tmp_path / "fig.png.tmp").symlink_to(victim)
    rc, _, err = run(["experiment", "sparsify", g, "--quick", "--format", "json", "--plot", out], capsys)
    assert rc == 0, err
    assert victim.read_text() == "precious\n" and os.readlink(tmp_path / "fig.png.tmp") == str(victim)
    assert out.read_bytes().startswith(b"\x89PNG")
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]     # no temporary left


def test_sparsify_plot_extension_must_name_a_figure_format(tmp_path, capsys):
    """`--plot x.xyz` wrote a PNG under that name."""
    g = grid(tmp_path)
    before = listing(tmp_path)
    rc, _, err = run(["experiment", "sparsify", g, "--quick", "--plot", tmp_path / "x.xyz"], capsys)
    assert rc == 2 and "the extension must be .png or .svg or .pdf (got .xyz)" in err
    assert listing(tmp_path) == before


@pytest.mark.parametrize("args", [["select", "{g}", "--budget", "1", "--out", ""],
                                  ["fim", "{g}", "--save", ""],
                                  ["solve", "{g}", "--out", ""]])
def test_empty_output_path_is_a_usage_error(tmp_path, capsys, args):
    """`--out ''` and `--save ''` wrote nothing and exited 0."""
    g = grid(tmp_path)
    before = listing(tmp_path)
    rc, _, err = run([a.format(g=g) for a in args], capsys)
    assert rc == 2 and "empty path" in err
    assert listing(tmp_path) == before


@pytest.mark.parametrize("where", ["missing", "read-only"])
def test_select_out_that_cannot_be_written_is_refused_before_the_work(tmp_path, capsys, monkeypatch, where):
    """An --out into a missing or read-only directory was found only after the selection, as an
    internal error."""
    import posecrb.selection.select as driver

    monkeypatch.setattr(driver, "select_edges", lambda *a, **k: pytest.fail("selected before checking --out"))
    g = grid(tmp_path)
    target = tmp_path / "missing" / "p.g2o" if where == "missing" else Path("/proc/posecrb-test.g2o")
    if where == "read-only" and os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        target = ro / "p.g2o"
    rc, _, err = run(["select", g, "--budget", "1", "--out", target], capsys)
    assert rc == 2 and ("does not exist" in err if where == "missing" else "cannot write in" in err)


def test_full_disk_during_select_out_is_exit_1_with_the_path(tmp_path, capsys, monkeypatch):
    """A full disk said `internal error ... (a bug in posecrb)`."""
    import errno

    import posecrb.core.outputs as outputs

    g = grid(tmp_path)
    out = tmp_path / "pruned.g2o"

    def full(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(outputs.os, "fsync", full)
    rc, _, err = run(["select", g, "--budget", "1", "--out", out], capsys)
    assert rc == 1 and f"cannot write {out}: No space left on device" in err
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


# ---------------------------------------------------------------- --fixed pairs files
def _pairs_case(tmp_path: Path) -> tuple[Path, str]:
    g = tmp_path / "loop.g2o"
    g.write_text(text(graph2(vertices=False)))          # 0-1-2-3-4 odometry, 4-0 and 1-3 loop closures
    return g, "0 1\n1 2\n2 3\n3 4\n"


def test_pairs_file_that_is_a_device_or_a_fifo_is_named_not_read(tmp_path, capsys):
    """`--fixed /dev/zero` read forever and used all the memory; a FIFO blocked."""
    g, _ = _pairs_case(tmp_path)
    fifo = tmp_path / "pairs.fifo"
    os.mkfifo(fifo)
    for path, what in ((fifo, "a FIFO (named pipe)"), ("/dev/zero", "a character device")):
        for cmd in (["select", g, "--budget", "1"], ["experiment", "sparsify", g, "--quick"]):
            rc, _, err = run([*cmd, "--fixed", path], capsys)
            assert rc == 1 and f"{path}: is {what}, not a regular file" in err, err


def test_pairs_file_comment_stays_a_comment_after_a_form_feed(tmp_path, capsys):
    """A line commented out with # came back to life after a form feed (str.splitlines)."""
    g, pairs = _pairs_case(tmp_path)
    f = tmp_path / "pairs.txt"
    f.write_text(pairs + "# 1 3 was fixed here\f4 0 came back\n")
    rc, out, err = run(["select", g, "--budget", "1", "--fixed", f, "--format", "json"], capsys)
    assert rc == 0, err
    assert json.loads(out)["fixed"]["edges"] == 4


def test_gzip_pairs_file_is_read(tmp_path, capsys):
    """A gzip-compressed --fixed file crashed with UnicodeDecodeError."""
    g, pairs = _pairs_case(tmp_path)
    f = tmp_path / "pairs.txt.gz"
    f.write_bytes(gzip.compress(pairs.encode()))
    rc, out, err = run(["select", g, "--budget", "1", "--fixed", f, "--format", "json"], capsys)
    assert rc == 0, err
    assert json.loads(out)["fixed"]["edges"] == 4


# ---------------------------------------------------------------- options the code cannot honour
def test_synth_poses_beyond_the_memory_is_a_usage_error(tmp_path, capsys):
    """`datasets synth grid2d --poses 100000000000` ended in `internal error: MemoryError ... 745 GiB`."""
    rc, _, err = run(["datasets", "synth", "grid2d", "--poses", "100000000000", "--out", tmp_path / "s.g2o"], capsys)
    assert rc == 2 and "--poses 100000000000 needs about" in err and "of memory, more than the" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("value", ["-1", str(2 ** 63), "1.5", "1_0"])
def test_seed_outside_numpys_range_is_a_usage_error(tmp_path, capsys, value):
    """`--seed -1` was accepted by `datasets synth` and failed in numpy after the work began."""
    rc, _, err = run(["datasets", "synth", "grid2d", "--noise", "0.1", "--seed", value, "--out", tmp_path / "s.g2o"],
                     capsys)
    assert rc == 2 and "--seed" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kc", ["1e308", "1e-308"])
def test_noise_level_beyond_the_precision_range_is_a_usage_error(tmp_path, capsys, monkeypatch, kc):
    """`experiment crlb --kc 1e308` ended in an internal error (OverflowError) after the work."""
    import posecrb.cli.commands.experiment as exp

    monkeypatch.setattr(exp, "crlb_sweep", lambda *a, **k: pytest.fail("trials started"))
    rc, _, err = run(["experiment", "crlb", grid(tmp_path), "--kc", kc, "--trials", "2"], capsys)
    assert rc == 2 and f"--kc {float(kc):g}: outside" in err


def test_trials_beyond_the_memory_is_a_usage_error(tmp_path, capsys, monkeypatch):
    """`--trials 10000000` (inside the old range) grew the memory without bound: now the estimate is
    checked against the memory available (here 8 GiB, whatever the machine has)."""
    import posecrb.core.resources as resources

    monkeypatch.setattr(resources, "available_memory", lambda: 8 * 1024 ** 3)
    for cmd in (["experiment", "crlb", grid(tmp_path), "--quick"], ["experiment", "thesis", "--quick"],
                ["experiment", "octagon", "--quick"]):
        rc, _, err = run([*cmd, "--trials", "10000000"], capsys)
        assert rc == 2 and "--trials 10000000 x" in err and "more than the 8 GiB available" in err


def test_every_integer_option_takes_plain_digits_only():
    """click's IntRange took `1_0` as ten (Python's int): every integer option now says no."""
    import click

    from posecrb.cli import cli
    from posecrb.cli.options import PlainInt

    def walk(cmd, path):
        if isinstance(cmd, click.Group):
            ctx = click.Context(cmd)
            for name in cmd.list_commands(ctx):
                yield from walk(cmd.get_command(ctx, name), [*path, name])
        else:
            for p in cmd.params:
                yield " ".join(path), p

    ints = [(c, p.name) for c, p in walk(cli, []) if isinstance(p.type, click.types.IntParamType)]
    assert len(ints) >= 15
    assert [(c, n) for c, n in ints if not any(isinstance(p.type, PlainInt) for cc, p in walk(cli, [])
                                               if (cc, p.name) == (c, n))] == []
    with pytest.raises(click.BadParameter, match="not an integer"):
        PlainInt(0, 5).convert("1_0", None, None)


# ---------------------------------------------------------------- regress never passes vacuously
@pytest.fixture
def empty_world(tmp_path, monkeypatch):
    """A working directory and cache without datasets, and no $POSECRB_DATA."""
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_regress_that_finds_no_dataset_exits_1(empty_world, capsys):
    """`posecrb regress` where no dataset is found printed "0 of 0 values within tolerance", exit 0."""
    rc, _, err = run(["regress"], capsys)
    assert rc == 1 and "not found:" in err and "--allow-missing" in err
    rc, _, err = run(["regress", "--allow-missing"], capsys)
    assert rc == 1 and "nothing was compared" in err


def test_regress_missing_dataset_of_the_expected_file_fails_unless_allowed(empty_world, capsys):
    g = empty_world / "mini.g2o"
    g.write_text(text(graph2()))
    exp = empty_world / "e.json"
    assert run(["regress", "--datasets", g, "--update", "--expected", exp], capsys)[0] == 0
    data = json.loads(exp.read_text())
    data["datasets"]["gone"] = dict(data["datasets"][str(g)])
    exp.write_text(json.dumps(data))
    rc, _, err = run(["regress", "--expected", exp], capsys)
    assert rc == 1 and "not found: gone" in err
    rc, _, err = run(["regress", "--expected", exp, "--allow-missing"], capsys)
    assert rc == 0 and "--allow-missing: 1 dataset(s) of the expected file not found" in err


@pytest.mark.parametrize("content, reason", [("{", ":1: invalid JSON"), ('{"datasets": []}', "'datasets' mapping"),
                                             ('{"datasets": {"CSAIL": {"lb": "1.0"}}}', "lb must be a finite number"),
                                             ('{"datasets": {"CSAIL": 3}}', "expected an object of values")])
def test_regress_malformed_expected_file_is_exit_1_with_file_and_reason(empty_world, capsys, content, reason):
    exp = empty_world / "e.json"
    exp.write_text(content)
    rc, _, err = run(["regress", "--expected", exp], capsys)
    assert rc == 1 and f"{exp}" in err and reason in err


@pytest.mark.timeout(300)
def test_regress_update_never_writes_into_an_installed_package(tmp_path):
    """`regress --update` without --expected rewrote the expected.json inside the installed package."""
    site = tmp_path / "site-packages"
    shutil.copytree(REPO / "posecrb", site / "posecrb", ignore=shutil.ignore_patterns("__pycache__"))
    installed = site / "posecrb" / "data" / "expected.json"
    before = installed.read_bytes()
    g = tmp_path / "mini.g2o"
    g.write_text(text(graph2()))
    env = {**os.environ, "PYTHONPATH": str(site), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    env.pop("POSECRB_DATA", None)
    res = subprocess.run([sys.executable, "-m", "posecrb", "regress", "--update", "--datasets", str(g)],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=240)
    assert installed.read_bytes() == before
    assert res.returncode == 2 and "pass --expected FILE" in res.stderr, res.stderr


# ---------------------------------------------------------------- statuses for doubtful numbers
def test_sed_logdet_is_within_its_accuracy_for_every_anchor_or_flagged(tmp_path, capsys):
    """A 3-pose chain, information 1e-6 and 1e6 on alternate translation axes (rotation 1 and 4): the
    log-det is exactly 2 ln 2 (a tree: the product of the edge determinants) for every anchor. With
    anchor 0 it printed 1.3863020 without a status. Now every anchor's value is within its error bound,
    and a bound above the printed precision (1e-6 relative) is a warning."""
    g = tmp_path / "chain.g2o"
    g.write_text("EDGE_SE2 0 1 1 0 0 1e-6 0 0 1e6 0 1\nEDGE_SE2 1 2 1 0 0 1e6 0 0 1e-6 0 4\n")
    exact = 2 * math.log(2)
    flagged = []
    for anchor in (0, 1, 2):
        rc, out, err = run(["fim", g, "--model", "sed", "--anchor", anchor, "--format", "json"], capsys)
        assert rc == 0, err
        row = json.loads(out)
        bound = row["logdet_accuracy"]["error_bound"]
        assert abs(row["logdet"] - exact) <= bound, (anchor, row["logdet"], bound)
        doubtful = bound > 1e-6 * max(1.0, exact)
        assert ("logdet_status" in row) == doubtful and ("log det of the FIM doubtful" in err) == doubtful
        flagged.append(doubtful)
    assert flagged == [True, False, True]        # anchor 1 splits the chain: no cancellation, every digit


def test_paper_fim_logdet_carries_its_accuracy(tmp_path, capsys):
    g = tmp_path / "g.g2o"
    g.write_text(text(graph2()))
    rc, out, _ = run(["fim", g, "--format", "json"], capsys)
    row = json.loads(out)
    assert rc == 0 and 0 < row["logdet_accuracy"]["error_bound"] < 1e-10 and "logdet_status" not in row


@pytest.mark.parametrize("scale", [1e-8, 1e8])
def test_bounds_at_extreme_overall_scale_follow_the_closed_form(tmp_path, capsys, scale):
    """Scaling every information matrix by s scales L_tau and L_w by s (2D: w = kappa): lb and ub move
    by (d + d_r)(n - 1) log s exactly, and no factorization fails (`L_tau not positive definite` was
    reported at 1e-8 and 1e8)."""
    base = grid(tmp_path, "base.g2o", poses=16)
    lines = []
    for ln in base.read_text().splitlines():
        f = ln.split()
        if f[0] == "EDGE_SE2":
            f = f[:6] + [repr(float(x) * scale) for x in f[6:]]
        lines.append(" ".join(f))
    scaled = tmp_path / "scaled.g2o"
    scaled.write_text("\n".join(lines) + "\n")
    rows = []
    for f in (base, scaled):
        rc, out, err = run(["bounds", f, "--estimate", "none", "--format", "json"], capsys)
        assert rc == 0, err
        rows.append(json.loads(out))
    shift = 3 * 15 * math.log(scale)
    for key in ("lb", "ub", "ub_lambda"):
        assert rows[1][key] == pytest.approx(rows[0][key] + shift, rel=1e-12, abs=1e-9 * abs(shift)), key


def test_subnormal_quaternion_is_reported_with_its_line(tmp_path, capsys):
    g = tmp_path / "q.g2o"
    info = "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1"
    g.write_text(f"EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 {info}\n"
                 f"EDGE_SE3:QUAT 1 2 1 0 0 1.234567e-318 2.345678e-319 0 9.87654e-319 {info}\n")
    rc, _, err = run(["info", g], capsys)
    assert rc == 0 and f"{g}:2: EDGE_SE3:QUAT: 1 quaternion(s) whose components are all subnormal" in err


@pytest.mark.timeout(300)
def test_monte_carlo_ratio_at_the_numerical_floor_is_unavailable(tmp_path, capsys):
    """`experiment crlb --kc 1e50` reported MSE/CRLB = 4e21 without a warning: at that level the CRLB is
    below the resolution of any double-precision estimate."""
    g = grid(tmp_path, poses=9)
    rc, out, err = run(["experiment", "crlb", g, "--kc", "1e50,1", "--trials", "4", "--format", "json"], capsys)
    assert rc == 0, err
    rows = {r["kc"]: r for r in json.loads(out)}
    assert rows[1e50]["ratio"] is None and rows[1e50]["ratio_status"]["status"] == "unavailable"
    assert "MSE/CRLB not available" in err
    assert rows[1.0]["ratio"] > 0 and "ratio_status" not in rows[1.0]


# ---------------------------------------------------------------- dataset resolution
@pytest.fixture
def two_copies(shared_datasets, tmp_path, monkeypatch):
    """tinyGrid3D twice on $POSECRB_DATA: an edited copy first, the verified one second."""
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()
    shutil.copy(shared_datasets / "tinyGrid3D.g2o", second / "tinyGrid3D.g2o")
    edited = (shared_datasets / "tinyGrid3D.g2o").read_text().replace("EDGE_SE3:QUAT", "EDGE_SE3:QUAT ", 1)
    (first / "tinyGrid3D.g2o").write_text(edited)
    monkeypatch.setenv("POSECRB_DATA", os.pathsep.join([str(first), str(second)]))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.chdir(tmp_path)
    return first, second


def test_corrupted_copy_shadowing_the_verified_one_warns_and_names_it(two_copies, capsys):
    first, second = two_copies
    rc, _, err = run(["info", "tinyGrid3D"], capsys)
    assert rc == 0
    assert f"{first / 'tinyGrid3D.g2o'} does not match the manifest's sha256 of tinyGrid3D" in err
    assert f"the verified copy is {second / 'tinyGrid3D.g2o'}" in err
    rc, _, err = run(["--strict", "info", "tinyGrid3D"], capsys)
    assert rc == 1 and "(--strict)" in err


def test_posecrb_data_entry_that_is_not_a_directory_is_an_error(tmp_path, capsys, monkeypatch):
    """POSECRB_DATA set to a file was silently ignored."""
    f = tmp_path / "intel.g2o"
    f.write_text(text(graph2()))
    monkeypatch.chdir(tmp_path)
    for value, what in ((str(f), "is a regular file, not a directory"), (str(tmp_path / "nope"), "does not exist")):
        monkeypatch.setenv("POSECRB_DATA", value)
        rc, _, err = run(["info", "intel"], capsys)
        assert rc == 2 and f"$POSECRB_DATA entry {value} {what}" in err


@pytest.mark.parametrize("field, value", [("file", "../escaped.g2o"), ("file", "/etc/passwd"), ("subdir", "../.."),
                                          ("file", "sub/dir.g2o"), ("subdir", "/abs")])
def test_manifest_path_cannot_leave_the_destination(field, value):
    from posecrb.datasets.manifest import ManifestError, parse_manifest

    entry = {"name": "x", "file": "x.g2o", "format": "g2o", "dim": 2, "poses": 2, "edges": 1,
             "url": "https://example.org/x.g2o", "sha256": "0" * 64, field: value}
    toml = "[[dataset]]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in entry.items())
    with pytest.raises(ManifestError, match="would leave the data directory"):
        parse_manifest(toml, "m.toml")


# ---------------------------------------------------------------- messages
def test_disconnected_graph_lists_each_components_own_ids(tmp_path, capsys):
    """A disconnected graph was reported as "#0: 2 poses (ids 0, 1, 2)": the third id was the next
    component's."""
    g = tmp_path / "two.g2o"
    g.write_text(f"EDGE_SE2 0 1 1 0 0 {INFO2}\nEDGE_SE2 5 6 1 0 0 {INFO2}\nEDGE_SE2 6 7 1 0 0 {INFO2}\n")
    rc, _, err = run(["bounds", g, "--estimate", "none"], capsys)
    assert rc == 1 and "#0: 3 poses (ids 5, 6, 7); #1: 2 poses (ids 0, 1)" in err


def test_shell_hints_are_quoted(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.chdir(tmp_path)
    rc, _, err = run(["info", "intel,my data; rm -rf ~"], capsys)
    assert rc == 1 and "give one dataset per argument" in err and "(intel 'my data; rm -rf ~')" in err


def test_tables_datasets_is_repeatable_and_never_splits_a_path(tmp_path, capsys, monkeypatch):
    """`tables --datasets` split paths at commas."""
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    a = tmp_path / "a,b.g2o"
    a.write_text(text(graph2()))
    b = tmp_path / "c.g2o"
    b.write_text(text(graph2()))
    rc, out, err = run(["tables", "--datasets", a, "--datasets", b, "--repeat", "1", "--format", "json"], capsys)
    assert rc == 0, err
    assert [r["dataset"] for r in json.loads(out)["rows"]] == ["a,b", "c"]


@pytest.mark.parametrize("command", ["tables", "regress"])
def test_datasets_comma_form_of_0_1_is_split_with_a_warning_or_refused_as_usage(tmp_path, capsys, monkeypatch,
                                                                                  command):
    """`--datasets a,b,c` was split at commas in 0.1; later it failed with "1 dataset(s) failed: a,b,c (not
    found)", exit 1. A value that names a file is taken whole; else one whose every part does is split,
    with a deprecation warning naming the repeatable form; else a usage error says the option repeats."""
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    monkeypatch.chdir(tmp_path)
    for name in ("a.g2o", "b.g2o", "c,d.g2o"):
        (tmp_path / name).write_text(text(graph2()))

    def call(value):
        args = ["tables", "--datasets", value, "--repeat", "1", "--format", "json"] if command == "tables" else \
            ["regress", "--datasets", value, "--expected", str(tmp_path / "e.json"), "--update"]
        return run(args, capsys)

    rc, out, err = call("a.g2o,b.g2o")
    assert rc == 0, err
    assert "--datasets a.g2o,b.g2o: the comma-separated form is deprecated" in err
    assert "--datasets a.g2o --datasets b.g2o" in err
    if command == "tables":
        assert [r["dataset"] for r in json.loads(out)["rows"]] == ["a.g2o", "b.g2o"]
    else:
        assert sorted(json.loads((tmp_path / "e.json").read_text())["datasets"]) == ["a.g2o", "b.g2o"]
    rc, out, err = call("c,d.g2o")            # a path with a comma is taken whole
    assert rc == 0 and "deprecated" not in err, err
    rc, _, err = call("a.g2o,nope.g2o")
    assert rc == 2 and "--datasets is repeatable" in err and "--datasets A --datasets B" in err


def test_markdown_and_latex_escape_dataset_names(tmp_path, capsys, monkeypatch):
    """Dataset names were written into Markdown and LaTeX unescaped (a | split the row, a $ or a
    backslash broke the document)."""
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    name = r"we|ird_$#&{x}\input~^*"
    g = tmp_path / f"{name}.g2o"
    g.write_text(text(graph2()))
    rc, out, _ = run(["tables", "--datasets", g, "--repeat", "1", "--table", "1", "--format", "markdown"], capsys)
    assert rc == 0
    row = next(ln for ln in out.splitlines() if "ird" in ln)
    assert r"we\|ird\_$#&{x}\\input\~^\*" in row
    rc, out, _ = run(["tables", "--datasets", g, "--repeat", "1", "--table", "1", "--format", "latex"], capsys)
    assert rc == 0
    assert (r"we\textbar{}ird\_\$\#\&\{x\}\textbackslash{}input\textasciitilde{}\textasciicircum{}*"
            in out)


# ---------------------------------------------------------------- found by the red-team pass
def test_too_long_output_name_is_refused_before_the_work_and_a_long_one_is_written(tmp_path, capsys):
    """A 256-byte file name ended in `cannot write ...: File name too long` after the solve; a
    251-byte one failed too, because of the temporary's longer name."""
    g = grid(tmp_path)
    rc, _, err = run(["solve", g, "--out", tmp_path / ("a" * 252 + ".g2o")], capsys)
    assert rc == 2 and "the file name is 256 bytes long" in err
    out = tmp_path / ("b" * 251 + ".g2o")
    rc, _, err = run(["solve", g, "--out", out], capsys)
    assert rc == 0 and out.is_file(), err
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_regress_expected_file_that_does_not_exist_is_a_usage_error(empty_world, capsys):
    rc, _, err = run(["regress", "--expected", empty_world / "nope.json"], capsys)
    assert rc == 2 and "nope.json: no such file" in err


def test_thesis_empty_m_list_is_a_usage_error(capsys):
    """`experiment thesis --m ''` ran the default list."""
    rc, _, err = run(["experiment", "thesis", "--m", "", "--trials", "2"], capsys)
    assert rc == 2 and "--m takes a comma-separated list" in err


def test_unreachable_dask_scheduler_is_a_usage_error(monkeypatch):
    """An unreachable --scheduler was an internal error (OSError) after a 30 s wait."""
    pytest.importorskip("dask.distributed")
    import dask.distributed

    from posecrb.core.errors import UsageError
    from posecrb.sim import montecarlo

    def refused(*a, **k):
        raise OSError("Timed out trying to connect to tcp://127.0.0.1:1 after 30 s")

    monkeypatch.setattr(dask.distributed, "Client", refused)
    with pytest.raises(UsageError, match="--scheduler tcp://127.0.0.1:1: cannot connect to the Dask scheduler"):
        montecarlo.run_tasks(montecarlo.demo_trial, [{}], montecarlo.make_tasks(0, 2, [(1,)]), executor="dask",
                             scheduler="tcp://127.0.0.1:1")
