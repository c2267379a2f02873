"""Monte Carlo engine: independent trials with reproducible seeds, run serially,
in a local process pool, or on a Dask distributed cluster.

Every trial gets its own ``numpy.random.SeedSequence`` (spawned from the user's
seed and a stable key of the experiment level), so a trial's random stream does
not depend on how many trials run, in which order, or where. Trial functions run
with BLAS/OpenMP limited to one thread in every executor, results come back in
task order, and all reductions happen afterwards in that order: for a given
seed the output is bit-identical whatever the executor and the number of jobs.

A trial function has the signature ``fn(context, task) -> result`` and must be a
module-level function (it is pickled by reference); ``context`` is shipped once
per worker (process-pool initializer / Dask ``scatter(broadcast=True)``), not
once per trial.

Executors:

* ``"serial"``: in-process loop (what ``--jobs 1`` runs);
* ``"local"``: ``concurrent.futures.ProcessPoolExecutor`` with ``jobs`` workers
  (``spawn`` start method: safe with threads and BLAS);
* ``"dask"``: ``dask.distributed`` (optional extra ``posecrb[dask]``). With a
  ``scheduler`` address the trials run on that cluster (its workers need posecrb
  installed); without one a ``LocalCluster`` of ``jobs`` single-threaded worker
  processes is started on 127.0.0.1 and closed afterwards.
"""
from __future__ import annotations

import contextlib
import math
import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from threadpoolctl import threadpool_limits

from ..core.errors import UsageError

EXECUTORS = ("serial", "local", "dask")


@dataclass(frozen=True)
class Task:
    """One Monte Carlo trial: ``group`` indexes the context list, ``trial`` numbers it within the group."""

    group: int
    trial: int
    seed: np.random.SeedSequence

    def rng(self) -> np.random.Generator:
        return np.random.default_rng(self.seed)


def level_key(value: float) -> int:
    """A stable non-negative integer for an experiment level (e.g. k_c = 2.5 -> 2500000).

    Seeds derived from it make the trials of one level identical whichever other
    levels are run alongside it (``--kc 20`` and ``--kc 1:20`` agree at k_c = 20).
    """
    key = int(round(float(value) * 1_000_000))
    if key < 0:
        raise UsageError(f"level key needs a non-negative value, got {value}")
    return key


def trial_seeds(seed: int, n: int, key: Sequence[int] = ()) -> list[np.random.SeedSequence]:
    """``n`` independent child seeds: ``SeedSequence(seed, spawn_key=key).spawn(n)``."""
    if n < 0:
        raise UsageError("number of trials must be >= 0")
    return np.random.SeedSequence(int(seed), spawn_key=tuple(int(k) for k in key)).spawn(n)


def make_tasks(seed: int, trials: int, keys: Sequence[Sequence[int]]) -> list[Task]:
    """Tasks for ``len(keys)`` groups of ``trials`` trials each, group g seeded by ``keys[g]``."""
    return [Task(g, t, s) for g, key in enumerate(keys) for t, s in enumerate(trial_seeds(seed, trials, key))]


def seed_record(task: Task) -> dict:
    """How to rebuild a task's seed (for run.json)."""
    # trial_seeds seeds every SeedSequence with an int (numpy also allows a sequence or None)
    return {"entropy": int(cast(int, task.seed.entropy)), "spawn_key": list(task.seed.spawn_key)}


# ---------------------------------------------------------------- execution in one place
@contextlib.contextmanager
def _single_threaded():
    """Limit BLAS/OpenMP pools to one thread (identical arithmetic in every executor)."""
    with threadpool_limits(limits=1):
        yield


def _run_chunk(fn: Callable, contexts: Sequence[Any], chunk: Sequence[tuple[int, Task]]) -> list[tuple[int, Any]]:
    with _single_threaded():
        return [(pos, fn(contexts[task.group], task)) for pos, task in chunk]


_WORKER: dict[str, Any] = {}


def _init_worker(fn: Callable, contexts: Sequence[Any]) -> None:
    _WORKER["fn"], _WORKER["contexts"] = fn, contexts


def _run_chunk_in_worker(chunk):
    return _run_chunk(_WORKER["fn"], _WORKER["contexts"], chunk)


def _run_chunk_dask(payload, chunk):
    fn, contexts = payload
    return _run_chunk(fn, contexts, chunk)


def task_chunks(tasks: Sequence[Task], size: int) -> list[list[tuple[int, Task]]]:
    items = list(enumerate(tasks))
    return [items[k:k + size] for k in range(0, len(items), size)]


def default_chunksize(n_tasks: int, workers: int) -> int:
    """About four chunks per worker: small enough to balance, large enough to amortise IPC."""
    return max(1, math.ceil(n_tasks / (4 * max(1, workers))))


def run_tasks(fn: Callable[[Any, Task], Any], contexts: Sequence[Any], tasks: Sequence[Task], *,
              executor: str = "serial", jobs: int = 1, scheduler: str | None = None, client: Any = None,
              chunksize: int | None = None, progress: Callable[[int], None] | None = None) -> list[Any]:
    """Run ``fn(contexts[task.group], task)`` for every task; results in task order.

    ``progress(k)`` is called in the calling process after every finished chunk
    with the number of trials it held.
    """
    if executor not in EXECUTORS:
        raise UsageError(f"unknown executor {executor!r}; choose from {', '.join(EXECUTORS)}")
    if jobs < 1:
        raise UsageError(f"--jobs must be >= 1, got {jobs}")
    tasks = list(tasks)
    out: list[Any] = [None] * len(tasks)
    if not tasks:
        return out
    if executor == "local" and jobs == 1:
        executor = "serial"
    size = chunksize or (1 if executor == "serial" else default_chunksize(len(tasks), jobs))
    chunks = task_chunks(tasks, size)

    def collect(done: list[tuple[int, Any]]) -> None:
        for pos, value in done:
            out[pos] = value
        if progress is not None:
            progress(len(done))

    if executor == "serial":
        for chunk in chunks:
            collect(_run_chunk(fn, contexts, chunk))
        return out
    if executor == "local":
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_init_worker,
                                 initargs=(fn, list(contexts))) as pool:
            futures = [pool.submit(_run_chunk_in_worker, chunk) for chunk in chunks]
            for fut in as_completed(futures):
                collect(fut.result())
        return out
    return run_dask(fn, contexts, chunks, jobs, scheduler, client, collect, out)


def run_dask(fn, contexts, chunks, jobs, scheduler, client, collect, out):
    try:
        from dask.distributed import Client, LocalCluster  # noqa: PLC0415 -- optional dependency (dask extra)
        from dask.distributed import as_completed as dask_as_completed  # noqa: PLC0415 -- optional (dask extra)
    except ImportError as exc:
        raise UsageError('--executor dask needs the optional extra: pip install "posecrb[dask]"') from exc
    with contextlib.ExitStack() as stack:
        if client is None:
            if scheduler:
                try:
                    client = stack.enter_context(Client(scheduler))
                except (OSError, TimeoutError, ValueError, TypeError) as exc:
                    # unreachable, refused or malformed address: the user's to fix, not a bug
                    raise UsageError(f"--scheduler {scheduler}: cannot connect to the Dask scheduler "
                                     f"({type(exc).__name__}: {exc})") from None
            else:
                cluster = stack.enter_context(LocalCluster(
                    n_workers=jobs, threads_per_worker=1, processes=True, host="127.0.0.1",
                    dashboard_address=":0"))   # any free port: None means distributed's 8787, which may be taken
                client = stack.enter_context(Client(cluster))
        # A fresh key per run (hash=False): re-scattering identical data under the same key from a
        # second client can leave workers replicating it forever (seen with distributed 2026.8).
        payload = client.scatter((fn, list(contexts)), hash=False)
        futures = [client.submit(_run_chunk_dask, payload, chunk, pure=False) for chunk in chunks]
        for fut in dask_as_completed(futures):
            collect(fut.result())
    return out


def mean_and_stderr(values: np.ndarray) -> tuple[float, float]:
    """Sample mean and its standard error (ddof = 1) over the first axis."""
    values = np.asarray(values, dtype=float)
    n = values.shape[0]
    mean = float(values.mean())
    se = float(values.std(ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
    return mean, se


def demo_trial(context: dict, task: Task) -> np.ndarray:
    """A cheap stand-in trial (tests, benchmarks): draws, a small SPD solve, a float reduction.

    ``context = {"size": k}``; returns a (3,) float array that depends on every bit of the draws.
    """
    rng = task.rng()
    k = int(context.get("size", 20))
    a = rng.standard_normal((k, k))
    spd = a @ a.T + k * np.eye(k)
    x = np.linalg.solve(spd, rng.standard_normal(k))
    return np.array([x @ x, np.log(np.linalg.det(spd)), float(task.group * 1000 + task.trial)])
