"""Worker functions of the Dask tests (imported by ``module:function`` on the Dask worker processes)."""

from __future__ import annotations

import os
import time


def sleepy(task) -> dict:
    """Longer than the timeout test's limit."""
    time.sleep(5)
    return {}


def echo(task) -> dict:
    """What reached the worker: the bus, the warm start and the worker's pid."""
    return {"bus": task.bus, "warm_start": task.warm_start, "pid": os.getpid()}


def slow_echo(task) -> dict:
    """:func:`echo` after 50 ms of work (a batch lasts long enough to kill its worker meanwhile)."""
    time.sleep(0.05)
    return echo(task)


def dies_on_doomed(task) -> dict:
    """Kills its worker process on the bus named ``doomed`` (every time: the retry dies too)."""
    if task.bus == "doomed":
        os._exit(17)
    return echo(task)


def spin(task) -> dict:
    """:func:`echo` after 50 ms of CPU work (a busy loop: thread CPU time, unlike :func:`slow_echo`)."""
    end = time.thread_time() + 0.05
    while time.thread_time() < end:
        pass
    return echo(task)
