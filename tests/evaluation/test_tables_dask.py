"""`tables --executor dask`: one dataset per task on a dask.distributed cluster gives the rows of the
local executor (every number except the timings), and says its timings are single-threaded."""
import numpy as np
import pytest

from posecrb.evaluation.tables import TableSettings, build_rows
from posecrb.io import write_g2o

from ..helpers import random_pose_graph

distributed = pytest.importorskip("dask.distributed")


def _is_timing(key: str) -> bool:
    return key.endswith("_time") or key in ("timing",)


@pytest.fixture
def small_files(tmp_path):
    paths = []
    for k, (n, dim) in enumerate([(12, 2), (10, 3), (15, 2)]):
        g, _, _ = random_pose_graph(n, dim, np.random.default_rng(k), rot_noise=0.02, trans_noise=0.05)
        p = tmp_path / f"g{k}_{dim}d.g2o"
        write_g2o(g, p)
        paths.append(str(p))
    paths.append(str(tmp_path / "missing.g2o"))   # a failure row travels back as a row too
    return paths


def test_dask_rows_equal_local_rows(small_files):
    from threadpoolctl import threadpool_limits

    settings = TableSettings(repeat=1)
    with threadpool_limits(1):   # as in a task: identical arithmetic whatever OPENBLAS_NUM_THREADS is
        local = build_rows(small_files, settings)
    done = []
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster, distributed.Client(cluster) as client:
        remote = build_rows(small_files, settings, executor="dask", client=client,
                            on_done=lambda name, row: done.append(name))
    assert sorted(done) == sorted(small_files)
    assert [r["dataset"] for r in remote] == [r["dataset"] for r in local]
    for a, b in zip(local, remote):
        if b["status"] != "not found":
            assert b["timing"] == "single-threaded task"
        keys = {k for k in a if not _is_timing(k)} | {k for k in b if not _is_timing(k)}
        for k in keys:
            # same code, same inputs, BLAS single-threaded in the task: bit-identical numbers
            assert a.get(k) == b.get(k), (a["dataset"], k)
    assert any(r["status"] == "ok" for r in local)


def test_scheduler_needs_dask():
    from posecrb.core.errors import UsageError

    with pytest.raises(UsageError):
        build_rows(["x"], TableSettings(repeat=1), scheduler="tcp://127.0.0.1:1")
