"""Monte Carlo engine: seeds, ordering, and bit-identical results across executors."""
from __future__ import annotations

import numpy as np
import pytest

from posecrb.core.errors import UsageError
from posecrb.sim.montecarlo import (
    Task,
    demo_trial,
    level_key,
    make_tasks,
    mean_and_stderr,
    run_tasks,
    seed_record,
    trial_seeds,
)


def _stack(results):
    return np.stack(results)


def test_trial_seeds_are_prefix_stable_and_distinct():
    a = trial_seeds(7, 10, (20_000_000,))
    b = trial_seeds(7, 4, (20_000_000,))
    draws = lambda ss: [np.random.default_rng(s).random() for s in ss]
    assert draws(a[:4]) == draws(b)                      # more trials do not change the first ones
    assert len(set(draws(a))) == 10
    assert draws(trial_seeds(8, 4, (20_000_000,))) != draws(b)   # the seed matters
    assert draws(trial_seeds(7, 4, (1_000_000,))) != draws(b)    # the level matters


def test_level_key_and_tasks():
    assert level_key(20) == 20_000_000 and level_key(2.5) == 2_500_000
    with pytest.raises(ValueError):
        level_key(-1)
    tasks = make_tasks(3, 5, [(1,), (2,)])
    assert [(t.group, t.trial) for t in tasks] == [(g, k) for g in range(2) for k in range(5)]
    # groups keyed by level: group 1 alone equals group 1 within a sweep
    alone = make_tasks(3, 5, [(2,)])
    assert [t.rng().random() for t in alone] == [t.rng().random() for t in tasks[5:]]
    rec = seed_record(tasks[6])
    assert np.random.default_rng(np.random.SeedSequence(rec["entropy"], spawn_key=rec["spawn_key"])).random() \
        == tasks[6].rng().random()


def test_serial_results_in_task_order_with_progress():
    tasks = make_tasks(11, 6, [(1,), (2,)])
    seen = []
    res = run_tasks(demo_trial, [{"size": 8}, {"size": 8}], tasks, progress=seen.append)
    assert sum(seen) == len(tasks)
    assert [int(r[2]) for r in res] == [t.group * 1000 + t.trial for t in tasks]


@pytest.mark.slow
def test_local_pool_bit_identical_to_serial():
    tasks = make_tasks(5, 9, [(1,), (2,), (3,)])
    contexts = [{"size": 30}] * 3
    serial = _stack(run_tasks(demo_trial, contexts, tasks))
    seen = []
    pooled = _stack(run_tasks(demo_trial, contexts, tasks, executor="local", jobs=2, chunksize=4,
                              progress=seen.append))
    assert sum(seen) == len(tasks)
    assert np.array_equal(serial, pooled)        # bit-identical, not merely close


@pytest.mark.slow
def test_dask_local_cluster_bit_identical_to_serial():
    distributed = pytest.importorskip("dask.distributed")
    tasks = make_tasks(5, 8, [(1,), (2,)])
    contexts = [{"size": 30}] * 2
    serial = _stack(run_tasks(demo_trial, contexts, tasks))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=":0") as cluster, distributed.Client(cluster) as client:
        via_client = _stack(run_tasks(demo_trial, contexts, tasks, executor="dask", client=client, chunksize=3))
        via_address = _stack(run_tasks(demo_trial, contexts, tasks, executor="dask",
                                       scheduler=cluster.scheduler_address))
    assert np.array_equal(serial, via_client)
    assert np.array_equal(serial, via_address)


def test_bad_executor_and_jobs():
    tasks = [Task(0, 0, np.random.SeedSequence(1))]
    with pytest.raises(UsageError):
        run_tasks(demo_trial, [{}], tasks, executor="slurm")
    with pytest.raises(UsageError):
        run_tasks(demo_trial, [{}], tasks, executor="local", jobs=0)
    assert run_tasks(demo_trial, [{}], [], executor="local", jobs=2) == []


def test_mean_and_stderr():
    m, se = mean_and_stderr(np.array([1.0, 2.0, 3.0, 4.0]))
    assert m == 2.5 and se == pytest.approx(np.std([1, 2, 3, 4], ddof=1) / 2)
