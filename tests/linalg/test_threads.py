"""BLAS thread policy (posecrb.linalg.threads): numpy's/scipy's own BLAS single-threaded in the
solver while CHOLMOD's keeps its threads; pool workers single-threaded."""
from __future__ import annotations

import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor

import pytest
import scipy.linalg  # noqa: F401 -- its BLAS among the loaded ones
import sksparse.cholmod  # noqa: F401

from posecrb.linalg import threads


def _blas_threads() -> dict[str, int]:
    return {i["filepath"]: i["num_threads"] for i in threads.controller().info() if i["user_api"] == "blas"}


def test_python_blas_is_the_vendored_one_when_cholmod_has_its_own():
    infos = [i for i in threads.controller().info() if i["user_api"] == "blas"]
    chosen = {c.filepath for c in threads.python_blas().lib_controllers}
    vendored = {i["filepath"] for i in infos if threads._vendored(i)}
    if vendored and len(vendored) < len(infos):
        assert chosen == vendored
    else:   # one library for everything: limiting it is the only choice
        assert chosen == {i["filepath"] for i in infos}


def test_solver_threads_and_factorization_threads_restore():
    before = _blas_threads()
    cholmod = {c.filepath for c in threads.cholmod_blas().lib_controllers}
    n = threads.cholmod_threads()
    with threads.solver_threads(n):
        assert set(_blas_threads().values()) == {1}
        with threads.factorization_threads():
            inside = _blas_threads()
            assert all(inside[p] == (n if p in cholmod else 1) for p in inside)
        assert set(_blas_threads().values()) == {1}
    assert _blas_threads() == before
    with threads.solver_threads(1), threads.factorization_threads():
        assert set(_blas_threads().values()) == {1}
    with threads.factorization_threads():        # outside the solver: nothing changes
        assert _blas_threads() == before


def _worker_threads() -> list[int]:
    from threadpoolctl import threadpool_info
    return [i["num_threads"] for i in threadpool_info()]


def test_pool_workers_single_threaded():
    ctx = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(1, mp_context=ctx, initializer=threads.single_threaded_worker) as pool:
        assert set(pool.submit(_worker_threads).result()) == {1}


def test_controller_cached_until_a_loader_is_imported(monkeypatch):
    a = threads.controller()
    assert threads.controller() is a
    if "numba" in sys.modules:
        monkeypatch.delitem(sys.modules, "numba")
    else:
        monkeypatch.setitem(sys.modules, "numba", None)
    assert threads.controller() is not a


def test_factorizations_threaded_only_for_the_block_matrices_of_large_graphs():
    """CHOLMOD's BLAS keeps its threads only in the factorizations ``threaded_matrix`` names; every
    other factorization runs it at one thread, and the value is the same either way."""
    import scipy.sparse as sp

    from posecrb.linalg import ordering as ordmod
    from posecrb.linalg.cholesky import SymbolicCholesky

    assert ordmod.threaded_matrix(3, ordmod.AUTO_ND_MIN_POSES, "fim")
    assert not ordmod.threaded_matrix(3, ordmod.AUTO_ND_MIN_POSES, "lb")
    assert not ordmod.threaded_matrix(3, ordmod.AUTO_ND_MIN_POSES - 1, "ub")
    assert ordmod.threaded_matrix(2, ordmod.AUTO_ND_MIN_POSES_2D, "solver")
    assert not ordmod.threaded_matrix(2, ordmod.AUTO_ND_MIN_POSES_2D - 1, "fim")
    assert not ordmod.threaded_matrix(2, 10 ** 6, "lb")
    seen = []
    real = threads.cholmod_single_threaded

    def spy():
        seen.append(True)
        return real()

    a = sp.random(60, 60, density=0.1, random_state=1)
    a = (a @ a.T + 60 * sp.identity(60)).tocsc()
    import posecrb.linalg.cholesky as chol
    orig = chol.cholmod_single_threaded
    chol.cholmod_single_threaded = spy
    try:
        ld1 = SymbolicCholesky(a).factor_logdet(a)[1]
        assert seen == [True]
        ld2 = SymbolicCholesky(a, threaded=True).factor_logdet(a)[1]
        assert seen == [True]
    finally:
        chol.cholmod_single_threaded = orig
    # the same factorization; a different BLAS blocking may change its rounding, within the
    # backward error of a Cholesky log-det: n eps cond(a) (times a margin of 10)
    import numpy as np

    tol = 10 * a.shape[0] * np.finfo(float).eps * np.linalg.cond(a.toarray())
    assert abs(ld1 - ld2) <= tol


def test_solve_threads_count_the_load_once_a_second_inside_the_solver(monkeypatch):
    """``solve_threads``: CHOLMOD's BLAS at the solver's factorization count, fewer when cores are
    busy; the busy cores are counted again only when the last count is SOLVE_LOAD_SECONDS old;
    outside ``solver_threads``, or at one thread, nothing changes."""
    cholmod = {c.filepath for c in threads.cholmod_blas().lib_controllers}
    before = _blas_threads()
    clock = [100.0]
    counts = []
    busy = [0]

    def fake_busy():
        counts.append(clock[0])
        return busy[0]

    monkeypatch.setattr(threads, "busy_cores", fake_busy)
    monkeypatch.setattr(threads, "_cores", lambda: 2)
    monkeypatch.setattr(threads.time, "monotonic", lambda: clock[0])
    with threads.solve_threads():                 # outside the solver
        assert _blas_threads() == before
    assert counts == []
    with threads.solver_threads(2):
        with threads.solve_threads():
            inside = _blas_threads()
            assert all(inside[p] == (2 if p in cholmod else 1) for p in inside)
        assert set(_blas_threads().values()) == {1}
        busy[0] = 1                               # another process takes a core ...
        clock[0] += 0.5 * threads.SOLVE_LOAD_SECONDS
        with threads.solve_threads():             # ... unseen until the count is a second old
            assert all(_blas_threads()[p] == 2 for p in cholmod)
        assert len(counts) == 1
        clock[0] += threads.SOLVE_LOAD_SECONDS
        with threads.solve_threads():
            assert set(_blas_threads().values()) == {1}
        assert len(counts) == 2
    with threads.solver_threads(2):               # a new solver block counts afresh
        busy[0] = 0
        with threads.solve_threads():
            assert all(_blas_threads()[p] == 2 for p in cholmod)
        assert len(counts) == 3
    with threads.solver_threads(1), threads.solve_threads():
        assert set(_blas_threads().values()) == {1}
    assert len(counts) == 3
    assert _blas_threads() == before


def test_schur_solves_of_large_graphs_take_the_solve_threads(monkeypatch):
    """The solver's preconditioner and Lanczos solves (``Problem.schur_solve``) run inside
    ``solve_threads`` exactly when M_red is a threaded matrix of a 3D graph, and give the same
    solution."""
    import numpy as np

    import posecrb.solver.problem as problem_mod
    from posecrb.sim.generators import grid
    from posecrb.solver.problem import Problem

    graph = grid(3, 5, noise=True, rng=0)
    entered = []
    real = threads.solve_threads

    def spy():
        entered.append(True)
        return real()

    monkeypatch.setattr(problem_mod, "solve_threads", spy)
    W = np.random.default_rng(0).standard_normal((graph.n * 3, 3))
    problem = Problem.from_graph(graph)
    factor = problem.factor_full(None, 1.0, name="M_red")
    symbolic = problem._full_symbolic
    assert symbolic is not None and not symbolic.threaded     # a small graph: one thread
    solutions = [problem.schur_solve(factor, W)]
    assert entered == []
    monkeypatch.setattr(symbolic, "threaded", True)           # as for a large graph
    with threads.solver_threads(2):
        solutions.append(problem.schur_solve(factor, W))
    assert entered == [True]
    flat = Problem.from_graph(grid(2, 12, noise=True, rng=0))   # 2D: one thread, even when large
    flat_factor = flat.factor_full(None, 1.0, name="M_red")
    assert flat._full_symbolic is not None
    monkeypatch.setattr(flat._full_symbolic, "threaded", True)
    flat.schur_solve(flat_factor, np.ones((flat.n * 2, 2)))
    assert entered == [True]
    dense = problem.full_matrix(None, 1.0).toarray()
    reference = np.linalg.solve(dense, np.vstack([np.zeros((graph.n - 1, 3)), W]))[graph.n - 1:]
    tol = 10 * dense.shape[0] * np.finfo(float).eps * np.linalg.cond(dense)
    for x in solutions:
        assert np.max(np.abs(x - reference)) <= tol * np.max(np.abs(reference))


def test_running_tasks_and_own_threads_parse_the_kernel_texts():
    assert threads._running_tasks("0.95 0.97 1.02 3/84 10297\n") == 3
    assert threads._running_tasks("0.95 0.97 1.02") is None
    assert threads._running_tasks("0.95 0.97 1.02 x/84 1") is None
    # a command name may hold blanks and parentheses: the state follows the LAST ')'
    stats = ["10 (python) R 1 10", "11 (a) b) S 1 10", "12 (x y) R 1", "13 (idle) D 0"]
    assert threads._own_running_threads(stats) == 2


def test_usable_threads_leave_the_busy_cores():
    assert threads.usable_threads(2, cores=2, busy=0) == 2
    assert threads.usable_threads(2, cores=2, busy=1) == 1
    assert threads.usable_threads(2, cores=2, busy=5) == 1
    assert threads.usable_threads(4, cores=16, busy=3) == 4
    assert threads.usable_threads(8, cores=8, busy=3) == 5


def test_load_aware_threads_limit_cholmod_only_when_cores_are_busy(monkeypatch):
    before = _blas_threads()
    cholmod = {c.filepath for c in threads.cholmod_blas().lib_controllers}
    with threads.cholmod_blas().limit(limits=2):
        monkeypatch.setattr(threads, "busy_cores", lambda: 10 ** 6)
        with threads.load_aware_threads():
            assert all(n == 1 for p, n in _blas_threads().items() if p in cholmod)
        monkeypatch.setattr(threads, "busy_cores", lambda: 0)
        with threads.load_aware_threads():
            inside = _blas_threads()
        assert all(inside[p] == 2 for p in cholmod)
    assert _blas_threads() == before


def test_busy_cores_sees_a_busy_process():
    """A process that never sleeps keeps a core busy at every read; the count is of OTHER
    processes, so this test's own thread never counts."""
    import subprocess
    import time

    if not sys.platform.startswith("linux"):
        assert threads.busy_cores() == 0
        return
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.5)
        assert threads.busy_cores() >= 1
    finally:
        hog.kill()
        hog.wait()


def test_python_blas_usable_threads_follow_the_enclosing_limit_and_the_load(monkeypatch):
    ctl = threads.python_blas()
    monkeypatch.setattr(threads, "_cores", lambda: 2)
    with ctl.limit(limits=1):       # a pool worker, OPENBLAS_NUM_THREADS=1, the solver: never more
        monkeypatch.setattr(threads, "busy_cores", lambda: 0)
        assert threads.python_blas_usable_threads() == 1
    with ctl.limit(limits=2):
        monkeypatch.setattr(threads, "busy_cores", lambda: 0)
        assert threads.python_blas_usable_threads() == 2
        monkeypatch.setattr(threads, "busy_cores", lambda: 1)
        assert threads.python_blas_usable_threads() == 1


def test_own_usable_threads_follow_the_load_and_stay_off_in_pool_workers(monkeypatch):
    monkeypatch.setattr(threads, "_cores", lambda: 2)
    monkeypatch.setattr(threads, "busy_cores", lambda: 0)
    assert threads.own_usable_threads() == 2
    monkeypatch.setattr(threads, "busy_cores", lambda: 1)
    assert threads.own_usable_threads() == 1
    monkeypatch.setattr(threads, "busy_cores", lambda: 0)
    monkeypatch.setattr(threads, "_IN_POOL_WORKER", True)   # what single_threaded_worker sets
    assert threads.own_usable_threads() == 1
    monkeypatch.setattr(threads, "_IN_POOL_WORKER", False)
    monkeypatch.setattr(threads, "_cores", lambda: 1)
    assert threads.own_usable_threads() == 1


def test_single_threaded_worker_turns_posecrb_threads_off():
    """In a real pool worker (the initializer of every --jobs pool), not a flag set by hand."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, initializer=threads.single_threaded_worker) as pool:
        assert pool.submit(threads.own_usable_threads).result() == 1


def _openmp_runtime():
    """ctypes handle of the OpenMP runtime loaded with CHOLMOD, or None."""
    import ctypes

    paths = [c.filepath for c in threads.controller().lib_controllers if c.user_api == "openmp"]
    if not paths:
        return None
    lib = ctypes.CDLL(paths[0])
    lib.omp_get_max_active_levels.restype = ctypes.c_int
    lib.omp_set_max_active_levels.argtypes = [ctypes.c_int]
    return lib


def test_cholmod_openmp_serial_turns_parallel_regions_off_and_restores():
    lib = _openmp_runtime()
    if lib is None:
        pytest.skip("no OpenMP runtime is loaded with CHOLMOD here")
    before = lib.omp_get_max_active_levels()
    lib.omp_set_max_active_levels(3)
    try:
        with threads.cholmod_openmp_serial():
            assert lib.omp_get_max_active_levels() == 0
        assert lib.omp_get_max_active_levels() == 3
        with pytest.raises(RuntimeError), threads.cholmod_openmp_serial():
            raise RuntimeError("a failed factorization")
        assert lib.omp_get_max_active_levels() == 3
    finally:
        lib.omp_set_max_active_levels(before)


_TEAM_PROBE = """
import os, sys
import numpy as np, scipy.sparse as sp
from posecrb.linalg.cholesky import SymbolicCholesky
from posecrb.linalg import threads
side = 20      # a 3D grid Laplacian: separators of hundreds of rows, where CHOLMOD opens its team
lap = sp.diags([-np.ones(side - 1), 2 * np.ones(side), -np.ones(side - 1)], [-1, 0, 1])
eye = sp.identity(side)
a = (sp.kron(sp.kron(lap, eye), eye) + sp.kron(sp.kron(eye, lap), eye) + sp.kron(sp.kron(eye, eye), lap)
     + sp.identity(side ** 3)).tocsc()
openmp = any(c.user_api == "openmp" for c in threads.controller().lib_controllers)
count = lambda: len(os.listdir("/proc/self/task"))
start = count()
SymbolicCholesky(a, mode="supernodal", threaded=True).factor_logdet(a)
threaded = count()
sym = SymbolicCholesky(a, mode="supernodal")
sym.factor_logdet(a)
single = count()
sym._symbolic.cholesky(a)       # CHOLMOD itself, as scikit-sparse calls it: opens the team here
print(openmp, start, threaded, single, count())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts the threads in /proc/self/task")
def test_factorizations_open_no_openmp_team():
    """CHOLMOD's supernodal factorization opens an OpenMP team of a compile-time size; posecrb's
    factorizations, with and without BLAS threads, keep it off (a fresh process: a team, once
    opened, stays). The same factorization called on CHOLMOD directly opens it last, so the counts
    are not blind to it."""
    import os
    import subprocess

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")    # no BLAS threads come or go
    out = subprocess.run([sys.executable, "-c", _TEAM_PROBE], env=env, capture_output=True, text=True,
                         check=True, timeout=300)
    openmp, start, threaded, single, direct = (int(x) if x.isdigit() else x for x in out.stdout.split())
    if openmp != "True" or max(threaded, single, direct) == start:
        pytest.skip("CHOLMOD opens no OpenMP team here")
    assert threaded == start
    assert single == start
