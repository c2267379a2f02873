"""The benchmark scripts' own code paths that no measurement run exercises in CI."""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _module(name: str):
    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    return importlib.import_module(name)


def _random_spd(seed: int):
    """A random sparse SPD matrix of 60 rows (condition number ~10^2), its dense log-det (numpy's
    slogdet, the reference) and the pose of each row (ten poses of 6 rows), for the pose ordering."""
    import numpy as np
    import scipy.sparse as sp

    rng = np.random.default_rng(seed)
    n = 60
    b = sp.random(n, n, density=0.08, random_state=rng)
    a = (b @ b.T + sp.diags(rng.uniform(1.0, 2.0, n))).tocsc()
    sign, ref = np.linalg.slogdet(a.toarray())
    assert sign == 1
    return a, float(ref), np.repeat(np.arange(n // 6), 6)


def test_scaling_plot_and_markdown_write_from_records(tmp_path):
    scaling = _module("scaling")
    records = [{"dim": d, "poses": n, "edges": 2 * n, "command": c, "wall": 0.01 * n ** 1.1, "rss": 1e5 * n,
                "status": "ok", "phases": "parse 0.01", "inprocess": 0.01 * n}
               for d in (2, 3) for n in (100, 1000, 10000) for c in ("solve", "fim")]
    out = tmp_path / "scaling.png"
    scaling.plot(records, str(out))
    assert out.stat().st_size > 1000
    table = scaling.markdown(records, "")
    assert table.count("\n| 3 | 10,000 |") == 2


def test_scaling_phases_count_every_stage_the_command_times():
    """The in-process sum must cover every stage a command reports: a stage left out (the log-det's
    accuracy bound, the CRLB's accuracy estimate) hides most of the time on large grids."""
    import json

    scaling = _module("scaling")
    reported = {
        "fim": {"parse": 1.0, "fim_build": 2.0, "fim_logdet": 3.0, "logdet_accuracy": 20.0},
        "bounds-vertices": {"parse": 1.0, "laplacians": 0.5, "lb": 1.0, "ub": 1.0, "ub_lambda": 0.5,
                            "fim_build": 2.0, "fim_logdet": 3.0, "logdet_accuracy": 20.0},
        "crlb": {"parse": 1.0, "fim_build": 2.0, "crlb_blocks": 18.0, "accuracy": 1.5, "curvature": 3.0},
    }
    for command, times in reported.items():
        text, total = scaling.phases(command, json.dumps({"times": times}))
        assert total == sum(times.values()), command
        assert all(name in text for name in times), command


def test_factor_candidates_rejects_runs_it_cannot_report(tmp_path, capsys):
    """An unknown candidate, or only posecrb's own (no CHOLMOD flop count, so no flop limit), is a
    usage error before any grid is built or any candidate is factored."""
    candidates = _module("factor_candidates")
    for spec, message in (("metis/all,bogus/all", "unknown candidate(s) bogus/all"),
                          ("metis/2t", "unknown candidate(s) metis/2t"),
                          ("posecrb/all,posecrb/1t", "needs CHOLMOD's flop count")):
        with pytest.raises(SystemExit) as exc:
            candidates.main(["--candidates", spec, "--cache-dir", str(tmp_path)])
        assert exc.value.code == 2
        assert message in capsys.readouterr().err
    assert not any(tmp_path.iterdir())   # nothing was built


def test_factor_candidates_one_thread_reaches_cholmods_blas():
    """A '/1t' candidate must run CHOLMOD's BLAS at one thread. threadpoolctl limits only the
    libraries loaded when the limit is entered, and CHOLMOD's BLAS loads with CHOLMOD: the limit
    once came first, and every '/1t' figure was measured with two threads. A fresh process (nothing
    loaded yet, as in the script's candidate processes) with OpenBLAS set to two threads."""
    import os
    import subprocess

    code = ("import sys; sys.path.insert(0, sys.argv[1]); import factor_candidates as fc\n"
            "with fc._limit_blas('1t'):\n"
            "    import _cholmod; import sksparse.cholmod\n"
            "    from posecrb.linalg.threads import cholmod_threads\n"
            "    inside = cholmod_threads()\n"
            "print(inside, cholmod_threads())\n")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="2", OMP_NUM_THREADS="2")
    out = subprocess.run([sys.executable, "-c", code, str(BENCHMARKS)], env=env, capture_output=True, text=True,
                         check=True, timeout=120)
    inside, after = (int(x) for x in out.stdout.split())
    if after < 2:
        pytest.skip("CHOLMOD's BLAS has a single thread here: no limit to check")
    assert inside == 1


def test_factor_candidates_mumps_is_skipped_with_its_reason_where_it_does_not_build(tmp_path, monkeypatch):
    """The MUMPS candidate compiles a driver against the system's MUMPS; where that fails (no MUMPS,
    no compiler) the candidate reports why instead of failing the run."""
    candidates = _module("factor_candidates")
    monkeypatch.setenv("POSECRB_MUMPS_LIBS", "-lposecrb_no_such_library")
    import numpy as np
    import scipy.sparse as sp

    res = candidates._mumps(sp.identity(3, format="csc"), np.arange(3), "mumps", "1t", tmp_path / "m.fim.npz")
    assert res["error"].startswith("skipped: ")
    assert not (tmp_path / "mumps_logdet").exists()


def test_factor_candidates_mumps_logdet_matches_dense_reference(tmp_path):
    """MUMPS's log-det through the driver, with its own ordering and with a given pivot order,
    against numpy's dense slogdet of the same random SPD matrix (optional: needs MUMPS here)."""
    import numpy as np
    import scipy.sparse as sp

    candidates = _module("factor_candidates")
    try:
        candidates._mumps_driver(tmp_path)
    except RuntimeError as exc:
        pytest.skip(str(exc))
    a, ref, pose_of_row = _random_spd(7)
    for kind in ("mumps", "mumps-pose-metis"):
        res = candidates._mumps(a, pose_of_row, kind, "1t", tmp_path / "m.fim.npz")
        assert "error" not in res, res
        # log-det error ~ n eps cond(A): far below 1e-9 for this size and conditioning
        assert abs(res["logdet"] - ref) <= 1e-9 * max(1.0, abs(ref)), kind
        assert res["flops"] > 0 and res["lnz"] >= a.nnz // 2
    # an indefinite matrix is an error with its reason, never the log of a negative determinant
    indefinite = sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]]))
    res = candidates._mumps(indefinite, np.arange(2), "mumps", "1t", tmp_path / "indefinite.fim.npz")
    assert "not positive definite" in res["error"]


def test_factor_candidates_pardiso_is_skipped_with_its_reason_without_mkl(monkeypatch):
    """The PARDISO candidate needs MKL's libmkl_rt through POSECRB_MKL_RT; unset or not loadable,
    the candidate reports why instead of failing the run."""
    import numpy as np
    import scipy.sparse as sp

    candidates = _module("factor_candidates")
    a = sp.identity(3, format="csc")
    monkeypatch.delenv("POSECRB_MKL_RT", raising=False)
    res = candidates._pardiso_candidate(a, np.arange(3), "pardiso", "all")
    assert res["error"].startswith("skipped: set POSECRB_MKL_RT")
    monkeypatch.setenv("POSECRB_MKL_RT", "/nonexistent/libmkl_rt.so")
    res = candidates._pardiso_candidate(a, np.arange(3), "pardiso", "all")
    assert res["error"].startswith("skipped: MKL PARDISO does not load")


def test_factor_candidates_pardiso_logdet_matches_dense_reference():
    """PARDISO's log-det, with its own ordering and with a given one, against numpy's dense
    slogdet of the same random SPD matrix (optional: needs MKL through POSECRB_MKL_RT)."""
    import numpy as np
    import scipy.sparse as sp

    candidates = _module("factor_candidates")
    pardiso = _module("_pardiso")
    try:
        pardiso.library()
    except pardiso.Unavailable as exc:
        pytest.skip(str(exc))
    a, ref, pose_of_row = _random_spd(11)
    for kind in ("pardiso", "pardiso-pose-metis"):
        res = candidates._pardiso_candidate(a, pose_of_row, kind, "all")
        assert "error" not in res, res
        # log-det error ~ n eps cond(A): far below 1e-9 for this size and conditioning
        assert abs(res["logdet"] - ref) <= 1e-9 * max(1.0, abs(ref)), kind
        assert res["lnz"] >= a.nnz // 2
    indefinite = sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]]))
    res = candidates._pardiso_candidate(indefinite, np.arange(2), "pardiso", "all")
    assert "not positive definite" in res["error"]


def test_select_engines_runs_both_engines_and_reports_the_choice(tmp_path, capsys):
    """benchmarks/select_engines.py on a small graph: both engines as whole processes, the same edges,
    ``auto``'s choice (the CHOLMOD engine here) and numba loaded by the path engine only."""
    import numpy as np

    from posecrb.io import write_g2o

    from .helpers import random_pose_graph

    write_g2o(random_pose_graph(80, 2, np.random.default_rng(7), loop_closures=30)[0], tmp_path / "small.g2o")
    assert _module("select_engines").main(["--repeat", "1", "--data-dir", str(tmp_path), "small"]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("| small |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[5] == "cholmod" and cells[8] == "yes" and cells[9] == "True, False"
    assert float(cells[6]) > 0 and float(cells[7]) > 0


def test_solver_variants_runs_both_base_preconditioners_and_needs_data(tmp_path, capsys, monkeypatch):
    """benchmarks/solver_variants.py on a small 3D graph: SE-Sync's and the rotation block's base
    preconditioner, both certified at the same optimum; without data it stops with a usage error."""
    import numpy as np

    from posecrb.io import write_g2o

    from .helpers import random_pose_graph

    write_g2o(random_pose_graph(30, 3, np.random.default_rng(3), loop_closures=20, rot_noise=0.05,
                                trans_noise=0.05)[0], tmp_path / "small3d.g2o")
    module = _module("solver_variants")
    assert module.main(["--repeat", "1", "--data-dir", str(tmp_path), "--variants", "schur-base,rotation-base",
                        "small3d"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines() if line.startswith("small3d ")]
    assert [r[1] for r in rows] == ["schur-base", "rotation-base"] and all(r[9] == "yes" for r in rows)
    monkeypatch.delenv("POSECRB_DATA", raising=False)
    monkeypatch.setattr(module, "data_dir", lambda arg: None)
    with pytest.raises(SystemExit) as exc:
        module.main(["--variants", "schur-base"])
    assert exc.value.code == 2


def test_process_parser_threads_default_is_what_help_says():
    """The whole-process scripts' --threads default: one thread unless the script keeps every pool's
    own default (0); --help prints the default the parser really has."""
    common = _module("_common")
    for default in (1, 0):
        ap = common.process_parser("x", threads=default)
        assert ap.parse_args([]).threads == default
        assert f"[default: {default}]" in " ".join(ap.format_help().split())
    assert common.process_parser("x").parse_args(["--threads", "2"]).threads == 2


@pytest.mark.parametrize("script", sorted(p.name for p in BENCHMARKS.glob("[a-z]*.py")))
def test_every_benchmark_script_starts_and_answers_help(script):
    """`make bench` runs every script: each must at least import what it names and parse --help
    (a renamed library function once broke one of them before any measurement started)."""
    import subprocess

    run = subprocess.run([sys.executable, str(BENCHMARKS / script), "--help"], capture_output=True, text=True,
                         timeout=120, cwd=BENCHMARKS.parent)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "usage:" in run.stdout.lower()


def test_parse_benchmark_compares_both_tokenisers_on_a_file_given_by_name(tmp_path, capsys, monkeypatch):
    """benchmarks/parse.py resolves a bare name in the data directory, reads it through the input
    layer and finds the fast and the reference tokeniser's graphs the same."""
    import numpy as np

    from posecrb.io import write_g2o

    from .helpers import random_pose_graph

    write_g2o(random_pose_graph(40, 3, np.random.default_rng(5), loop_closures=10)[0], tmp_path / "tiny.g2o")
    monkeypatch.setattr(sys, "argv", ["parse.py", "--repeat", "1", "--no-grid", "--data-dir", str(tmp_path), "tiny"])
    _module("parse").main()
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("tiny.g2o"))
    assert row.split()[-1] == "yes"


def test_accuracy_bound_norm_bound_dominates_the_exact_one_and_uses_the_true_norm():
    """benchmarks/accuracy_bound.py: ``||A^{-1}||_2`` from Lanczos against dense numpy, and the norm
    bound at least the exact one (every ``|(A^{-1})_ij| <= ||A^{-1}||_2``), with the same gamma."""
    import numpy as np
    import scipy.sparse as sp

    from posecrb.linalg.accuracy import logdet_accuracy
    from posecrb.linalg.cholesky import SymbolicCholesky

    rng = np.random.default_rng(21)
    n = 60
    b = sp.random(n, n, density=0.08, random_state=rng) + sp.eye(n)
    a = (b @ b.T + 1e-2 * sp.eye(n)).tocsc()
    factor, logdet = SymbolicCholesky(a).factor_logdet(a)
    bound, inv_norm, gamma = _module("accuracy_bound").norm_bound(factor, n)
    dense = a.toarray()
    eig = np.linalg.eigvalsh(dense)
    reference = 1.0 / eig[0]
    # ARPACK's tol: the Ritz value within a relative 1e-6 of the eigenvalue
    assert inv_norm == pytest.approx(reference, rel=1e-6)
    exact = logdet_accuracy(factor, logdet)
    assert bound >= exact.error_bound * (1 - 1e-6)
    lower = np.abs(factor.L().toarray())
    assert bound == pytest.approx(gamma * float(lower.sum(axis=0) @ lower.sum(axis=0)) * reference, rel=1e-6)


def test_orderings_counts_are_cholmods_and_a_chain_has_no_fill_under_amd(tmp_path, capsys):
    """benchmarks/orderings.py --counts: CHOLMOD's analysis counts per matrix and ordering. A pose
    chain's FIM and M_red are block tridiagonal (chordal), where minimum degree eliminates without
    fill, so AMD's nnz(L) is exactly nnz(tril(A)); with loop closures every ordering has at least
    that many and flops (sum of squared column counts) at least nnz(L)."""
    import numpy as np

    from posecrb.io import write_g2o
    from posecrb.models.paper.fim import paper_fim

    from .helpers import random_pose_graph

    chain = random_pose_graph(30, 2, np.random.default_rng(1), loop_closures=0)[0]
    loops = random_pose_graph(60, 3, np.random.default_rng(2), loop_closures=25)[0]
    write_g2o(chain, tmp_path / "chain.g2o")
    write_g2o(loops, tmp_path / "loops.g2o")
    orderings = "amd,nesdis/poses,metis/poses,nesdis"
    assert _module("orderings").main(["--counts", "--grids3", "", "--data-dir", str(tmp_path), "--orderings",
                                      orderings, "--matrices", "FIM,Mred", "chain", "loops"]) == 0
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in capsys.readouterr().out.splitlines()
            if line.startswith(("| chain |", "| loops |"))]
    assert [(r[0], r[1]) for r in rows] == [("chain", "FIM"), ("chain", "Mred"), ("loops", "FIM"), ("loops", "Mred")]
    fim = {"chain": paper_fim(chain, chain.vertex_rot, chain.vertex_trans).to_layout("poses").matrix,
           "loops": paper_fim(loops, loops.vertex_rot, loops.vertex_trans).to_layout("poses").matrix}
    for name, matrix, _, *cells in rows:
        counts = [(float(c.split(" G / ")[0]) * 1e9, float(c.split(" G / ")[1].rstrip("M")) * 1e6) for c in cells]
        assert len(counts) == 4 and all(fl >= lnz > 0 for fl, lnz in counts)
        if matrix == "FIM":
            a = fim[name]
            tril = (a.nnz + a.shape[0]) // 2
            # the cells carry 3 significant digits
            assert all(lnz >= tril * (1 - 5e-3) for _, lnz in counts)
            if name == "chain":
                assert counts[0][1] == pytest.approx(tril, rel=5e-3)
