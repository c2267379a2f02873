"""BLAS thread policy (posecrb.linalg.threads): numpy's/scipy's own BLAS single-threaded in the
solver while CHOLMOD's keeps its threads; pool workers single-threaded."""
from __future__ import annotations

import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor

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
