"""Every command against the hostile-input corpus (tests/hostile/corpus.py).

For each case and command: exit 0 with the numbers of the same graph written cleanly, or
exit 1 with ``file:line`` and the reason; never a traceback, a RuntimeWarning (they are
turned into errors here, so one reaching ``main`` shows up as an internal error), a numpy
repr, or a temporary file left in the output directory. Commands run in-process through
``posecrb.cli.main`` on graphs of 4-5 poses; a few run as ``python -W error::RuntimeWarning
-m posecrb`` to cover the real entry point.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from posecrb.cli import main
from posecrb.core.folders import MANIFEST
from posecrb.io import load

from ..hostile.corpus import BIG_IDS, CASES, ODD_SEPARATORS, Case, write, write_clean

ACCEPTED = sorted(n for n, c in CASES.items() if c.accepted)
REJECTED = sorted(n for n, c in CASES.items() if not c.accepted)
REPO = Path(__file__).resolve().parents[2]

# command -> (argv builder, result files it may leave in the output directory)
COMMANDS = {
    "info": (lambda f, o: ["info", f, "--format", "json"], set()),
    "bounds": (lambda f, o: ["bounds", f, "--format", "json", "--repeat", "1"], set()),
    "solve": (lambda f, o: ["solve", f, "--format", "json", "--out", str(o / "estimate.g2o")], {"estimate.g2o"}),
    "fim": (lambda f, o: ["fim", f, "--format", "json", "--save", str(o / "fim")], {"fim.npz"}),
    "crlb": (lambda f, o: ["crlb", f, "--format", "json", "--poses", "all"], set()),
    "fim-sed": (lambda f, o: ["fim", f, "--model", "sed", "--format", "json"], set()),
    "crlb-sed": (lambda f, o: ["crlb", f, "--model", "sed", "--format", "json"], set()),
    "tables": (lambda f, o: ["tables", "--datasets", f, "--format", "json", "--repeat", "1", "--out", str(o / "t")],
               {"t"}),
    "regress": (lambda f, o: ["regress", "--datasets", f, "--expected", str(o / "expected.json"), "--update"],
                {"expected.json"}),
    "timeline": (lambda f, o: ["timeline", f, "--format", "json"], set()),
}

# numbers compared with the clean graph: graph-only ones to 1e-12 relative (the same floats
# up to the last bit of a normalised quaternion), solver-dependent ones to 1e-6 (the
# solver's stopping point may move with an ulp of input).
GRAPH_ONLY = {"tau_min", "tau_max", "kappa_min", "kappa_max", "poses", "edges", "lb", "ub", "ub_lambda",
              "degree_mean", "components", "parallel_edges"}


def _numbers(command: str, out: str, odir: Path) -> dict[str, float]:
    if command == "regress":
        data = json.loads((odir / "expected.json").read_text())["datasets"]
        (row,) = data.values()
        return {k: v for k, v in row.items() if isinstance(v, (int, float))}
    data = json.loads(out)
    if command == "tables":
        data = data["rows"][0]
    if command == "timeline":
        data = data["rows"][-1]
    keys = {"info": ["poses", "edges", "tau_min", "tau_max", "kappa_min", "kappa_max", "degree_mean",
                     "parallel_edges", "components"],
            "bounds": ["lb", "ub", "ub_lambda", "fim_logdet"],
            "solve": ["objective", "relaxation_value"],
            "fim": ["logdet", "trace", "size", "nnz"],
            "crlb": ["trace_crlb", "mse_bound", "trace_translation", "trace_rotation"],
            "fim-sed": ["logdet", "trace", "rank", "nullity"],
            "crlb-sed": ["trace_crlb", "mse_bound", "nullity"],
            "tables": ["lb", "ub", "ub_lambda", "objective", "fim_logdet"],
            "timeline": ["lb", "ub", "t_opt_graph", "fim_logdet"]}[command]
    return {k: data[k] for k in keys}


def _same_numbers(got: dict, want: dict) -> None:
    for k, v in want.items():
        if not isinstance(v, (int, float)) or not isinstance(got[k], (int, float)):
            assert got[k] == v, (k, got[k], v)        # e.g. a status instead of a number: the same one
            continue
        rtol = 1e-12 if k in GRAPH_ONLY else 1e-6
        assert math.isclose(got[k], v, rel_tol=rtol, abs_tol=0), (k, got[k], v)


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    """main() with every RuntimeWarning raised as an error; checks what no run may print."""
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    for bad in ("Traceback", "RuntimeWarning", "internal error", "np.float64", "np.int64", "numerical problem"):
        assert bad not in err and bad not in out, (bad, err)
    return rc, out, err


def leftovers(odir: Path, allowed: set[str]) -> list[str]:
    """Files in the output directory that are not the command's results, temporaries included (a
    folder output's manifest of what posecrb wrote is one of its results)."""
    found = []
    for p in odir.rglob("*"):
        rel = p.relative_to(odir)
        if rel.parts[0] not in allowed or (p.name.startswith(".") and p.name != MANIFEST) \
                or p.suffix in (".tmp", ".part"):
            found.append(str(rel))
    return sorted(found)


# Accepted inputs whose result for one command is numerically unavailable (the same for the
# clean twin): information spanning 1e12..1e-3 on every edge makes the SE(d) FIM singular to
# working precision (relative eigenvalue 1e-15), so its inverse is refused.
NUMERICALLY_UNAVAILABLE = {("information_diag_1e12_1e-3", "crlb-sed"): "numerically singular"}

_clean_cache: dict[tuple[str, str], dict[str, float]] = {}


def _clean_numbers(case: Case, command: str, tmp_path_factory, capsys) -> dict[str, float]:
    key = (case.name, command)
    if key not in _clean_cache:
        d = tmp_path_factory.mktemp("clean")
        f = write_clean(case, d)
        odir = d / "out"
        odir.mkdir()
        rc, out, err = run_cli(COMMANDS[command][0](str(f), odir), capsys)
        assert rc == 0, err
        _clean_cache[key] = _numbers(command, out, odir)
    return _clean_cache[key]


def _run_case(case, command: str, tmp_path, capsys):
    """Write ``case`` to a file, run ``command`` on it with an empty output folder: (file, folder,
    files the command may leave there, (exit code, stdout, stderr))."""
    f = write(case, tmp_path)
    odir = tmp_path / "out"
    odir.mkdir()
    build, allowed = COMMANDS[command]
    return f, odir, allowed, run_cli(build(str(f), odir), capsys)


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("name", ACCEPTED)
def test_accepted_hostile_input_gives_the_numbers_of_the_clean_graph(tmp_path, tmp_path_factory, capsys,
                                                                     name, command):
    case = CASES[name]
    f, odir, allowed, (rc, out, err) = _run_case(case, command, tmp_path, capsys)
    if (name, command) in NUMERICALLY_UNAVAILABLE:
        # The reader accepts the file; the quantity itself is beyond double precision, which is an
        # error with the reason and the offending edge's line, never a number.
        assert rc == 1, out
        assert NUMERICALLY_UNAVAILABLE[name, command] in err and "line " in err, err
        assert "Traceback" not in err
        return
    assert rc == 0, err
    got = _numbers(command, out, odir)
    want = _clean_numbers(case, command, tmp_path_factory, capsys)
    _same_numbers(got, want)
    assert leftovers(odir, allowed) == []
    if command == "fim":
        assert json.loads(out)["saved"] == str(odir / "fim.npz") and (odir / "fim.npz").is_file()
    if name == "ids_beyond_2p53" and command == "info":
        row = json.loads(out)
        assert (row["id_min"], row["id_max"]) == (BIG_IDS[0], BIG_IDS[-1])
    if name == "ids_beyond_2p53" and command == "solve":
        # solve --out writes the ids back exactly (no float64 round trip)
        written = (odir / "estimate.g2o").read_text().split("\n")
        vids = sorted(int(ln.split()[1]) for ln in written if ln.startswith("VERTEX"))
        assert vids == sorted(BIG_IDS)
        assert f"EDGE_SE2 {BIG_IDS[1]} {BIG_IDS[2]} " in (odir / "estimate.g2o").read_text()
        assert load(odir / "estimate.g2o").ids.tolist() == list(BIG_IDS)


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("name", REJECTED)
def test_rejected_hostile_input_exits_1_with_file_line_and_reason(tmp_path, capsys, name, command):
    case = CASES[name]
    f, odir, allowed, (rc, out, err) = _run_case(case, command, tmp_path, capsys)
    assert rc == 1
    where = f"{f}:{case.line}:" if case.line is not None else f"{f}:"
    assert where in err and case.reason in err, err
    # tables reports a failed dataset as a row of its --out files; nothing else may remain
    assert leftovers(odir, {"t"} if command == "tables" else set()) == []


@pytest.mark.parametrize("name", ["odd_separators_in_comments", "ids_beyond_2p53", "information_1e200"])
def test_experiment_crlb_on_hostile_input(tmp_path, tmp_path_factory, capsys, name):
    case = CASES[name]
    f = write(case, tmp_path)
    odir = tmp_path / "out"
    odir.mkdir()
    args = ["experiment", "crlb", str(f), "--quick", "--trials", "2", "--kc", "1", "--format", "json",
            "--out", str(odir / "exp")]
    rc, out, err = run_cli(args, capsys)
    if not case.accepted:
        assert rc == 1 and f"{f}:{case.line}:" in err and leftovers(odir, set()) == []
        return
    assert rc == 0, err
    got = json.loads(out)          # one level: one JSON object
    c = write_clean(case, tmp_path)
    rc, out_clean, _ = run_cli(["experiment", "crlb", str(c), "--quick", "--trials", "2", "--kc", "1",
                                "--format", "json"], capsys)
    want = json.loads(out_clean)
    _same_numbers({k: got[k] for k in ("mse", "mse_bound")}, {k: want[k] for k in ("mse", "mse_bound")})
    assert leftovers(odir, {"exp"}) == []
    assert sorted(p.name for p in (odir / "exp").iterdir()) == [MANIFEST, "crlb.png", "rows.csv", "rows.json",
                                                                "run.json", "trials.csv"]


@pytest.mark.parametrize("name", ["information_1e308", "ids_beyond_2p53"])
def test_datasets_verify_parses_hostile_files(tmp_path, capsys, monkeypatch, name):
    """A hostile file under a manifest name on the search path: exit 1 (file:line or checksum)."""
    import posecrb.datasets.search as ds

    d = tmp_path / "data"
    d.mkdir()
    f = write(CASES[name], d, "intel.g2o")
    monkeypatch.setattr(ds, "search_path", lambda data_dir=None: [d])
    rc, out, err = run_cli(["datasets", "verify", "--parse", "--format", "json"], capsys)
    assert rc == 1
    if CASES[name].accepted:
        assert "checksum mismatch" in err
    else:
        assert f"{f}:{CASES[name].line}:" in err


# ---------------------------------------------------------------- line separators, one by one
@pytest.mark.parametrize("sep", sorted(ODD_SEPARATORS))
def test_each_odd_separator_keeps_a_comment_a_comment(tmp_path, sep):
    from ..hostile.corpus import INFO2, graph2, text

    lines = graph2()
    commented = f"# off:{ODD_SEPARATORS[sep]}EDGE_SE2 0 2 5 5 1 {INFO2}"
    g = load(write(Case(sep, text([commented] + lines + ["EDGE_SE2 0 3 1 0 0 " + INFO2])), tmp_path))
    assert g.m == len([ln for ln in lines if ln.startswith("EDGE")]) + 1
    assert g.edge_lines[-1] == len(lines) + 2      # the line number of the last line is exact
    assert not any((g.src == 0) & (g.dst == 2) & (g.trans[:, 0] == 5))


# ---------------------------------------------------------------- inputs that are not regular files
def _special_inputs(tmp_path: Path) -> dict[str, tuple[str, str]]:
    d = tmp_path / "adir.g2o"
    d.mkdir()
    fifo = tmp_path / "fifo.g2o"
    os.mkfifo(fifo)
    return {"directory": (str(d), "is a directory"), "fifo": (str(fifo), "is a FIFO (named pipe)"),
            "device": ("/dev/zero", "is a character device")}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("command", ["info", "bounds", "solve", "fim", "crlb", "tables", "regress", "experiment"])
def test_non_regular_files_as_input_are_named_not_read(tmp_path, capsys, command):
    odir = tmp_path / "out"
    odir.mkdir()
    for path, what in _special_inputs(tmp_path).values():
        if command == "experiment":
            args = ["experiment", "crlb", path, "--quick", "--trials", "2", "--kc", "1"]
        elif command in COMMANDS:
            args = COMMANDS[command][0](path, odir)
        rc, out, err = run_cli(args, capsys)
        assert rc == 1 and f"{path}: {what}, not a regular file" in err, err
        assert leftovers(odir, {"t"}) == []


@pytest.mark.timeout(120)
@pytest.mark.parametrize("command", ["fim", "crlb", "bounds"])
def test_non_regular_estimate_file_is_named_not_read(tmp_path, capsys, command):
    f = write_clean(CASES["crlf_line_ends"], tmp_path)
    for path, what in _special_inputs(tmp_path).values():
        rc, out, err = run_cli([command, str(f), "--estimate", path], capsys)
        assert rc == 1 and f"{path}: {what}, not a regular file" in err, err


# ---------------------------------------------------------------- the real entry point
@pytest.mark.parametrize("name", ["information_1e200", "quaternion_norm_overflows", "translation_1e308"])
def test_python_m_posecrb_with_runtime_warnings_as_errors(tmp_path, name):
    case = CASES[name]
    f = write(case, tmp_path)
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    for cmd in (["info", str(f)], ["crlb", str(f), "--format", "json"]):
        res = subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-m", "posecrb", *cmd],
                             capture_output=True, text=True, env=env, timeout=120, cwd=tmp_path)
        assert "Traceback" not in res.stderr and "RuntimeWarning" not in res.stderr
        if case.accepted:
            assert res.returncode == 0, res.stderr
        else:
            assert res.returncode == 1 and f"{f}:{case.line}: " in res.stderr and case.reason in res.stderr


def test_a_runtime_warning_reaches_the_user_as_one_log_line(tmp_path, capsys, monkeypatch):
    """The safety net in main(): a warning nobody silenced at its source becomes one line."""
    import posecrb.cli.commands.info as info_cmd

    real = info_cmd.graph_info

    def noisy(graph):
        np.log(np.zeros(1))            # divide by zero: a numpy RuntimeWarning
        return real(graph)

    monkeypatch.setattr(info_cmd, "graph_info", noisy)
    f = write_clean(CASES["crlf_line_ends"], tmp_path)
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        rc = main(["info", str(f), "--format", "json"])
    err = capsys.readouterr().err
    assert rc == 0
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines == ["posecrb: warning: numerical problem in test_hostile_input.py "
                     "(divide by zero encountered in log); results may be inaccurate"]


# ---------------------------------------------------------------- hostile option values
def _all_params():
    import click

    from posecrb.cli import cli

    def walk(cmd, path):
        for p in cmd.params:
            yield path, p
        if isinstance(cmd, click.Group):    # the top-level group loads its commands on request
            ctx = click.Context(cmd)
            for name in cmd.list_commands(ctx):
                yield from walk(cmd.get_command(ctx, name), path + [name])
    yield from walk(cli, [])


def test_every_float_option_uses_the_validated_type():
    import click

    from posecrb.cli.options import POSE_ID, FiniteFloat

    floats = [(" ".join(path), p.name) for path, p in _all_params() if isinstance(p.type, click.types.FloatParamType)]
    assert floats, "no float option found"
    assert [(c, n) for c, n in floats if not isinstance(dict(_all_params_by_name())[(c, n)], FiniteFloat)] == []
    anchors = [(" ".join(path), p.type) for path, p in _all_params() if p.name in ("anchor", "anchors")]
    assert anchors and all(t is POSE_ID for _, t in anchors)


def _all_params_by_name():
    for path, p in _all_params():
        yield (" ".join(path), p.name), p.type


FLOAT_OPTIONS = [
    (["solve", "{f}"], "--certificate-tol"),
    (["datasets", "fetch", "intel"], "--timeout"),
    (["datasets", "fetch", "intel"], "--deadline"),
    (["datasets", "synth", "grid2d", "--out", "{o}/s.g2o"], "--noise"),
    (["datasets", "synth", "grid2d", "--out", "{o}/s.g2o"], "--tau"),
    (["datasets", "synth", "grid2d", "--out", "{o}/s.g2o"], "--kappa"),
    (["experiment", "crlb", "{f}", "--quick"], "--kappa"),
    (["experiment", "crlb", "{f}", "--quick"], "--tau"),
    (["experiment", "octagon", "--quick"], "--radius"),
]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-1", "1_0", "1e999"])
@pytest.mark.parametrize("base, option", FLOAT_OPTIONS, ids=[f"{b[0]}-{b[1]}{o}" for b, o in FLOAT_OPTIONS])
def test_bad_float_option_values_exit_2(tmp_path, capsys, base, option, value):
    """`solve --certificate-tol nan` looped forever; -1 and inf were accepted."""
    f = write_clean(CASES["crlf_line_ends"], tmp_path)
    args = [a.format(f=f, o=tmp_path) for a in base] + [option, value]
    rc, out, err = run_cli(args, capsys)
    assert rc == 2 and f"Invalid value for '{option}'" in err, err
    assert list(tmp_path.iterdir()) == [f]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("tol", [float("nan"), float("inf"), -1.0])
def test_solver_rejects_a_bad_certificate_tolerance_instead_of_looping(tol):
    from posecrb.core.errors import PosecrbError
    from posecrb.solver import solve

    f = CASES["crlf_line_ends"].clean
    from posecrb.io import parse_text

    with pytest.raises(PosecrbError, match="certificate tolerance must be a finite number"):
        solve(parse_text(f, "t.g2o"), certificate_tol=tol)


def test_pose_id_options_are_integers_that_fit_int64(tmp_path, capsys):
    f = write(CASES["ids_beyond_2p53"], tmp_path)
    rc, out, _ = run_cli(["crlb", str(f), "--anchor", str(BIG_IDS[-1]), "--format", "json"], capsys)
    assert rc == 0 and json.loads(out)["anchors"] == [BIG_IDS[-1]]
    for bad in ("1_0", "-1", str(2 ** 63), "1.0"):
        rc, out, err = run_cli(["crlb", str(f), "--anchor", bad], capsys)
        assert rc == 2 and "is not a pose id" in err
    for bad in ("1_0", "\u0661", str(2 ** 63), f"0-{2 ** 63 - 1}"):
        rc, out, err = run_cli(["crlb", str(f), "--poses", bad], capsys)
        assert rc == 2 and "--poses" in err and "is not a pose id or an id range" in err


# ---------------------------------------------------------------- outputs never destroy data
def test_solve_refuses_to_write_over_its_input(tmp_path, capsys, monkeypatch):
    import posecrb.solver

    monkeypatch.setattr(posecrb.solver, "solve", lambda *a, **k: pytest.fail("solved before checking --out"))
    f = write_clean(CASES["crlf_line_ends"], tmp_path)
    before = f.read_bytes()
    link = tmp_path / "link.g2o"
    link.symlink_to(f.name)
    hard = tmp_path / "hard.g2o"
    os.link(f, hard)
    for out in (f, link, hard, Path(os.path.relpath(f))):
        rc, _, err = run_cli(["solve", str(f), "--out", str(out)], capsys)
        assert rc == 2 and "is the input file" in err, err
    assert f.read_bytes() == before


@pytest.mark.parametrize("args, message", [
    (["solve", "{f}", "--out", "{o}/missing/x.g2o"], "directory {o}/missing does not exist"),
    (["solve", "{f}", "--out", "{o}/afile/x.g2o"], "{o}/afile is not a directory"),
    (["solve", "{f}", "--out", "/dev/null"], "is a character device"),
    (["solve", "{f}", "--out", "/proc/posecrb-test.g2o"], "cannot write in /proc"),
    (["fim", "{f}", "--save", "{o}/missing/f"], "directory {o}/missing does not exist"),
    (["fim", "{f}", "--save", "{o}/adir/"], "--save {o}/adir/: is a directory"),
    (["tables", "--datasets", "{f}", "--out", "{o}/afile"], "afile: is a regular file, not a directory"),
    (["tables", "--datasets", "{f}", "--out", "{o}/afile/sub"], "{o}/afile is not a directory"),
    (["experiment", "crlb", "{f}", "--quick", "--out", "{o}/afile"], "afile: is a regular file, not a directory"),
    (["experiment", "crlb", "{f}", "--quick", "--out", "{o}/afile/sub"], "{o}/afile is not a directory"),
    (["experiment", "crlb", "{f}", "--quick", "--plot", "{o}/afile/p.png"], "{o}/afile is not a directory"),
    (["experiment", "crlb", "{f}", "--quick", "--plot", "{o}/p.xyz"],
     "the extension must be .png or .svg or .pdf (got .xyz)"),
    (["experiment", "octagon", "--quick", "--out", "{o}/afile/sub"], "{o}/afile is not a directory"),
    (["experiment", "thesis", "--quick", "--plot", "{o}/adir"], "is a directory"),
    (["datasets", "synth", "grid2d", "--out", "{o}/afile/s.g2o"], "{o}/afile is not a directory"),
    (["regress", "--datasets", "{f}", "--update", "--expected", "{o}/missing/e.json"],
     "directory {o}/missing does not exist"),
])
def test_output_locations_are_checked_before_the_work(tmp_path, capsys, monkeypatch, args, message):
    """A 70 s solve ended in `internal error: FileNotFoundError`: now exit 2 at once."""
    import importlib

    import posecrb.evaluation.regress
    import posecrb.evaluation.tables
    import posecrb.solver.estimate

    sweep = importlib.import_module("posecrb.experiments.crlb_sweep")

    def forbidden(*a, **k):
        pytest.fail("work started before the output location was checked")

    for mod, name in ((posecrb.solver.estimate, "from_solver"), (posecrb.evaluation.tables, "build_rows"),
                      (sweep, "crlb_sweep"), (posecrb.evaluation.regress, "compute_metrics")):
        monkeypatch.setattr(mod, name, forbidden)
    import posecrb.cli.commands.regress as regress_cmd
    import posecrb.solver
    monkeypatch.setattr(posecrb.solver, "solve", forbidden)
    monkeypatch.setattr(regress_cmd, "compute_metrics", forbidden)
    f = write_clean(CASES["crlf_line_ends"], tmp_path)
    (tmp_path / "afile").write_text("keep\n")
    (tmp_path / "adir").mkdir()
    before = sorted(p.name for p in tmp_path.iterdir())
    rc, out, err = run_cli([a.format(f=f, o=tmp_path) for a in args], capsys)
    assert rc == 2 and message.format(o=tmp_path) in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before and (tmp_path / "afile").read_text() == "keep\n"


@pytest.mark.timeout(120)
def test_non_regular_expected_file_is_named_not_read(tmp_path, capsys):
    for path, what in _special_inputs(tmp_path).values():
        rc, out, err = run_cli(["regress", "--expected", path], capsys)
        assert rc == 1 and f"{path}: {what}, not a regular file" in err, err


def test_warning_origin_is_found_by_location_not_by_directory_name(tmp_path):
    """A checkout (or any directory) named ``posecrb`` is not the package: only files inside the
    installed package are named as its modules."""
    import os

    import posecrb.models.paper.fim as paper_fim
    from posecrb.cli import _warning_origin

    assert _warning_origin(paper_fim.__file__) == "posecrb.models.paper.fim"
    outside = tmp_path / "posecrb" / "tests" / "test_x.py"
    assert _warning_origin(str(outside)) == "test_x.py"
    assert _warning_origin(os.path.join("somewhere", "posecrb", "fim.py")) == "fim.py"
