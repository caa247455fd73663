"""Local worker pool: real spawned processes; crashes and hangs fail one task only."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from aslm_core.window import Window
from service.executors.base import WindowTask
from service.executors.local import LocalPool


def task(bus: str) -> WindowTask:
    t = np.arange(100) / 50.0
    return WindowTask(Window(t, V=1 + 0 * t, theta=0 * t, P=0.5 + 0 * t, Q=0.1 + 0 * t, bus=bus))


@pytest.fixture
def env(tmp_path, monkeypatch):
    monkeypatch.setenv("ASLM_TEST_HANG_BUS", "hang")
    monkeypatch.setenv("ASLM_TEST_MARKER", str(tmp_path / "marker"))
    return tmp_path / "marker"


def test_killed_worker_fails_its_task_only_and_is_replaced(env):
    pool = LocalPool(2, "service_helpers:hang_once_identify", timeout_s=60)
    try:
        assert pool.wait_ready(60)
        hang = pool.submit(task("hang"))
        others = [pool.submit(task(f"b{i}")) for i in range(6)]
        deadline = time.monotonic() + 30
        while not env.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        pid = int(env.read_text())
        assert pool.busy().get(pid) == "hang"
        os.kill(pid, signal.SIGKILL)
        out = hang.result(timeout=30)
        assert (out.ok, out.reason) == (False, "worker_crashed")
        assert all(f.result(timeout=30).ok for f in others)
        assert pool.replaced == 1
        assert pool.wait_ready(60)
        again = pool.submit(task("hang"))  # marker exists: the replacement runs it normally
        assert again.result(timeout=30).ok
    finally:
        pool.close()


def test_hung_task_times_out_and_others_finish(env):
    pool = LocalPool(2, "service_helpers:hang_once_identify", timeout_s=2.0)
    try:
        assert pool.wait_ready(60)
        hang = pool.submit(task("hang"))
        others = [pool.submit(task(f"b{i}")) for i in range(4)]
        out = hang.result(timeout=30)
        assert (out.ok, out.reason) == (False, "timeout")
        assert [f.result(timeout=30).ok for f in others] == [True] * 4
        assert pool.replaced == 1
    finally:
        pool.close()


def _one_bad_task_fails_alone(pool: LocalPool, bad: str, at: int, reason: str) -> None:
    """40 tasks with ``bad`` at position ``at``: it alone fails with ``reason``; its worker is replaced."""
    assert pool.wait_ready(60)
    names = [f"b{i}" for i in range(at)] + [bad] + [f"b{i}" for i in range(at, 40)]
    futs = pool.submit_many([task(n) for n in names])
    outs = {n: f.result(timeout=60) for n, f in zip(names, futs, strict=True)}
    assert (outs[bad].ok, outs[bad].reason) == (False, reason)
    assert all(o.ok for n, o in outs.items() if n != bad)
    assert pool.replaced == 1


@pytest.mark.parametrize("depth", [1, 8])
def test_window_crashing_its_worker_fails_that_bus_only_with_tasks_queued_behind_it(monkeypatch, depth):
    # With depth 8 a worker holds up to 8 tasks: the crash fails the one running, the ones queued
    # behind it in the dead worker run elsewhere.
    monkeypatch.setenv("ASLM_TEST_CRASH_BUS", "crash")
    pool = LocalPool(2, "service_helpers:crash_identify", timeout_s=60, depth=depth)
    try:
        _one_bad_task_fails_alone(pool, "crash", 10, "worker_crashed")
    finally:
        pool.close()


def test_hung_task_in_a_full_worker_times_out_alone(env):
    pool = LocalPool(2, "service_helpers:hang_once_identify", timeout_s=2.0, depth=8)
    try:
        _one_bad_task_fails_alone(pool, "hang", 5, "timeout")
    finally:
        pool.close()


def test_result_that_cannot_be_sent_back_fails_its_task_only():
    pool = LocalPool(1, "service_helpers:unpicklable_identify", timeout_s=60)
    try:
        assert pool.wait_ready(60)
        bad, good = pool.submit_many([task("bad"), task("good")])
        out = bad.result(timeout=30)
        assert not out.ok and out.reason.startswith("error:") and "not transferable" in out.message
        assert good.result(timeout=30).ok
        assert pool.replaced == 0
    finally:
        pool.close()


def test_exceptions_become_reasons():
    pool = LocalPool(1, "service.worker:identify_window", timeout_s=60)
    try:
        t = np.arange(3) / 50.0  # far too short for the identifier
        bad = WindowTask(Window(t, V=1 + 0 * t, theta=0 * t, P=0 * t, Q=0 * t, bus="x"))
        out = pool.submit(bad).result(timeout=120)
        assert not out.ok and out.reason.startswith(("window:", "error:"))
        assert out.message
    finally:
        pool.close()
    assert pool.submit(task("late")).result(timeout=5).reason == "shutdown"


def test_background_tasks_run_only_when_no_foreground_task_waits():
    pool = LocalPool(2, "service_helpers:fake_identify", timeout_s=60)
    try:
        assert pool.wait_ready(120)
        done: list[str] = []

        def submit(tasks):
            for fut, t in zip(pool.submit_many(tasks), tasks, strict=True):
                fut.add_done_callback(lambda f, bus=t.bus: done.append(bus))
        background = [task(f"bg{i}") for i in range(4)]
        for t in background:
            t.fn, t.background = "service_helpers:slow_identify", True
        submit(background)  # both workers idle: bg0 and bg1 start, bg2 and bg3 wait
        time.sleep(0.1)
        submit([task(f"fg{i}") for i in range(16)])  # must not wait behind bg2, bg3 (FIFO put them first)
        deadline = time.monotonic() + 30
        while len(done) < 20 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert sorted(done[-2:]) == ["bg2", "bg3"], done
        assert set(done[:-2]) == {f"fg{i}" for i in range(16)} | {"bg0", "bg1"}
    finally:
        pool.close()


def test_the_input_history_crosses_the_process_boundary():
    """A real worker given the six windows before a noisy window (what the scheduler cuts with
    ``input_history_windows``) identifies it with their pooled spectrum; one of them unusable: the window alone."""
    from conftest import equation_window

    rec = equation_window(seed=4, fs=50.0, fine=4, duration=70.0)
    rng = np.random.default_rng(1)
    V = rec.V + 1e-3 * rng.standard_normal(rec.t.size)
    theta = rec.theta + 1e-3 * rng.standard_normal(rec.t.size)
    wins = [Window(rec.t[s], V[s], theta[s], rec.P[s], rec.Q[s], bus="b")
            for s in (slice(j * 500, (j + 1) * 500) for j in range(7))]
    short = Window(wins[0].t[:5], wins[0].V[:5], wins[0].theta[:5], wins[0].P[:5], wins[0].Q[:5], bus="b")
    pool = LocalPool(1, "service.worker:identify_window", timeout_s=120)
    try:
        assert pool.wait_ready(600)
        with_history, broken = (f.result(timeout=120) for f in pool.submit_many(
            [WindowTask(wins[6], options={"n_starts": 1}, history=tuple(wins[:6])),
             WindowTask(wins[6], options={"n_starts": 1}, history=(short, *wins[1:6]))]))
        assert with_history.ok and with_history.value["quality"]["input_spectrum_windows"] == 6.0
        assert broken.ok and "input_spectrum_windows" not in broken.value["quality"]
        assert "weighted_chi2" in broken.value["quality"]  # identified alone, its refinement as without a history
    finally:
        pool.close()
