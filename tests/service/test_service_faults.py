"""The service under operational faults, on a manual clock without Zenoh: a bad persisted period, a crash
mid-period, a failing storage, and what /health and the metrics say about them (issue 17)."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from service_helpers import settings_for, wait_for

from service.app import Service
from service.buffers import BufferStore
from service.clock import ManualClock
from service.health import IngestWatch, pool_problem
from service.models import PeriodSummary
from service.sources.base import Inlet
from service.storage import Storage
from service.testing import MemorySource

ROOT = Path(__file__).resolve().parents[1]

T0 = 1_000_000.0
FAKE = "service_helpers:fake_identify"


@pytest.mark.parametrize("bad", [math.inf, math.nan, 1e12, 1.0])
def test_a_bad_persisted_period_is_never_reloaded(tmp_path, bad):
    settings = settings_for(tmp_path, 7447, sources=[], sinks=["storage"], period_s=60.0, window_s=2.0, late_s=0.5)
    storage = Storage(settings.storage_path)
    storage.set_config({"period_s": bad})
    storage.close()
    svc = Service(settings, rest=False)
    try:
        assert svc.period_s == 60.0
    finally:
        svc.storage.close()


def _feed(svc: Service, clock, bus: str, end: float, seconds: float = 3.0) -> None:
    """Frames of ``bus`` at 50 frames/s over (end - seconds, end], through the service's validation."""
    source = MemorySource()
    source.start(Inlet(svc.store, max_future_s=5.0, f0=50.0, clock=clock))
    t = end - np.arange(int(seconds * 50))[::-1] / 50.0
    rng = np.random.default_rng(0)
    source.push_window(bus, t, 1 + 0.01 * rng.standard_normal(t.size), np.zeros(t.size), np.full(t.size, 0.8),
                       np.full(t.size, 0.3))


@pytest.fixture
def manual_service(tmp_path):
    made = []

    def make(**overrides) -> tuple[Service, ManualClock]:
        clock = ManualClock(T0 + 1.0)
        base = dict(sources=[], sinks=["storage"], period_s=10.0, window_s=2.0, late_s=0.5, identify_fn=FAKE,
                    diagnose_every=0, workers=1)
        svc = Service(settings_for(tmp_path, 7447, **{**base, **overrides}), rest=False, clock=clock).start()
        made.append(svc)
        clock.settle(30)
        return svc, clock

    yield make
    for svc in made:
        svc.stop()


def _run_period(svc: Service, clock: ManualClock, boundary: float, *buses: str) -> None:
    clock.advance_to(boundary)
    for bus in buses:
        _feed(svc, clock, bus, boundary)
    clock.advance_to(boundary + 0.5)
    clock.settle(30)


def test_health_is_degraded_while_storage_fails_and_results_still_reach_rest(manual_service):
    svc, clock = manual_service()
    assert svc.status().problems == ()
    pages = svc.storage._db.execute("PRAGMA page_count").fetchone()[0]
    svc.storage._db.execute(f"PRAGMA max_page_count = {pages}")  # SQLite's "database or disk is full"
    _run_period(svc, clock, T0 + 10, *(f"b{i}" for i in range(60)))
    assert svc.latest.results["b0"].period == T0 + 10  # REST "latest" has it although it is not stored
    problems = svc.status().problems
    assert len(problems) == 1 and problems[0].startswith("storage: storage writes failing"), problems
    metrics = svc.metrics.render().decode()
    assert 'aslm_component_ok{component="storage"} 0.0' in metrics
    assert 'aslm_component_ok{component="scheduler"} 1.0' in metrics
    assert "aslm_storage_backlog 61.0" in metrics  # 60 results and the period, kept for a retry
    svc.storage._db.execute("PRAGMA max_page_count = 1073741824")
    _run_period(svc, clock, T0 + 20, "b0")
    assert svc.status().problems == ()
    assert [p.period for p in svc.storage.periods()] == [T0 + 20, T0 + 10]
    assert len(svc.storage.latest_all()) == 60


def test_health_reports_a_dead_scheduler_and_its_restart(manual_service):
    svc, clock = manual_service()
    svc.scheduler.restart_delay_s = 0.0
    svc.period_s = float("nan")  # a value the settings now refuse: planning raises (ValueError from floor)
    svc.scheduler.replan()
    clock.advance(0.0)
    for _ in range(200):
        if svc.scheduler.restarts:
            break
        time.sleep(0.01)
    health = svc.status()
    assert svc.scheduler.restarts >= 1 and any(p.startswith("scheduler: scheduler restarted") for p in health.problems)
    assert "aslm_scheduler_restarts_total" in svc.metrics.render().decode()
    svc.period_s = 10.0
    svc.scheduler.replan()
    wait_for(lambda: svc.scheduler.next_period == T0 + 10, 10, 0.01)  # the restarted loop plans again
    _run_period(svc, clock, T0 + 10, "b1")
    assert [p.period for p in svc.storage.periods()] == [T0 + 10]
    assert svc.status().problems == ()


def test_ingest_watch_reports_no_frames_and_all_frames_dropped():
    clock = ManualClock(T0)
    store = BufferStore(2.0, 50.0, 0.5)
    watch = IngestWatch(store, clock, stale_s=60.0)
    source = MemorySource()
    source.start(Inlet(store, max_future_s=5.0, f0=50.0, clock=clock))
    assert watch.problem() is None
    clock.advance(61.0)
    assert watch.problem() == "no frames received for 61 s"
    t = clock.now() - np.arange(5)[::-1] / 50.0
    source.push_window("b1", t, np.ones(5), np.zeros(5), np.ones(5), np.zeros(5))
    assert watch.problem() is None
    clock.advance(61.0)
    source.push_window("b1", t - 3600.0, np.ones(5), np.zeros(5), np.ones(5), np.zeros(5))  # all late
    assert watch.problem() == "none of the 5 frames received in the last 61 s was buffered (dropped: late 5)"


def test_pool_problem_when_every_identification_of_the_last_period_failed():
    failed = PeriodSummary(period=T0, period_s=10.0, n_ok=0, n_failed=3, n_skipped=1, latency_s=0.1,
                           completed_at=T0 + 1)
    assert pool_problem(object(), failed) == f"every identification of period {T0:.0f} failed (3)"
    assert pool_problem(object(), failed.model_copy(update={"n_ok": 1})) is None


KILLED = '''
import sys, time
import numpy as np
sys.path.insert(0, "tests")
from service_helpers import settings_for
from service.app import Service
from service.clock import ManualClock
from service.sources.base import Inlet
from service.testing import MemorySource
from pathlib import Path

clock = ManualClock({start})
settings = settings_for(Path({tmp!r}), 7447, sources=[], sinks=["storage"], period_s=10.0, window_s=2.0,
                        late_s=0.5, identify_fn="service_helpers:hang_once_identify", diagnose_every=0, workers=1)
svc = Service(settings, rest=False, clock=clock).start()
clock.settle(60)
source = MemorySource()
source.start(Inlet(svc.store, max_future_s=5.0, f0=50.0, clock=clock))
clock.advance_to({boundary})
for bus in ("b1", "b2", "b3"):
    t = {boundary} - np.arange(150)[::-1] / 50.0
    source.push_window(bus, t, 1 + 0.01 * np.sin(t * 7), np.zeros(150), np.full(150, 0.8), np.full(150, 0.3))
clock.advance_to({boundary} + 0.5)
print("period started", flush=True)
time.sleep(600)
'''


def _marked_worker(marker: Path) -> int | None:
    """The pid ``hang_once_identify`` wrote (the worker it hangs), or None."""
    try:
        return int(marker.read_text())
    except (OSError, ValueError):
        return None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie (exited, not yet reaped by its new parent) counts as gone.
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.slow
def test_a_kill_9_mid_period_is_recorded_as_interrupted_at_the_next_start(tmp_path, monkeypatch):
    # b2 hangs its worker on purpose: the period is still running when the process is killed.
    env = {**os.environ, "ASLM_TEST_HANG_BUS": "b2", "ASLM_TEST_MARKER": str(tmp_path / "marker"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")])}
    script = KILLED.format(start=T0 + 1.0, tmp=str(tmp_path), boundary=T0 + 10)
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    hung = None
    try:
        assert proc.stdout.readline().strip() == "period started"
        storage = Storage(tmp_path / "aslm.sqlite")
        wait_for(lambda: (tmp_path / "marker").exists() and storage.latest("b1") is not None, 60, 0.05)
        storage.close()
        hung = _marked_worker(tmp_path / "marker")
        assert hung is not None and _alive(hung)
    finally:
        proc.kill()  # SIGKILL: nothing of the service runs after this
        proc.wait(30)
    if hung is not None:
        # The worker hung in its task outlives its killed service only until it sees its pipe close.
        end = time.monotonic() + 10.0
        while _alive(hung) and time.monotonic() < end:
            time.sleep(0.05)
        outlived = _alive(hung)
        if outlived:
            os.kill(hung, signal.SIGKILL)  # never leave it behind, even when the assertion fails
        assert not outlived, f"worker {hung} outlived its killed service"
    clock = ManualClock(T0 + 30.0)
    svc = Service(settings_for(tmp_path, 7447, sources=[], sinks=["storage"], period_s=10.0, window_s=2.0,
                               late_s=0.5, identify_fn=FAKE, diagnose_every=0, workers=1), rest=False, clock=clock)
    try:
        svc.start()
        (summary,) = svc.storage.periods()
        assert (summary.period, summary.status, summary.n_ok) == (T0 + 10, "interrupted", 1)
        assert summary.no_result == ["b2", "b3"] and summary.completed_at == T0 + 30.0
        assert 'aslm_periods_missed_total{status="interrupted"} 1.0' in svc.metrics.render().decode()
    finally:
        svc.stop()
    assert Storage(tmp_path / "aslm.sqlite").interrupted(T0 + 40, 0.5) == []  # recorded once
