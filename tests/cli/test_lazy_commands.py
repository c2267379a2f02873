"""The lazy command group: `posecrb --help` renders the command list from a static table without
importing any command module, and that table says what the commands themselves say."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import click
import numpy as np
import pytest

import posecrb
from posecrb.cli import _EXPLICIT_SHORT_HELP, COMMANDS, cli
from posecrb.io import write_g2o

from ..helpers import make_random_graph, random_pose_graph


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_table_matches_each_commands_own_help(name):
    command = cli.get_command(click.Context(cli), name)
    assert command is not None and command.name == name
    for limit in (20, 45, 80, 200):     # every width click may render at
        table = click.Command(name, short_help=COMMANDS[name][1] if name in _EXPLICIT_SHORT_HELP else None,
                              help=None if name in _EXPLICIT_SHORT_HELP else COMMANDS[name][1])
        assert table.get_short_help_str(limit) == command.get_short_help_str(limit)


def test_every_command_module_is_in_the_table():
    from importlib.resources import files

    modules = {p.name[:-3] for p in files("posecrb.cli.commands").iterdir()
               if p.name.endswith(".py") and not p.name.startswith("_")}
    assert modules == {module for module, _ in COMMANDS.values()}


def test_help_imports_no_command_module_and_no_numerics():
    code = ("import sys; from posecrb.cli import main; rc = main(['--help']); "
            "bad = sorted(m for m in sys.modules if m.startswith(('posecrb.cli.commands.', 'numpy', 'scipy', "
            "'numba', 'sksparse'))); print(rc, bad, file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stderr.strip().splitlines()[-1] == "0 []"


# ---- whole-process start-up: what each command imports --------------------------------------------

# A hand-written 2D g2o file: a triangle (ids 0, 1, 2), a separate edge (ids 5, 7) and an isolated
# vertex (id 9), so three components, four edges and six poses, known without running posecrb.
_SMALL_G2O = """\
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1 0 0
VERTEX_SE2 2 1 1 0
VERTEX_SE2 5 4 0 0
VERTEX_SE2 7 5 0 0
VERTEX_SE2 9 7 7 0
EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000
EDGE_SE2 1 2 0 1 1.5707963267948966 100 0 0 100 0 1000
EDGE_SE2 2 0 -1 0 -1.5707963267948966 100 0 0 100 0 1000
EDGE_SE2 5 7 1 0 0 100 0 0 100 0 1000
"""

# Run ``python -m posecrb ARGS`` exactly as a user does (runpy, __main__), then print the modules
# that were imported, as JSON, on the last line of stderr (atexit runs after sys.exit).
_RUN_AND_LIST = ("import atexit, json, runpy, sys; "
                 "atexit.register(lambda: print('MODULES ' + json.dumps(sorted(sys.modules)), file=sys.stderr)); "
                 "sys.argv = ['posecrb', *sys.argv[1:]]; runpy.run_module('posecrb', run_name='__main__')")


def _run(args: list[str], listing: bool = False) -> tuple[subprocess.CompletedProcess, set[str]]:
    argv = [sys.executable, "-c", _RUN_AND_LIST, *args] if listing else [sys.executable, "-m", "posecrb", *args]
    out = subprocess.run(argv, capture_output=True, text=True, check=False, timeout=300)
    modules: set[str] = set()
    if listing:
        last = [line for line in out.stderr.splitlines() if line.startswith("MODULES ")]
        assert last, out.stderr
        modules = set(json.loads(last[-1][len("MODULES "):]))
    return out, modules


def _loaded(modules: set[str], *packages: str) -> list[str]:
    """The packages among ``packages`` of which some module was imported."""
    return sorted(p for p in packages if any(m == p or m.startswith(p + ".") for m in modules))


@pytest.fixture(scope="module")
def small_g2o(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("lazy") / "small.g2o"
    path.write_text(_SMALL_G2O)
    return path


@pytest.fixture(scope="module")
def solvable_g2o(tmp_path_factory) -> Path:
    """A connected random 3D graph (3D: the rotation weights take Bessel function ratios; solve needs CHOLMOD)."""
    path = tmp_path_factory.mktemp("lazy") / "solvable.g2o"
    write_g2o(make_random_graph(np.random.default_rng(11), n=12, extra=8, dim=3, sparse_ids=False), path)
    return path


def test_python_m_help_imports_no_numerics():
    out, modules = _run(["--help"], listing=True)
    assert out.returncode == 0, out.stderr
    assert "Commands:" in out.stdout and "solve" in out.stdout
    assert _loaded(modules, "numpy", "scipy", "numba", "sksparse", "rich", "pandas") == []
    assert not any(m.startswith("posecrb.cli.commands.") for m in modules)


def test_python_m_version():
    out, _ = _run(["--version"])
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith(f"posecrb {posecrb.__version__} from ")


def test_info_imports_numpy_but_no_scipy(small_g2o):
    out, modules = _run(["info", str(small_g2o), "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    row = json.loads(out.stdout)
    assert (row["poses"], row["edges"], row["components"], row["component_sizes"]) == (6, 4, 3, [3, 2, 1])
    assert (row["id_min"], row["id_max"], row["degree_min"], row["degree_max"]) == (0, 9, 0, 2)
    assert _loaded(modules, "numpy") == ["numpy"]
    assert _loaded(modules, "scipy", "numba", "sksparse", "rich", "pandas", "matplotlib", "dask") == []


def test_info_table_works_from_python_m(small_g2o):
    out, _ = _run(["info", str(small_g2o)])
    assert out.returncode == 0, out.stderr
    assert "small" in out.stdout and "components" in out.stdout
    lines = [line for line in out.stdout.splitlines() if "components" in line and "sizes" not in line]
    assert lines and lines[0].split()[-2] == "3", out.stdout


def test_solve_json_imports_only_what_it_needs(solvable_g2o):
    out, modules = _run(["solve", str(solvable_g2o), "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    row = json.loads(out.stdout)
    assert row["certified"] is True and row["poses"] == 12
    assert _loaded(modules, "numba", "rich", "pandas", "matplotlib", "dask") == []
    assert _loaded(modules, "numpy", "scipy.sparse", "sksparse") == ["numpy", "scipy.sparse", "sksparse"]
    # The certificate's eigenvalue estimate is numpy-only: ARPACK would load scipy.linalg (~45 ms).
    assert _loaded(modules, "scipy.sparse.linalg", "scipy.linalg") == []


@pytest.mark.parametrize("command", ["fim", "bounds", "crlb"])
def test_small_inversions_import_no_numba(solvable_g2o, command):
    """The log-det's accuracy bound and the CRLB invert small factors with numpy and LAPACK
    (posecrb.linalg.selinv's block kernels): numba's import and first call would cost more."""
    out, modules = _run([command, str(solvable_g2o), "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    row = json.loads(out.stdout)
    assert row["poses"] == 12
    assert _loaded(modules, "numba") == []


def test_bounds_loads_no_graph_or_special_function_module(solvable_g2o):
    """The graph lower bound of lambda_min(L_w) (spanning trees: scipy.sparse.csgraph, which loads
    scipy.linalg) is computed only where it could exceed the certified one, and eq. (59)'s Bessel
    ratios need no scipy.special: neither is imported by a 3D ``bounds``."""
    out, modules = _run(["bounds", str(solvable_g2o), "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["gap_bound"] > 0
    assert _loaded(modules, "scipy.sparse.csgraph", "scipy.special") == []


def test_anchored_sed_logdet_of_a_large_grid_imports_no_numba(tmp_path):
    """The log-det's accuracy bound of a factor that the selected inversion would take through the
    compiled kernels (the SE(d) FIM of the 3D grid of 1,728 poses) comes from the lambda_min tier
    (posecrb.linalg.accuracy): no numba, and the exact tier's status."""
    from posecrb.linalg import selinv
    from posecrb.linalg.ordering import ordered_symbolic
    from posecrb.models.sed.fim import sed_fim
    from posecrb.sim.generators import grid

    g = grid(3, 12)
    path = tmp_path / "grid3d.g2o"
    write_g2o(g, path)
    fim = sed_fim(g, g.vertex_rot, g.vertex_trans)
    dofs = (np.arange(1, g.n)[:, None] * 6 + np.arange(6)).ravel()
    free = fim.matrix[dofs][:, dofs].tocsc()
    symbolic, _ = ordered_symbolic(free, "auto", dim=3, poses=g.n, matrix="fim",
                                   pose_of_row=np.repeat(np.arange(g.n - 1), 6), n_poses=g.n - 1)
    lower = symbolic.factor(free).L().tocsc()
    indptr = lower.indptr.astype(np.int64)
    assert selinv.inversion_steps(indptr, selinv.supernode_bounds(indptr, lower.indices)) > selinv._BLOCK_MAX_STEPS
    out, modules = _run(["fim", str(path), "--model", "sed", "--anchor", "0", "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    row = json.loads(out.stdout)
    assert row["poses"] == 1728 and "logdet_status" not in row
    assert _loaded(modules, "numba") == []


def test_select_fiedler_imports_no_numba(tmp_path):
    """lambda_2 needs no compiled kernel: numba (0.2-0.5 s) and scipy's graph and eigen modules stay
    unloaded (320 poses: the sparse path, Lanczos on the pseudo-inverse). Neither does the tree
    objective's greedy on a graph this small (posecrb.selection.greedy.pick_engine: whole-factor solves)."""
    path = tmp_path / "chain.g2o"
    write_g2o(random_pose_graph(320, 2, np.random.default_rng(5), loop_closures=60)[0], path)
    out, modules = _run(["select", str(path), "--budget", "20%", "--objective", "fiedler", "--method", "relax",
                         "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["fixed"]["added_for_connectivity"] == []
    assert _loaded(modules, "numba", "scipy.sparse.csgraph", "scipy.sparse.linalg", "scipy.linalg") == []
    out, modules = _run(["select", str(path), "--budget", "2", "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["stats"]["engine"] == "cholmod"
    assert _loaded(modules, "numba") == []


def test_tables_json_off_a_terminal_loads_no_rich(solvable_g2o):
    out, modules = _run(["tables", "--datasets", str(solvable_g2o), "--table", "2", "--format", "json",
                         "--repeat", "1"], listing=True)
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)["rows"]
    assert [(r["dataset"], r["status"], r["poses"]) for r in rows] == [("solvable", "ok", 12)]
    assert _loaded(modules, "rich", "pandas", "matplotlib", "dask") == []


def test_cli_defers_numpy_modules_it_never_uses_and_they_still_work(solvable_g2o):
    """scipy's array-API layer touches every name in numpy.__all__; the CLI defers the unused
    submodules, which stay unexecuted through a whole solve and load normally on first use."""
    code = ("import sys, importlib.util; from posecrb.cli import main; "
            f"rc = main(['solve', {str(solvable_g2o)!r}, '--format', 'json']); "
            "names = ('numpy.f2py', 'numpy.testing', 'numpy.polynomial', 'numpy.ma'); "
            "lazy = [type(sys.modules[n]).__name__ for n in names]; "
            "import numpy as np; np.testing.assert_allclose(np.sqrt(2.0) ** 2, 2.0); "
            "masked = float(np.ma.masked_invalid([1.0, np.nan]).sum()); "
            "coef = np.polynomial.polynomial.polyfit([0.0, 1.0, 2.0], [1.0, 3.0, 5.0], 1); "
            "f2py = callable(np.f2py.run_main); ok = [type(sys.modules[n]).__name__ for n in names]; "
            "print(rc, lazy, ok, [round(float(c), 9) for c in coef], f2py, masked, file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    rc, rest = out.stderr.strip().splitlines()[-1].split(" ", 1)
    assert rc == "0"
    assert rest == ("['_LazyModule', '_LazyModule', '_LazyModule', '_LazyModule'] "
                    "['module', 'module', 'module', 'module'] [1.0, 2.0] True 1.0")


def test_weak_3d_rotations_leave_numpy_polynomial_deferred(tmp_path):
    """A 3D file whose rotation concentrations are below omega's series switch (kappa = 0.01):
    reading and solving it evaluates that series, which must not execute numpy.polynomial."""
    path = tmp_path / "weak3d.g2o"
    write_g2o(random_pose_graph(12, 3, np.random.default_rng(3), kappa=0.01)[0], path)
    code = ("import sys; from posecrb.cli import main; "
            f"rc = main(['solve', {str(path)!r}, '--format', 'json']); "
            "from posecrb.core.noise import omega, _SERIES_BELOW; "
            "small = float(omega(0.01)) > 0 and 0.01 < _SERIES_BELOW; "
            "print(rc, small, type(sys.modules['numpy.polynomial']).__name__, file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    assert out.stderr.strip().splitlines()[-1] == "0 True _LazyModule"


def test_library_import_changes_no_import_machinery():
    """Only the CLI's main() defers modules; importing posecrb as a library leaves sys.meta_path alone."""
    code = ("import sys; before = [type(f).__name__ for f in sys.meta_path]; import posecrb, posecrb.solver, "
            "posecrb.cli; print(before == [type(f).__name__ for f in sys.meta_path], file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    assert out.stderr.strip().splitlines()[-1] == "True"


def test_option_choices_are_the_librarys():
    """Every choice is defined once (posecrb.core.choices): the library's tuples are those tuples, and
    every click.Choice of the command tree (and every keyword of an InputFile) offers one of them."""
    from posecrb.cli.paths import InputFile
    from posecrb.core import choices, noise
    from posecrb.io import reader
    from posecrb.linalg import ordering
    from posecrb.models import paper, sed
    from posecrb.selection import objectives, select
    from posecrb.sim import generators, sampling

    assert noise.ROTATION_WEIGHTS is choices.ROTATION_WEIGHTS and ordering.ORDERINGS is choices.ORDERINGS
    assert paper.fim.FIM_VARIANTS is choices.FIM_VARIANTS and sed.frames.FRAMES is choices.FRAMES
    assert objectives.OBJECTIVES is choices.OBJECTIVES and select.METHODS is choices.METHODS
    assert reader.QUATERNION_MODES is choices.QUATERNION_MODES and generators.KINDS is choices.SYNTH_KINDS
    assert sampling.NOISE_SCALES is choices.NOISE_SCALES
    defined = {v for k, v in vars(choices).items() if k.isupper() and isinstance(v, tuple)}

    def walk(command):
        if isinstance(command, click.Group):
            for name in command.list_commands(None):
                yield from walk(command.get_command(None, name))
            return
        for p in command.params:
            if isinstance(p.type, click.Choice):
                yield command.name, p.name, tuple(p.type.choices)
            if isinstance(p.type, InputFile) and p.type.keywords:
                yield command.name, p.name, p.type.keywords

    seen = list(walk(cli))
    assert len(seen) > 15
    assert [s for s in seen if s[2] not in defined] == []


def test_solve_of_weak_rotations_imports_no_bessel_functions(tmp_path):
    """The reader checks eq. (59)'s rotation weight of every 3D edge with kappa < 1e-3 (as in
    parking-garage.g2o); it comes from a power series there, so solve still does not pay for
    scipy.special's import."""
    from dataclasses import replace

    g = make_random_graph(np.random.default_rng(12), n=12, extra=8, dim=3, sparse_ids=False)
    info = g.info.copy()
    info[0, 3:, 3:] *= 1e-5   # kappa of edge 0 from [5, 50] to below 1e-3
    path = tmp_path / "weak.g2o"
    write_g2o(replace(g, info=info), path)
    out, modules = _run(["solve", str(path), "--format", "json"], listing=True)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["certified"] is True
    kappa = 3 / (2 * np.trace(np.linalg.inv(info[0, 3:, 3:])))
    assert kappa < 1e-3
    assert "scipy.sparse" in modules and _loaded(modules, "scipy.special") == []


def test_program_entry_freezes_the_heap_after_the_command_and_exits_with_its_code(monkeypatch):
    """``posecrb.cli.run`` (the ``posecrb`` command and ``python -m posecrb``): the command runs first,
    then every live object moves to the collector's permanent generation (the interpreter's shutdown
    collections skip them), then the process exits with the command's code."""
    import posecrb.cli as cli

    calls: list[str] = []
    monkeypatch.setattr(cli, "main", lambda: calls.append("main") or 3)
    monkeypatch.setattr(cli.gc, "freeze", lambda: calls.append("freeze"))
    with pytest.raises(SystemExit) as exc:
        cli.run()
    assert exc.value.code == 3
    assert calls == ["main", "freeze"]


def test_python_dash_m_and_the_console_script_run_the_program_entry():
    """Both ways a user starts posecrb go through ``run`` (a usage error is still exit 2)."""
    import tomllib

    pyproject = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    assert pyproject["project"]["scripts"]["posecrb"] == "posecrb.cli:run"
    out, _ = _run(["--no-such-option"])
    assert out.returncode == 2
    marked = subprocess.run(
        [sys.executable, "-c", "import gc, runpy, sys; gc.freeze = lambda: print('FROZEN', file=sys.stderr); "
         "sys.argv = ['posecrb', '--version']; runpy.run_module('posecrb', run_name='__main__')"],
        capture_output=True, text=True, check=False, timeout=300)
    assert marked.returncode == 0 and marked.stderr.strip().endswith("FROZEN"), marked.stderr
