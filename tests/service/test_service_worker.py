"""What runs in a worker: the identification's dict, outcome reasons."""

from __future__ import annotations

import numpy as np

from aslm_core import IdentifyConfig, Window, identify
from service.executors.base import WindowTask
from service.worker import result_dict, run_task


def _task() -> WindowTask:
    rng = np.random.default_rng(1)
    t = np.arange(500) / 50.0
    V = 1.0 + 0.003 * np.sin(2 * np.pi * 0.7 * t) + 1e-3 * rng.standard_normal(t.size)
    theta = 0.005 * np.sin(2 * np.pi * 0.4 * t)
    return WindowTask(Window(t, V, theta, P=0.8 * V * V, Q=0.3 * V, bus="b"), options={"n_starts": 1})


def test_result_dict_is_to_dict():
    task = _task()
    res = identify(task.window, config=IdentifyConfig(n_starts=1))
    assert result_dict(res) == res.to_dict()


def test_run_task_returns_the_identification_or_a_reason():
    out = run_task("service.worker:identify_window", _task())
    assert out.ok and set(out.value) >= {"dynamic", "static", "objective", "fit", "elapsed_s"}
    short = WindowTask(Window(np.arange(3) / 50.0, np.ones(3), np.zeros(3), np.ones(3), np.ones(3), bus="s"))
    out = run_task("service.worker:identify_window", short)
    assert not out.ok and out.reason.startswith(("window:", "error:"))


def test_run_task_reports_cpu_time_apart_from_wall_time():
    busy = run_task("service_dask_helpers:spin", _task())  # 50 ms of CPU
    idle = run_task("service_dask_helpers:slow_echo", _task())  # 50 ms asleep
    assert busy.ok and idle.ok
    # A busy thread's CPU time equals its wall time up to the two clocks' reading order and accounting (CI once saw
    # CPU ahead of wall by 0.2 µs), so "no more CPU than wall" holds within a millisecond, not exactly.
    assert busy.cpu_s > 0.02 and busy.elapsed_s >= busy.cpu_s - 1e-3
    assert idle.elapsed_s >= 0.05 and idle.cpu_s < 0.02
