"""The Dask executor against a real local Dask cluster on 127.0.0.1 (skipped without dask[distributed])."""

from __future__ import annotations

import numpy as np
import pytest

from aslm_core.window import Window
from service.executors import make_executor
from service.executors.base import WindowTask
from service.executors.dask import DaskPool

distributed = pytest.importorskip("distributed")


def task(bus: str, n: int = 100) -> WindowTask:
    t = np.arange(n) / 50.0
    return WindowTask(Window(t, V=1 + 0 * t, theta=0 * t, P=0.5 + 0 * t, Q=0.1 + 0 * t, bus=bus))


def test_dask_executor_runs_tasks_and_reports_failures():
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp://", host="127.0.0.1", scheduler_port=0,
                                  dashboard_address=None) as cluster:
        pool = make_executor(cluster.scheduler_address, 1, "service.worker:identify_window", timeout_s=120)
        assert isinstance(pool, DaskPool)
        try:
            out = pool.submit(task("short", n=3)).result(timeout=180)  # far too short: refused by the core
            assert not out.ok and out.reason.startswith(("window:", "error:")) and out.message
            slow = DaskPool(cluster.scheduler_address, "time:sleep", timeout_s=1.0)  # sleep(task) -> TypeError
            bad = slow.submit(task("x")).result(timeout=60)
            assert not bad.ok and bad.reason == "error:TypeError"
            slow.close()
        finally:
            pool.close()


def test_dask_timeout_fails_the_task():
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://", host="127.0.0.1", scheduler_port=0,
                                  dashboard_address=None) as cluster:
        pool = DaskPool(cluster.scheduler_address, "service_dask_helpers:sleepy", timeout_s=1.0)
        try:
            out = pool.submit(task("hang")).result(timeout=30)
            assert (out.ok, out.reason) == (False, "timeout")
        finally:
            pool.close()
