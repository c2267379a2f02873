"""Which BLAS runs with how many threads (docs/decisions/blas-threads.md).

Two BLAS libraries are usually loaded: the one CHOLMOD links (the system's ``libblas.so.3``,
the threaded OpenBLAS that ``make install`` installs), which does the supernodal factorizations'
dense work, and the private copy numpy and scipy bring in their wheels (a ``<package>.libs``
directory), which does posecrb's own small dense products.

* CHOLMOD's BLAS keeps its threads (every core by default) in the factorizations of the block
  matrices (FIM, ub, CRLB, the solver's M_red) of 3D graphs with at least 10,000 poses and 2D
  graphs with at least 50,000 (``posecrb.linalg.ordering.threaded_matrix``), whose
  nested-dissection separators are dense blocks of a thousand rows and more: there two threads pay
  (``SymbolicCholesky(threaded=True)``, set by ``posecrb.linalg.ordering.ordered_symbolic``).
  Only on the cores no other process keeps busy, counted at each such factorization
  (``load_aware_threads``): OpenBLAS's threads spin-wait for each other, so one sharing its core
  stalls the others, and two threads next to one busy process were slower than one.
* Every other factorization runs CHOLMOD's BLAS at one thread: small supernodes, where threads
  only add synchronisation and collapse when another process holds a core: on a loaded machine
  the FIM log-det of a mid-size 2D grid took several times longer with two threads than with one
  (docs/decisions/blas-threads.md).
* The solver runs every BLAS at one thread (many small products and triangular solves), except
  CHOLMOD's in the M_red factorizations of those large graphs (``solver_threads``,
  ``factorization_threads``) and in the triangular solves with those factors of 3D graphs
  (``solve_threads``, posecrb.solver.problem): the top separators of a 3D graph are dense
  triangles of thousands of rows, whose solves two threads share. The solves re-count the busy
  cores at most once a second. ``verify``'s certificates and refinement run inside the same
  policy (``posecrb.solver.solve.solver_thread_policy``), and the CRLB's accuracy estimate solves
  at one thread unless its matrix is threaded: a solve with one right-hand side through small
  supernodes takes several times longer on OpenBLAS's threads.
* numpy's/scipy's OpenBLAS stays at one thread in the solver and the selected inversion: its
  threads collapse under load (posecrb.linalg.selinv). The exception: the selected inversion's
  supernodes of at least 10^9 flops (the top separators of large graphs, nearly all of its flops
  there) run it on the cores no other process keeps busy (``python_blas_usable_threads``).

* posecrb's own threads (the scalar greedy's two halves, posecrb.selection.greedy) take the cores
  no other process keeps busy (``own_usable_threads``).
* CHOLMOD's own OpenMP loops run on the calling thread in every factorization
  (``cholmod_openmp_serial``): CHOLMOD 3's supernodal factorization opens an OpenMP team of a size
  fixed when it was compiled (4 threads in Debian's SuiteSparse 5, whatever ``OMP_NUM_THREADS``
  says) for loops over the rows of large supernodes, and on 2 cores, next to OpenBLAS's threads or
  not, that team cost more than its loops save.

Process pools run each worker with every pool at one thread (``single_threaded_worker``), and
posecrb's own threads off, so ``--jobs`` workers never oversubscribe the cores.

Rounding: a threaded BLAS splits a product into blocks by thread, so a factorization's last bits
can depend on the number of threads (never on the run: for a fixed count the blocking, hence the
result, is the same). Every tolerance of the test suite is derived from the factorization's
backward error (condition number x eps), which covers any blocking.
"""
from __future__ import annotations

import contextlib
import contextvars
import functools
import os
import sys
import time
from collections.abc import Iterator
from typing import Any

# Set in a process pool's worker (``single_threaded_worker``): posecrb's own threads stay off there.
_IN_POOL_WORKER = False

# Threads of CHOLMOD's BLAS inside ``factorization_threads`` (None: leave them as they are).
_FACTOR_THREADS: contextvars.ContextVar[int | None] = contextvars.ContextVar("factor_threads", default=None)

# The usable count of ``solve_threads`` and when it was taken (time.monotonic()): one list per
# ``solver_threads`` block, so a solve re-counts the busy cores at most every SOLVE_LOAD_SECONDS.
_SOLVE_LOAD: contextvars.ContextVar[list[float] | None] = contextvars.ContextVar("solve_load", default=None)
# A count of the busy cores (busy_cores' three samples) is small next to a preconditioner solve
# of a large graph, the only solves that take threads: re-counting at most once a second keeps
# its share of the solves' time under a percent (docs/decisions/blas-threads.md).
SOLVE_LOAD_SECONDS = 1.0

# Modules that load a BLAS or OpenMP library: the controller is rebuilt when one more is imported.
_LOADERS = ("numpy", "scipy.linalg", "sksparse.cholmod", "numba")


def controller() -> Any:
    """threadpoolctl's controller of the libraries loaded now; scanning them costs a noticeable
    part of a small problem's solve, so it is rebuilt only after a module that loads a BLAS
    (docs/decisions/fixed-costs.md)."""
    return _controller(tuple(m in sys.modules for m in _LOADERS))


@functools.lru_cache(maxsize=4)
def _controller(_loaded: tuple[bool, ...]) -> Any:
    from threadpoolctl import ThreadpoolController  # noqa: PLC0415 -- only where threads are set

    return ThreadpoolController()


def _vendored(info: dict) -> bool:
    # auditwheel and delocate put a wheel's private libraries in <package>.libs / .dylibs
    parent = os.path.basename(os.path.dirname(info.get("filepath") or ""))
    return parent.endswith((".libs", ".dylibs"))


def python_blas() -> Any:
    """The BLAS libraries numpy/scipy brought in their wheels, when CHOLMOD has another one;
    every BLAS otherwise (one library shared by all: limiting it limits CHOLMOD too)."""
    ctl = controller()
    blas = [c for c in ctl.lib_controllers if c.user_api == "blas"]
    own = [c for c in blas if _vendored(c.info())]
    if own and len(own) < len(blas):
        return ctl.select(filepath=[c.filepath for c in own])
    return ctl.select(user_api="blas")


def cholmod_blas() -> Any:
    """The BLAS libraries that are not numpy's/scipy's own (``python_blas``): CHOLMOD's."""
    ctl = controller()
    own = {c.filepath for c in python_blas().lib_controllers}
    return ctl.select(filepath=[c.filepath for c in ctl.lib_controllers
                                if c.user_api == "blas" and c.filepath not in own])


def cholmod_threads() -> int:
    """How many threads CHOLMOD's BLAS has now (1 when it cannot be told apart)."""
    return max([c.num_threads for c in cholmod_blas().lib_controllers], default=1)


def _running_tasks(loadavg: str) -> int | None:
    """Runnable tasks of the whole system: the first half of the 4th field of /proc/loadavg
    ("R/T"), which counts the reading thread itself; None when the text is not that."""
    fields = loadavg.split()
    if len(fields) < 4 or "/" not in fields[3]:
        return None
    running = fields[3].split("/", 1)[0]
    return int(running) if running.isdigit() else None


def _own_running_threads(states: list[str]) -> int:
    """Threads of this process in the running state, from the texts of /proc/self/task/*/stat
    (the state is the first field after the parenthesised command name)."""
    return sum(1 for st in states if st[st.rfind(")") + 2: st.rfind(")") + 3] == "R")


def busy_cores(samples: int = 3, interval: float = 0.002) -> int:
    """How many cores other processes keep busy now: the system's runnable tasks minus this
    process's own running threads, the least of ``samples`` reads ``interval`` seconds apart (a task
    that ran only at one read is not a busy core). 0 where /proc cannot tell (not Linux)."""
    least: int | None = None
    for k in range(samples):
        if k:
            time.sleep(interval)
        try:
            with open("/proc/loadavg") as f:
                running = _running_tasks(f.read())
            states = []
            for task in os.listdir("/proc/self/task"):
                try:
                    with open(f"/proc/self/task/{task}/stat") as f:
                        states.append(f.read())
                except OSError:
                    continue    # the thread ended between the listing and the read
        except OSError:
            return 0
        if running is None:
            return 0
        others = max(0, running - max(_own_running_threads(states), 1))
        least = others if least is None else min(least, others)
    return least or 0


def usable_threads(threads: int, cores: int, busy: int) -> int:
    """Threads for a factorization that ``threads`` would run: at most the cores not kept busy by
    other processes, at least 1. OpenBLAS's threads wait for each other by spinning, so one that
    shares its core with another process stalls every other thread: on 2 cores, a large 3D
    factorization that two threads make faster on a quiet machine became slower with two than
    with one next to one busy process (docs/decisions/blas-threads.md)."""
    return max(1, min(threads, cores - busy))


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def load_aware_threads() -> Any:
    """CHOLMOD's BLAS at ``usable_threads`` inside (a context manager): its threads as they are
    when no other process keeps a core busy, fewer when one does. The count comes from the
    whole system's runnable tasks (a container sees its host's), so it errs towards fewer
    threads, the side that costs at most the threads' gain."""
    threads = cholmod_threads()
    if threads <= 1:
        return contextlib.nullcontext()
    usable = usable_threads(threads, _cores(), busy_cores())
    return contextlib.nullcontext() if usable == threads else cholmod_blas().limit(limits=usable)


def python_blas_usable_threads() -> int:
    """``usable_threads`` for numpy's/scipy's BLAS: the threads it has now (an enclosing limit, a
    pool worker's single thread or ``OPENBLAS_NUM_THREADS`` count), fewer when other processes keep
    cores busy. For the few large dense products of a computation that otherwise runs that BLAS at
    one thread (the selected inversion's separators, posecrb.linalg.selinv)."""
    threads = max([c.num_threads for c in python_blas().lib_controllers], default=1)
    return 1 if threads <= 1 else usable_threads(threads, _cores(), busy_cores())


def own_usable_threads() -> int:
    """Threads for posecrb's own parallel steps (Python threads around compiled kernels that
    release the GIL: the scalar greedy of posecrb.selection.greedy): the cores no other process
    keeps busy, and 1 in a process pool's worker (``single_threaded_worker``), whose pool already
    shares the cores out."""
    if _IN_POOL_WORKER:
        return 1
    cores = _cores()
    return usable_threads(cores, cores, busy_cores()) if cores > 1 else 1


@functools.lru_cache(maxsize=4)
def _openmp_levels(paths: tuple[str, ...]) -> tuple[tuple[Any, Any], ...]:
    """(omp_get_max_active_levels, omp_set_max_active_levels) of each OpenMP runtime in ``paths``."""
    import ctypes  # noqa: PLC0415 -- only where CHOLMOD factors

    found = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
            get, put = lib.omp_get_max_active_levels, lib.omp_set_max_active_levels
        except (OSError, AttributeError):
            continue
        get.restype, get.argtypes = ctypes.c_int, []
        put.restype, put.argtypes = None, [ctypes.c_int]
        found.append((get, put))
    return tuple(found)


@contextlib.contextmanager
def cholmod_openmp_serial() -> Iterator[None]:
    """Every OpenMP parallel region on one thread inside (a context manager).

    CHOLMOD 3's supernodal factorization opens an OpenMP team of a compile-time size (Debian's
    SuiteSparse 5: ``num_threads(4)``, which ``OMP_NUM_THREADS`` and threadpoolctl cannot lower)
    for loops over the rows of large supernodes. On a 2-core machine those 4 threads wake and
    sleep at every such supernode: a solve of a large grid made over a hundred thousand voluntary
    context switches, and the team made the M_red factorizations of large 2D grids slower, both
    with CHOLMOD's BLAS on two threads and on one (docs/decisions/blas-threads.md).
    Small factorizations never open the team. ``max-active-levels = 0`` makes every parallel
    region inactive, i.e. run by the thread that meets it; the previous value is restored on exit.
    In GCC's libgomp the setting is process-wide, so another thread's OpenMP regions run on one
    thread meanwhile too.
    """
    paths = tuple(c.filepath for c in controller().lib_controllers if c.user_api == "openmp")
    levels = _openmp_levels(paths) if paths else ()
    saved = [get() for get, _ in levels]
    for _, put in levels:
        put(0)
    try:
        yield
    finally:
        for (_, put), level in zip(levels, saved):
            put(level)


def cholmod_single_threaded() -> Any:
    """CHOLMOD's BLAS at one thread inside (a context manager; nothing to do when it has one)."""
    ctl = cholmod_blas()
    if all(c.num_threads == 1 for c in ctl.lib_controllers):
        return contextlib.nullcontext()
    return ctl.limit(limits=1)


@contextlib.contextmanager
def solver_threads(factor_threads: int) -> Iterator[None]:
    """Every BLAS at one thread inside, except CHOLMOD's in ``factorization_threads`` blocks,
    which get ``factor_threads``."""
    token = _FACTOR_THREADS.set(factor_threads)
    load = _SOLVE_LOAD.set([1.0, -float("inf")])
    try:
        with controller().limit(limits=1, user_api="blas"):
            yield
    finally:
        _SOLVE_LOAD.reset(load)
        _FACTOR_THREADS.reset(token)


@contextlib.contextmanager
def factorization_threads() -> Iterator[None]:
    """CHOLMOD's BLAS at the count ``solver_threads`` chose, for one factorization."""
    n = _FACTOR_THREADS.get()
    if n is None or n <= 1:
        yield
        return
    with cholmod_blas().limit(limits=n):
        yield


def solve_threads() -> Any:
    """CHOLMOD's BLAS for one triangular solve with the factor of a large graph's matrix in a
    ``solver_threads`` block (a context manager): the count ``solver_threads`` chose for the
    factorizations, fewer while other processes keep cores busy, counted again when the last count
    is SOLVE_LOAD_SECONDS old. Outside such a block, or at one thread, nothing changes."""
    n = _FACTOR_THREADS.get()
    load = _SOLVE_LOAD.get()
    if n is None or n <= 1 or load is None:
        return contextlib.nullcontext()
    now = time.monotonic()
    if now - load[1] >= SOLVE_LOAD_SECONDS:
        load[0], load[1] = usable_threads(n, _cores(), busy_cores()), now
    return contextlib.nullcontext() if load[0] <= 1 else cholmod_blas().limit(limits=int(load[0]))


def all_single_threaded() -> Any:
    """Every BLAS and OpenMP pool at one thread (a context manager)."""
    return controller().limit(limits=1)


def single_threaded_worker() -> None:
    """Initializer of a process pool's workers: every BLAS/OpenMP pool at one thread for the
    worker's life (the workers share the cores; threads inside each would oversubscribe them)."""
    global _IN_POOL_WORKER
    import numpy  # noqa: F401, PLC0415 -- load the libraries first: threadpoolctl sets the loaded ones
    import sksparse.cholmod  # noqa: F401, PLC0415
    from threadpoolctl import threadpool_limits  # noqa: PLC0415 -- only in pool workers

    threadpool_limits(limits=1)
    _IN_POOL_WORKER = True
