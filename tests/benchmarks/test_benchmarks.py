"""The benchmark suite (benchmarks/): its inputs, the whole-process harness with stand-in peers, the
report on records made here, and the quick run of every benchmark (CI's check that none is broken)."""
from __future__ import annotations

import importlib
import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
HAS_HYPERFINE = shutil.which("hyperfine") is not None
needs_hyperfine = pytest.mark.skipif(not HAS_HYPERFINE, reason="hyperfine is not installed (apt-get install hyperfine)")


def _module(name: str):
    """A module of benchmarks/ (``peers.NAME`` for a peer script), imported as the scripts import them."""
    for directory in (BENCHMARKS, BENCHMARKS / "peers"):
        if str(directory) not in sys.path:
            sys.path.insert(0, str(directory))
    return importlib.import_module(name)


@pytest.fixture
def bench_env(tmp_path, monkeypatch):
    """Grids cached in a scratch directory; the quick suite's inputs."""
    monkeypatch.setenv("POSECRB_BENCH_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("POSECRB_BENCH", "quick")
    return tmp_path


def test_grid_inputs_are_full_lattices_with_every_neighbour_pair(bench_env):
    """A grid's name gives the full lattice of side ceil(N^(1/d)); the file `posecrb datasets synth`
    writes has s^d poses and one edge per pair of lattice neighbours, d s^(d-1) (s - 1) (closed form)."""
    import posecrb

    inputs = _module("suite.inputs")
    assert inputs.grid_spec("grid2d-100000") == (2, 317 ** 2)
    assert inputs.grid_spec("grid3d-20000") == (3, 28 ** 3)
    assert inputs.grid_spec("grid3d-125") == (3, 125)
    assert inputs.grid_spec("intel") is None
    for dim, side in ((2, 8), (3, 4)):
        graph = posecrb.load(inputs.grid_file(dim, side ** dim))
        assert (graph.dim, graph.n, graph.m) == (dim, side ** dim, dim * side ** (dim - 1) * (side - 1))
    with pytest.raises(NotImplementedError):   # asv's "skip": a dataset that is not there
        inputs.path("no-such-dataset")


def test_sesync_output_is_parsed_and_objectives_compared_to_the_printed_digits():
    sesync = _module("peers.sesync_solve")
    out = sesync.parse_sesync("Loaded 3500 measurements between 1728 poses from file x\n"
                              "Value of rounded pose estimates F(x): 52.3482\n"
                              "Value of dual SDP solution F(Y): 52.3482\nFound global optimum!\n")
    assert (out["poses"], out["measurements"], out["objective"], out["certified"]) == (1728, 3500, 52.3482, True)
    assert sesync.parse_sesync("Escaping saddle point\n")["status"] == "saddle point"
    # 52.3482 printed: the true value lies within half a unit of the 6th digit, 5e-5
    assert sesync.printed_tolerance(52.3482) == pytest.approx(5e-5)
    assert sesync.objectives_agree(52.34822729, 52.3482)
    assert not sesync.objectives_agree(52.3490, 52.3482)
    assert not sesync.objectives_agree(math.nan, 52.3482)


@needs_hyperfine
def test_sesync_comparison_with_a_stand_in_peer(bench_env, monkeypatch):
    """A stand-in for SE-Sync's executable prints SE-Sync's lines with the objective of an independent
    `posecrb solve` run: the harness times both, parses both objectives, finds them equal to the
    printed digits, and the report's row and sum come from hyperfine's medians."""
    fake = bench_env / "SE-Sync"
    fake.write_text(textwrap.dedent(f"""\
        #!{sys.executable}
        import json, subprocess, sys
        out = json.loads(subprocess.run([sys.executable, "-m", "posecrb", "solve", sys.argv[1], "--sesync-compat",
                                         "--format", "json"], capture_output=True, text=True, check=True).stdout)
        print(f"Loaded {{out['edges']}} measurements between {{out['poses']}} poses from file {{sys.argv[1]}}")
        print(f"Value of rounded pose estimates F(x): {{out['objective']:.6g}}")
        print("Found global optimum!")
        """))
    fake.chmod(0o755)
    monkeypatch.setenv("SESYNC_BIN", str(fake))
    out = bench_env / "results"
    assert _module("peers.sesync_solve").main(["--quick", "--out", str(out), "grid2d-400", "grid3d-125"]) == 0
    group = json.loads((out / "sesync.json").read_text())
    assert [c["label"] for c in group["comparisons"]] == ["grid2d-400", "grid3d-125"]
    for c in group["comparisons"]:
        assert c["checks"]["agree"] and c["checks"]["sesync"]["certified"] and c["checks"]["posecrb"]["certified"]
        assert c["checks"]["poses"] == c["checks"]["sesync"]["poses"]
        assert {r["command"] for r in c["hyperfine"]["results"]} == {"SE-Sync", "posecrb"}
    report = _module("report")
    text = report.sesync(report.read_groups(out))
    total = sum(r["median"] for c in group["comparisons"] for r in c["hyperfine"]["results"]
                if r["command"] == "posecrb")
    assert "| **sum** |  |  | " in text and report.seconds(total) in text


@needs_hyperfine
def test_a_comparison_that_fails_is_recorded_as_failed_not_timed(tmp_path):
    """A command that fails in its check run, or only in hyperfine's timed runs, leaves a comparison
    marked failed with the reason (no timing), and the report's row says so."""
    import argparse

    harness = _module("harness")
    options = argparse.Namespace(runs=1, warmup=0, out=str(tmp_path / "out"), threads=0, quick=True)
    group = harness.Group("sesync", options)
    marker = tmp_path / "ran-once"
    second_run_fails = ("import os, sys; p = sys.argv[1]; "
                        "sys.exit(1) if os.path.exists(p) else open(p, 'w').close()")
    ok = harness.Command("posecrb", (sys.executable, "-c", "pass"))
    assert group.compare("flaky", [harness.Command("SE-Sync", (sys.executable, "-c", second_run_fails,
                                                               str(marker))), ok]) is None
    broken = harness.Command("SE-Sync", (sys.executable, "-c", "import sys; sys.exit('no such file')"))
    assert group.compare("broken", [broken, ok]) is None
    group.save()
    saved = json.loads((tmp_path / "out" / "sesync.json").read_text())["comparisons"]
    assert saved[0]["failed"] == {"hyperfine": "exit 1"} and "hyperfine" not in saved[0]
    assert saved[1]["failed"] == {"SE-Sync": "exit 1: no such file"}
    report = _module("report")
    rows = report.sesync(report.read_groups(tmp_path / "out")).splitlines()
    assert any(r.startswith("| broken | failed: SE-Sync: exit 1: no such file") for r in rows)


FAKE_MAC = {
    "mac/__init__.py": "",
    "mac/utils/__init__.py": "",
    "mac/utils/graphs.py": "from collections import namedtuple\nEdge = namedtuple('Edge', 'i j weight')\n",
    "mac/solvers.py": textwrap.dedent("""\
        import numpy as np

        class NaiveGreedy:
            def __init__(self, cand):
                self.cand = cand
            def subset(self, k):
                w = np.zeros(len(self.cand))
                w[np.argsort([-e.weight for e in self.cand], kind="stable")[:k]] = 1.0
                return w

        class MAC:
            def __init__(self, fixed, cand, n, fiedler_method=None):
                self.fixed, self.cand, self.n = fixed, cand, n
            def evaluate_objective(self, w):
                # lambda_2 of the weighted Laplacian, dense (the stand-in's own evaluator)
                lap = np.zeros((self.n, self.n))
                for e, x in [(e, 1.0) for e in self.fixed] + list(zip(self.cand, w)):
                    lap[e.i, e.i] += x * e.weight; lap[e.j, e.j] += x * e.weight
                    lap[e.i, e.j] -= x * e.weight; lap[e.j, e.i] -= x * e.weight
                return float(np.linalg.eigvalsh(lap)[1])
            def solve(self, k, w_init, max_iters=20, rounding="nearest", use_cache=True):
                return w_init, w_init, self.evaluate_objective(np.ones(len(self.cand)))
        """),
}


@needs_hyperfine
def test_mac_comparison_poses_the_same_problem_to_both_sides(bench_env, monkeypatch):
    """With a stand-in MAC (a dense lambda_2 evaluator and the naive selection), the problem both sides
    get is the same: posecrb's lambda_2 (rotation weight 2 kappa in 2D) is twice the stand-in's
    evaluation of posecrb's selection, mapped back through the candidates, at K = 20% rounded down."""
    for name, text in FAKE_MAC.items():
        (bench_env / "fake" / name).parent.mkdir(parents=True, exist_ok=True)
        (bench_env / "fake" / name).write_text(text)
    interpreter = bench_env / "mac-python"
    interpreter.write_text(f"#!/bin/sh\nPYTHONPATH={bench_env / 'fake'} exec {sys.executable} \"$@\"\n")
    interpreter.chmod(0o755)
    monkeypatch.setenv("POSECRB_MAC_PYTHON", str(interpreter))
    out = bench_env / "results"
    assert _module("peers.mac_select").main(["--quick", "--out", str(out)]) == 0
    (c,) = json.loads((out / "mac.json").read_text())["comparisons"]
    checks = c["checks"]
    assert checks["budget"] == checks["candidates"] * 20 // 100
    # lambda_2 from Lanczos (posecrb) against a dense eigensolver: agreement to ~1e-9 relative
    assert checks["posecrb_value"] == pytest.approx(2 * checks["lambda2"]["posecrb"], rel=1e-7)
    assert checks["lambda2"]["posecrb"] > checks["lambda2"]["MAC"]   # the naive choice is worse here
    report = _module("report")
    assert c["label"] in report.mac(report.read_groups(out))


def _asv_result(path: Path, benchmarks: dict[str, tuple[list[list[str]], list[float | None]]]) -> None:
    """An asv result file (format 2) of ``benchmarks``: name -> (params, values over their product)."""
    columns = ["result", "params", "version", "started_at", "duration"]
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.parent / "machine.json").write_text(json.dumps({"machine": "test", "cpu": "cpu", "num_cpu": "2"}))
    path.write_text(json.dumps({
        "commit_hash": "0123456789abcdef", "env_name": "existing", "date": 0, "python": "3.11", "version": 2,
        "result_columns": columns,
        "results": {name: [values, [[repr(v) for v in p] for p in params], "v", 1.7e12, 1.0]
                    for name, (params, values) in benchmarks.items()}}))


def _group(out: Path, name: str, comparisons: list[dict]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps({"group": name, "environment": {"date": "2026-01-01T00:00",
                                                                                   "commit": "abc", "runs": 5},
                                                  "comparisons": comparisons}))


def _timed(label: str, medians: dict[str, float], checks: dict | None = None, rss: dict | None = None) -> dict:
    results = [{"command": k, "median": v, "user": v / 2, "system": 0.0} for k, v in medians.items()]
    return {"label": label, "hyperfine": {"results": results}, "checks": checks or {}, "peak_rss": rss or {}}


def test_report_tables_from_records_made_here(tmp_path):
    """The report on result files written here: power laws come back as their exponents, each goal is
    judged by its rule (met, missed), the per-file sums and ratios are the records' own, the fastest
    ordering is named, the figure is drawn, and a table without results says which command makes them."""
    report = _module("report")
    grids = ["grid2d-1000", "grid2d-10000", "grid2d-100000"]
    poses = [32 ** 2, 100 ** 2, 317 ** 2]
    _asv_result(tmp_path / "asv" / "test" / "0123abcd-existing.json", {
        "bench_solve.Solve.time_solve": ([["intel"] + grids], [0.1] + [1e-4 * n ** 1.2 for n in poses]),
        "bench_solve.Solve.peakmem_solve": ([["intel"] + grids], [8e7] + [1e4 * n for n in poses]),
        "bench_select.Select.time_select": ([["intel"], ["tree-greedy", "tree-relax"]], [0.2, 0.1]),
        "bench_models.Orderings.time_fim": ([["grid3d-20000"], ["auto", "amd", "metis"]], [2.0, 5.0, None]),
    })
    hyper = tmp_path / "hyperfine"
    _group(hyper, "startup", [_timed("startup", {"import floor": 0.2, "posecrb --help": 0.2, "posecrb info": 0.4},
                                     {"file": "/data/CSAIL.g2o"})])
    _group(hyper, "goals", [_timed("solve grid2d-100000", {"solve": 12.0}, {"poses": 100489, "certified": True}),
                            _timed("bounds-vertices grid3d-20000", {"bounds": 40.0},
                                   {"poses": 21952, "times": {"parse": 2.0, "fim_logdet": 15.0},
                                    "runs": {"parse": 5, "fim_logdet": 1}})])
    _group(hyper, "sesync", [
        _timed("big", {"SE-Sync": 2.0, "posecrb": 1.0}, {"agree": True, "poses": 10}),     # met: 1.0 <= 2.0
        _timed("small", {"SE-Sync": 0.1, "posecrb": 0.35}, {"agree": True, "poses": 5}),  # 0.1 + 0.2 + 0.1
        _timed("slow", {"SE-Sync": 0.6, "posecrb": 0.7}, {"agree": False, "poses": 7})])  # missed: 0.7 > 0.6
    tables = report.build(report.find_asv(tmp_path / "asv", None), report.read_groups(hyper), tmp_path / "out")

    assert "| 2 | solve | 3 | 1.20 | 1.00 |" in tables["scaling"]
    assert (tmp_path / "out" / "scaling.png").stat().st_size > 10_000
    goals = {row.split(" | ")[0].lstrip("| "): row for row in tables["goals"].splitlines()[2:]}
    assert goals["`posecrb --help` at most 0.25 s"].endswith("| yes |")
    assert goals["`posecrb info` of a small file (CSAIL) at most 0.35 s"].endswith("| **no** |")
    assert "12.00 s" in goals["`solve` of the 2D grid of 100,489 poses at most 15 s, certified"]
    bounds = next(v for k, v in goals.items() if k.startswith("`bounds --estimate vertices`"))
    assert "allowed 39.00 s" in bounds and bounds.endswith("| **no** |")     # 1.5 x (2 x 5 + 15) + 1.5
    sesync = next(v for k, v in goals.items() if k.startswith("every SE-Sync file"))
    assert "2 of 3 files; sum 2.050 s against 2.700 s, **0.76x**" in sesync and sesync.endswith("| **no** |")
    relax = next(v for k, v in goals.items() if k.startswith("the tree objective's"))
    assert "intel 0.100 s against 0.200 s (0.50x)" in relax and relax.endswith("| yes |")
    assert "| **sum** |  |  | 2.700 | 2.050 | **0.76** |" in tables["sesync"]
    assert "| slow |" in tables["sesync"] and "| **no** |" in tables["sesync"]
    assert report.agreement(True, 10.0, 10.0, True) == "yes"
    assert report.agreement(False, 125.698, 125.693515, True) == "**no**: posecrb lower (certified)"
    assert report.agreement(False, 125.698, 125.693515, False) == "**no**: posecrb lower"
    assert report.agreement(False, 125.69, 125.70, True) == "**no**: SE-Sync lower"
    assert report.agreement(False, math.nan, 1.0, True) == "**no**"
    assert "| grid3d-20000 | 2.000 | 5.000 | - | auto |" in tables["orderings"]
    assert "| intel | - | 0.100 |" in tables["inprocess"]
    assert tables["gtsam"].startswith("No results") and "gtsam_marginals.py" in tables["gtsam"]
    assert "| in-process suite (asv) |" in tables["provenance"] and "| 0123456 |" in tables["provenance"]

    text = report.page(tables, report.TEMPLATE.read_text())
    assert "<!-- table:" not in text
    for name, table in tables.items():
        assert table.replace("](scaling.png)", "](figures/scaling.png)") in text, name
    assert "](figures/scaling.png)" in text and "](scaling.png)" not in text


def test_report_page_needs_a_marker_for_every_table_and_no_other():
    """The performance page is written only from a template whose markers are exactly the report's
    tables: a table without its marker would vanish from the page, a stray marker would stay in it."""
    report = _module("report")
    tables = {"goals": "| a |", "sesync": "| b |"}
    assert report.page(tables, "# P\n<!-- table: goals -->\ntext\n<!-- table: sesync -->") == \
        "# P\n| a |\ntext\n| b |\n"
    with pytest.raises(ValueError, match="sesync"):
        report.page(tables, "<!-- table: goals -->")
    with pytest.raises(ValueError, match="mac"):
        report.page(tables, "<!-- table: goals -->\n<!-- table: sesync -->\n<!-- table: mac -->")


FLOP_LIMIT = "bench_models.FimFlopLimit.track_"


@pytest.mark.parametrize(("seconds", "verdict"), [(4.5, "| yes |"), (6.0, "| **no** |"), (None, "| - | - |")])
def test_report_flop_limit_goal_from_stored_records(tmp_path, seconds, verdict):
    """The FIM log-det's cost goal from a stored record of FimFlopLimit: the time against the limit
    (Gflop / GF/s) and their ratio, judged against 1.6x (met at 1.45x, missed at 1.94x); a
    benchmark that was skipped (no values) or did not run leaves "-"."""
    report = _module("report")
    gflop, rate = 341.0, 110.0                        # limit 3.1 s
    figures = {"seconds": seconds, "gflop": gflop, "dgemm_rate": rate,
               "limit_ratio": None if seconds is None else seconds * rate / gflop}
    _asv_result(tmp_path / "asv" / "test" / "0123abcd-existing.json",
                {FLOP_LIMIT + what: ([["grid3d-20000"]], [value]) for what, value in figures.items()})
    tables = report.build(report.find_asv(tmp_path / "asv", None), {}, None)
    (row,) = [r for r in tables["goals"].splitlines() if r.startswith("| FIM log-det")]
    assert row.startswith("| FIM log-det of the 3D grid of 21,952 poses at most 1.6x the flop limit (median of 3) |")
    assert row.endswith(verdict)
    if seconds is not None:
        assert f"{seconds:.3f} s against 341 Gflop / 110.0 GF/s = 3.100 s: **{seconds / 3.1:.2f}x**" in row
    assert report.flop_limit_goal(report.AsvRun(None))[1:] == ["-", "-"]


@pytest.mark.parametrize("ordering", ["amd", "metis"])
def test_fim_flop_count_is_the_column_counts_of_a_dense_factor(bench_env, ordering):
    """The benchmark's flop count (CHOLMOD's own ``Common->fl`` through ctypes, with the ordering the
    FimResult reports, the pose-level one rebuilt from its matrix) equals the closed form sum_j c_j^2
    of the column counts c_j of a dense Cholesky factor of a matrix with the FIM's stored pattern and
    random values (exact zeros stay exact outside the symbolic pattern), permuted by the ordering
    posecrb's own analysis of that FIM uses."""
    import numpy as np
    import scipy.sparse as sp

    import posecrb
    from posecrb.models.paper.fim import fim_symbolic_choice, paper_fim

    inputs, bench_models = _module("suite.inputs"), _module("suite.bench_models")
    graph = posecrb.load(inputs.path(inputs.GRID_3D_SMALL))
    res = posecrb.fim(graph, estimate="vertices", ordering=ordering)
    try:
        flops = bench_models.factor_flops(res)
    except NotImplementedError as exc:     # not CHOLMOD 3.0.x: the benchmark skips too
        pytest.skip(str(exc))
    fim = paper_fim(graph, graph.vertex_rot, graph.vertex_trans, graph.anchor_index(None))
    assert (fim.matrix != res.matrix).nnz == 0
    perm = fim_symbolic_choice(fim, ordering)[0].permutation
    lower = sp.tril(fim.matrix, k=-1).tocoo()
    dense = np.zeros(fim.matrix.shape)
    dense[lower.row, lower.col] = np.random.default_rng(0).uniform(-1.0, 1.0, lower.nnz)
    dense += dense.T
    dense[np.diag_indices_from(dense)] = np.abs(dense).sum(axis=1) + 1.0     # diagonally dominant: SPD
    counts = np.count_nonzero(np.linalg.cholesky(dense[np.ix_(perm, perm)]), axis=0).astype(float)
    assert flops == np.sum(counts ** 2)


def test_report_fit_exponent_against_closed_forms():
    report = _module("report")
    sizes = [1e3, 1e4, 1e5]
    assert report.fit_exponent(sizes, [3 * n ** 1.5 for n in sizes]) == pytest.approx(1.5, rel=1e-12)
    assert math.isnan(report.fit_exponent([1e3], [1.0]))
    assert math.isnan(report.fit_exponent(sizes, [None, None, 2.0]))


@pytest.mark.parametrize("script", ["commands.py", "report.py", "run.py", "peers/sesync_solve.py",
                                    "peers/gtsam_marginals.py", "peers/mac_select.py"])
def test_every_script_answers_help(script):
    run = subprocess.run([sys.executable, str(BENCHMARKS / script), "--help"], capture_output=True, text=True,
                         timeout=120, cwd=BENCHMARKS.parent)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "usage:" in run.stdout.lower()


def test_benchmarks_import_only_public_names():
    """What a benchmark needs is public (``posecrb.__all__``) or it is not benchmarked: no
    ``posecrb.<module>`` import anywhere under benchmarks/."""
    import posecrb

    offenders = []
    for path in BENCHMARKS.rglob("*.py"):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            stripped = line.strip()
            if stripped.startswith(("from posecrb.", "import posecrb.")):
                offenders.append(f"{path.name}:{number}: {stripped}")
            if stripped.startswith("from posecrb import "):
                names = [n.strip() for n in stripped[len("from posecrb import "):].split(",")]
                offenders += [f"{path.name}:{number}: {n}" for n in names if n not in posecrb.__all__]
            offenders += [f"{path.name}:{number}: posecrb.{n}" for n in _attributes(stripped)
                          if n not in posecrb.__all__]
    assert not offenders


def _attributes(line: str) -> list[str]:
    import re

    return re.findall(r"\bposecrb\.([A-Za-z_]\w*)\(", line)


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("asv") is None, reason="asv is not installed (the dev extra)")
def test_bench_quick_runs_every_benchmark(tmp_path):
    """`make bench-quick`: every asv benchmark once on small inputs, every whole-process comparison
    whose programs are here, and the report; exit 0. CI runs this, so a broken benchmark fails it."""
    env = {**os.environ, "POSECRB_BENCH_CACHE": os.environ.get("POSECRB_BENCH_CACHE",
                                                               str(Path.home() / ".cache" / "posecrb-bench"))}
    run = subprocess.run([sys.executable, str(BENCHMARKS / "run.py"), "--quick", "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=600, env=env, cwd=BENCHMARKS.parent)
    assert run.returncode == 0, (run.stdout + run.stderr)[-4000:]
    assert (tmp_path / "report" / "goals.md").is_file()
    if HAS_HYPERFINE:
        assert {p.stem for p in (tmp_path / "hyperfine").glob("*.json")} >= {"startup", "goals", "timeline",
                                                                             "threads"}


@pytest.mark.skipif(importlib.util.find_spec("asv") is None, reason="asv is not installed (the dev extra)")
def test_a_broken_benchmark_fails_the_quick_run(tmp_path):
    """The quick run's exit status: a benchmark that raises makes asv, so run.py, exit non-zero."""
    suite = tmp_path / "broken"
    suite.mkdir()
    (suite / "__init__.py").write_text("")
    (suite / "bench_broken.py").write_text("def time_broken():\n    raise RuntimeError('broken')\n")
    config = tmp_path / "asv.conf.json"
    config.write_text(json.dumps({"version": 1, "project": "posecrb", "repo": str(BENCHMARKS.parent),
                                  "environment_type": "existing", "benchmark_dir": "broken",
                                  "results_dir": str(tmp_path / "results"), "env_dir": str(tmp_path / "env"),
                                  "html_dir": str(tmp_path / "html")}))
    argv = _module("run").asv_argv(True, None, config)
    subprocess.run([*argv[:5], "machine", "--yes"], capture_output=True, check=False)
    run = subprocess.run(argv, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode != 0
    assert "broken" in run.stdout + run.stderr


def test_inputs_dimension_of_a_dataset_from_its_lines(tmp_path, monkeypatch):
    inputs = _module("suite.inputs")
    (tmp_path / "flat.g2o").write_text("VERTEX_SE2 0 0 0 0\n")
    (tmp_path / "space.g2o").write_text("EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1" + " 1" * 21 + "\n")
    monkeypatch.setenv("POSECRB_DATA", str(tmp_path))
    assert (inputs.dimension("flat"), inputs.dimension("space")) == (2, 3)
    assert inputs.lattice_side(100000, 2) == 317 and inputs.lattice_side(1000, 3) == 10


def test_alternating_rounds_merge_one_run_per_call_in_reversed_orders(monkeypatch):
    """``alternating`` calls hyperfine once per round with one run of each command, the order reversed
    every other round, and merges the runs: every time kept, the median of them all."""
    import argparse

    harness = _module("harness")
    calls = []

    def fake(commands, options):
        calls.append(([c.label for c in commands], options.runs, options.warmup))
        k = len(calls)
        return {"results": [{"command": c.label, "times": [10.0 * k + i]} for i, c in enumerate(commands)]}

    monkeypatch.setattr(harness, "hyperfine", fake)
    a, b = harness.Command("now", ("true",)), harness.Command("before", ("true",))
    out = harness.alternating([a, b], argparse.Namespace(runs=3, warmup=2))
    assert calls == [(["now", "before"], 1, 2), (["before", "now"], 1, 0), (["now", "before"], 1, 0)]
    now, before = out["results"]
    assert now["command"] == "now" and now["times"] == [10.0, 21.0, 30.0] and now["median"] == 21.0
    assert before["times"] == [11.0, 20.0, 31.0] and before["median"] == 20.0 and out["alternated"] == 3


def test_stage_samples_alternate_the_commands_and_keep_every_reported_time(monkeypatch):
    """The parse stage's samples: the check run's JSON, then one untimed run of each command per
    round in alternating order; a failed run or one without the stage adds nothing."""
    import json

    commands_module, harness = _module("commands"), _module("harness")
    order = []
    replies = {"now": iter([0.3, 0.2, None]), "before": iter([1.1, "fail", 0.9])}

    def fake_run(cmd, timeout=None):
        order.append(cmd.label)
        value = next(replies[cmd.label])
        if value == "fail":
            return harness.CheckRun(1, "", "boom", None)
        times = {} if value is None else {"parse": value}
        return harness.CheckRun(0, json.dumps({"times": times}), "", None)

    monkeypatch.setattr(harness, "check_run", fake_run)
    now, before = harness.Command("now", ("true",)), harness.Command("before", ("true",))
    entry = {"outputs": {"now": harness.CheckRun(0, json.dumps({"times": {"parse": 0.25}}), "", None),
                         "before": harness.CheckRun(0, "not json", "", None)}}
    samples = commands_module.stage_samples(entry, [now, before], "parse", 3)
    assert order == ["now", "before", "before", "now", "now", "before"]
    assert samples == {"now": [0.25, 0.3, 0.2], "before": [1.1, 0.9]}
    assert commands_module.median_or_none(samples["now"]) == 0.25
    assert commands_module.median_or_none([]) is None


def test_report_baseline_judges_the_cost_goals(tmp_path):
    """The baseline table from records made here: bounds against the allowance from solve, select's
    exponent over the grids (a closed-form power law), its certified ratios, the parse speed-up."""
    report = _module("report")

    def timed(**medians):
        return {"results": [{"command": k.replace("_", " "), "median": v, "times": [v]} for k, v in medians.items()]}

    comps = [
        {"label": "bounds intel", "hyperfine": timed(bounds=0.5, bounds_before=1.3, solve=0.4), "checks": {}},
        {"label": "bounds torus3D", "hyperfine": timed(bounds=2.0, bounds_before=2.5, solve=1.0), "checks": {}},
    ]
    for n in (10_000, 30_000, 100_000):            # time = c n^1.1
        comps.append({"label": f"select grid2d-{n}", "hyperfine": timed(select=1e-4 * n ** 1.1, select_before=1.0),
                      "checks": {"candidates": n, "ratio": 0.80, "ratio_before": 0.805, "method": "rounds"}})
    comps.append({"label": "parse grid2d-100000", "hyperfine": timed(info=0.5, info_before=1.2),
                  "checks": {"parse": 0.2, "parse_before": 1.0, "parse_runs": 4}})
    text = report.baseline({"baseline": {"environment": {"baseline_commit": "65df671"}, "comparisons": comps}})
    assert text.startswith("Against 65df671")
    goals = {line.split("|")[1].strip(): line.split("|")[-2].strip() for line in text.splitlines()
             if line.startswith("| ") and line.count("|") == 4}
    assert goals["`bounds` at most the larger of `solve` + 0.3 s and 1.3x `solve`"] == "**no**"   # 2.0 > 1.3
    exponent = [line for line in text.splitlines() if "exponent in the candidates" in line][0]
    assert "| 1.10 |" in exponent and exponent.endswith("| yes |")
    assert goals["parsing the 2D grid at least 4x faster"] == "yes"
    assert "| parse grid2d-100000 (in-process, median of 4) | 1.000 | 0.200 |" in text
    assert goals["certified ratio at least the earlier greedy's minus 0.01"] == "yes"


def test_select_leaves_out_exactly_the_datasets_too_small_for_its_budget():
    """Select's budget of 20% selects at least one candidate edge of every SE-Sync dataset it runs
    on, and every dataset it leaves out is one where 20% rounds down to none (which select refuses)."""
    from posecrb import load
    from posecrb.selection.budget import split_edges

    inputs, bench_select = _module("suite.inputs"), _module("suite.bench_select")
    checked = 0
    for name in inputs.SESYNC_DATASETS:
        try:
            path = inputs.path(name)
        except NotImplementedError:
            continue
        candidates = split_edges(load(path)).candidates.size
        too_few = math.floor(0.2 * candidates) < 1   # a fraction rounds down
        assert too_few == (name in bench_select.TOO_FEW_CANDIDATES), (name, candidates)
        checked += 1
    if checked == 0:
        pytest.skip("no SE-Sync dataset here (POSECRB_DATA)")


def test_a_baseline_command_imports_the_earlier_checkout_from_this_one(tmp_path):
    """The baseline group runs the earlier checkout by PYTHONPATH while the working directory is this
    checkout; ``python -m`` and ``-c`` put the working directory first, so without the harness's
    safe-path setting the "before" program would be this checkout again (both sides the same code)."""
    harness = _module("harness")
    (tmp_path / "posecrb").mkdir()
    (tmp_path / "posecrb" / "__init__.py").write_text("")
    assert harness.imported_posecrb({"PYTHONPATH": str(tmp_path)}) == (tmp_path / "posecrb").resolve()
    assert harness.imported_posecrb({}) == BENCHMARKS.parent / "posecrb"


def test_report_says_whether_the_library_is_the_same_at_every_commit_of_a_run():
    """A run spanning commits is labelled by whether posecrb/ differs between them (git's own diff)."""
    report = _module("report")
    head = subprocess.run(["git", "-C", str(BENCHMARKS.parent), "rev-parse", "--short=7", "HEAD"],
                          capture_output=True, text=True, check=False).stdout.strip()
    first = subprocess.run(["git", "-C", str(BENCHMARKS.parent), "rev-list", "--max-parents=0", "--abbrev-commit",
                            "--abbrev=7", "HEAD"], capture_output=True, text=True, check=False).stdout.split()
    if not head or not first:
        pytest.skip("not a git checkout with its history")
    assert "is the same" in report.library_identity([head, head])
    assert "differs" in report.library_identity([first[0], head])


def test_the_performance_page_is_the_reports_and_fits_300_lines():
    """docs/performance.md is the report's page of the present template (every prose line of
    benchmarks/performance.md.in in it, in order, no marker left) and at most 300 lines."""
    report = _module("report")
    page = (BENCHMARKS.parent / "docs" / "performance.md").read_text().splitlines()
    assert len(page) <= 300
    assert not any(line.startswith("<!-- table: ") for line in page)
    position = 0
    for line in report.TEMPLATE.read_text().splitlines():
        if line.startswith("<!-- table: "):
            continue
        assert line in page[position:], f"the page lacks the template's line {line!r}: run make bench-report"
        position = page.index(line, position) + 1


def test_report_writes_no_page_without_results(tmp_path):
    """`make bench-report` on a machine without the suite's results fails and leaves the page as it
    was: a page of "No results" lines would replace the last run's figures."""
    page = tmp_path / "performance.md"
    page.write_text("the last run's page\n")
    proc = subprocess.run([sys.executable, str(BENCHMARKS / "report.py"), "--asv", str(tmp_path / "none"),
                           "--hyperfine", str(tmp_path / "none"), "--out", str(tmp_path / "out"), "--page", str(page)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 1 and "run make bench first" in proc.stderr
    assert page.read_text() == "the last run's page\n"
