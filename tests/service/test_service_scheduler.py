"""The scheduler in virtual time: a manual clock, an in-memory source and sink, tasks run inline.

Each test runs several periods of the real :class:`service.scheduler.Scheduler` thread in milliseconds.
The identification is the stand-in ``service_helpers:fake_identify`` (D from the warm start, a + 1 each
period) except in the test that runs the real identifier.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import D_TRUE

from service.buffers import BufferStore
from service.clock import ManualClock
from service.frames import FrameBatch, encode_json
from service.scheduler import QualityRules, Scheduler
from service.sinks.base import SinkChain
from service.sinks.storage import StorageSink
from service.sources.base import Inlet
from service.storage import Storage
from service.testing import InlineExecutor, MemorySink, MemorySource

T0 = 1_000_000.0  # a multiple of every period used here [s]
FS = 50.0
WINDOW_S, LATE_S = 2.0, 0.5
RULES = QualityRules(WINDOW_S, FS, min_coverage=0.8, max_gap_s=0.2, min_v_std=1e-5)
FAKE = "service_helpers:fake_identify"


class Bench:
    """A scheduler on a manual clock, fed by a MemorySource, writing to a SinkChain ending in ``sink``."""

    def __init__(self, *, period_s: float = 10.0, start: float = T0, fn: str = FAKE, sinks: tuple = (),
                 rules: QualityRules = RULES, frame_rate: float = FS, options: dict | None = None,
                 input_history: int | None = None) -> None:
        self.clock = ManualClock(start)
        self.store = BufferStore(rules.window_s, frame_rate, LATE_S, history_s=(input_history or 0) * rules.window_s)
        self.source = MemorySource()
        self.source.start(Inlet(self.store, max_future_s=5.0, f0=50.0, clock=self.clock))
        self.sink = MemorySink()
        self.errors: list[str] = []
        self.chain = SinkChain([*sinks, self.sink], on_error=self.errors.append)
        self.period_s = period_s
        self.warm: dict[str, list[float]] = {}
        self.scheduler = Scheduler(
            self.store, InlineExecutor(fn), rules, late_s=LATE_S, f0=50.0, period_s=lambda: self.period_s,
            on_results=self.chain.write_results, on_period=self.chain.write_period, warm_starts=self.warm,
            options=options if options is not None else {"n_starts": 3}, n_starts_warm=1, clock=self.clock,
            input_history=input_history,
        )

    def start(self) -> Bench:
        self.scheduler.start()
        self.clock.settle()
        return self

    def feed(self, bus: str, t_end: float, seconds: float = 3.0, *, keep=None, v_std: float = 0.01,
             seed: int = 0) -> None:
        """Frames of ``bus`` at FS in (t_end - seconds, t_end]; ``keep(t)`` selects some of them."""
        k = np.arange(round((t_end - seconds) * FS) + 1, round(t_end * FS) + 1)
        t = k / FS
        if keep is not None:
            t = t[keep(t)]
        rng = np.random.default_rng(seed)
        n = t.size
        self.source.push_window(bus, t, V=1.0 + v_std * rng.standard_normal(n), theta=0.01 * rng.standard_normal(n),
                                P=0.8 + 0.01 * rng.standard_normal(n), Q=0.3 + 0.01 * rng.standard_normal(n))

    def run_to(self, t: float) -> None:
        """Move the clock to ``t`` and wait until the scheduler has done everything due by then."""
        self.clock.advance_to(t)
        self.clock.settle()

    def period(self, boundary: float, *buses: str) -> None:
        """Frames of ``buses`` up to ``boundary`` arrive in time (at ``boundary``), then the period runs."""
        self.run_to(boundary)
        for bus in buses:
            self.feed(bus, boundary)
        self.run_to(boundary + LATE_S)

    def stop(self) -> None:
        self.scheduler.stop()


@pytest.fixture
def bench():
    made: list[Bench] = []

    def make(**kwargs) -> Bench:
        made.append(Bench(**kwargs))
        return made[-1]

    yield make
    for b in made:
        b.stop()


def test_boundaries_are_multiples_of_T_and_periods_run_after_the_late_allowance(bench):
    b = bench(period_s=10.0, start=T0 + 3.7).start()
    assert b.scheduler.next_period == T0 + 10
    b.run_to(T0 + 10)
    b.feed("b1", T0 + 10)
    b.run_to(T0 + 10 + LATE_S - 0.01)
    assert b.sink.periods == []  # still inside the late-data allowance
    b.run_to(T0 + 10 + LATE_S)
    for k in (2, 3):
        b.period(T0 + 10 * k, "b1")
    assert [p.period for p in b.sink.periods] == [T0 + 10, T0 + 20, T0 + 30]
    assert all(p.period % 10.0 == 0 and p.period_s == 10.0 for p in b.sink.periods)
    assert [p.completed_at for p in b.sink.periods] == [T0 + 10 + LATE_S, T0 + 20 + LATE_S, T0 + 30 + LATE_S]
    assert [p.latency_s for p in b.sink.periods] == [0.0, 0.0, 0.0]  # the clock did not move during a period
    assert [(r.period, r.status, r.completed_at) for r in b.sink.results] == [
        (T0 + 10 * k, "ok", T0 + 10 * k + LATE_S) for k in (1, 2, 3)]
    assert b.scheduler.next_period == T0 + 40


def test_a_changed_period_takes_effect_from_the_next_boundary(bench):
    class ChangesT(MemorySink):
        """A PUT /config arriving while the first period is being computed."""

        def write_results(self, batch, payloads):
            super().write_results(batch, payloads)
            if b.period_s != 4.0:
                b.period_s = 4.0
                b.scheduler.replan()

    b = bench(period_s=10.0, start=T0 + 1.0, sinks=(ChangesT("put-config"),)).start()
    b.period(T0 + 10, "b1")
    assert b.scheduler.next_period == T0 + 12  # the first multiple of the new T after the last boundary
    for boundary in (T0 + 12, T0 + 16):
        b.period(boundary, "b1")
    assert [(p.period, p.period_s) for p in b.sink.periods] == [(T0 + 10, 10.0), (T0 + 12, 4.0), (T0 + 16, 4.0)]
    assert [r.period_s for r in b.sink.results] == [10.0, 4.0, 4.0]


def test_a_change_while_waiting_replans_the_boundary_being_waited_for(bench):
    b = bench(period_s=10.0, start=T0 + 1.0).start()
    assert b.scheduler.next_period == T0 + 10
    b.period_s = 4.0
    b.scheduler.replan()
    b.clock.advance(0.0)
    b.clock.settle()
    assert b.scheduler.next_period == T0 + 4
    b.period(T0 + 4, "b1")
    assert [(p.period, p.period_s) for p in b.sink.periods] == [(T0 + 4, 4.0)]


def test_skipped_windows_carry_the_exact_reason(bench):
    b = bench(period_s=10.0, start=T0 + 1.0).start()
    end = T0 + 10
    b.run_to(end)
    b.feed("ok", end)
    b.feed("stale", end - 5.0)  # arriving now, stamped older than the window: a PMU clock 5 s behind
    b.feed("coverage", end, keep=lambda t: np.arange(t.size) % 2 == 0)  # half the frames, 40 ms apart
    b.feed("gap", end, keep=lambda t: (t <= end - 1.3) | (t > end - 1.0))  # 85 % of the frames, one 0.32 s gap
    b.feed("flat", end, v_std=0.0)  # V constant: no ambient excitation
    b.run_to(end + LATE_S)
    got = {r.bus: (r.status, r.reason) for r in b.sink.results}
    assert got == {"ok": ("ok", None), "stale": ("skipped", "clock_offset"), "coverage": ("skipped", "coverage"),
                   "gap": ("skipped", "gap"), "flat": ("skipped", "no_excitation")}
    summary = b.sink.periods[0]
    assert (summary.n_ok, summary.n_failed, summary.n_skipped) == (1, 0, 4)
    frames = {r.bus: r.n_frames for r in b.sink.results}
    assert frames == {"ok": 100, "stale": 0, "coverage": 50, "gap": 85, "flat": 100}


def test_warm_starts_are_carried_from_one_period_to_the_next(bench):
    b = bench(period_s=10.0, start=T0 + 1.0).start()
    for k in (1, 2):
        b.period(T0 + 10 * k, "b1")
    b.period(T0 + 30)  # no new data: skipped, the warm start stays
    b.period(T0 + 40, "b1")
    rows = [(r.status, r.warm_start, r.parameters.dynamic["a"] if r.parameters else None,
             r.parameters.n_starts if r.parameters else None) for r in b.sink.results]
    assert rows == [("ok", False, 41.0, 3), ("ok", True, 42.0, 1), ("skipped", False, None, None),
                    ("ok", True, 43.0, 1)]
    assert b.warm == {"b1": [43.0, 10.0, 1.0, 0.3]}


def test_a_failing_sink_stops_neither_the_other_sinks_nor_the_periods(bench):
    broken = MemorySink("broken", persists=True, fail=True)
    b = bench(period_s=10.0, start=T0 + 1.0, sinks=(broken,)).start()
    for k in (1, 2):
        b.period(T0 + 10 * k, "b1", "b2")
    assert [p.period for p in b.sink.periods] == [T0 + 10, T0 + 20]
    assert sorted((r.period, r.bus) for r in b.sink.results) == [(T0 + 10, "b1"), (T0 + 10, "b2"),
                                                                  (T0 + 20, "b1"), (T0 + 20, "b2")]
    assert b.errors == ["broken", "broken"] * 2  # results, then period, each period
    assert [k for _, k, _ in broken.journal] == ["results", "period"] * 2  # it was tried every time


def test_results_are_persisted_before_they_are_published(bench, tmp_path):
    journal: list = []
    storage = Storage(tmp_path / "aslm.sqlite")
    stored_when_published: list[bool] = []

    class Publisher(MemorySink):
        def write_results(self, batch, payloads):
            stored_when_published.extend(storage.latest(r.bus) == r for r in batch)
            super().write_results(batch, payloads)

        def write_diagnosis(self, bus, period, payload):
            stored_when_published.append(storage.latest_diagnoses().get(bus) == payload)
            super().write_diagnosis(bus, period, payload)

    # Given in the wrong order on purpose: the chain puts the persisting sinks first.
    pub, db = Publisher("pub", journal=journal), MemorySink("db", persists=True, journal=journal)
    b = bench(period_s=10.0, start=T0 + 1.0, sinks=(pub, StorageSink(storage, 1e9), db)).start()
    b.period(T0 + 10, "b1", "b2")
    assert stored_when_published == [True, True]
    assert journal == [("db", "results", ("b1", "b2")), ("pub", "results", ("b1", "b2")),
                       ("db", "period", T0 + 10), ("pub", "period", T0 + 10)]
    b.chain.write_diagnosis("b1", T0 + 10, '{"bus": "b1", "period": 1000010.0, "verdict": "consistent"}')
    assert [name for name, kind, _ in journal if kind == "diagnosis"] == ["db", "pub"]
    assert stored_when_published == [True, True, True]
    assert storage.periods(1)[0].period == T0 + 10
    assert b.sink.diagnoses == [{"bus": "b1", "period": T0 + 10, "verdict": "consistent"}]
    storage.close()


def test_the_inlet_validates_against_the_injected_clock(bench):
    b = bench(start=T0)
    t = T0 + np.array([4.0, 4.02, 6.0])  # the last one beyond max_future_s = 5 s of the clock
    n = t.size
    msg = encode_json(FrameBatch(t=t, V=np.ones(n), theta=np.zeros(n), P=np.ones(n), Q=np.zeros(n)))
    b.source.push_message("b1", msg, "application/json")
    b.source.push_message("b1", b"not json", "application/json")
    counts = b.store.counts("b1")
    assert counts.buffered == 2 and counts.rejected == {"future": 1}
    assert sum(counts.messages_rejected.values()) == 1


def test_the_real_identifier_runs_inline_and_is_warm_started(bench, eq_window):
    fs = 100.0
    rules = QualityRules(10.0, fs, min_coverage=0.9, max_gap_s=0.2, min_v_std=1e-5)
    b = bench(period_s=20.0, start=T0 + 1.0, fn="service.worker:identify_window", rules=rules, frame_rate=fs,
              options={"n_starts": 3, "lowpass_hz": 2.0}).start()
    w = eq_window
    for k in (1, 2):
        end = T0 + 20 * k
        b.run_to(end)
        b.source.push_window("eq", w.t - w.t[-1] + end, w.V, w.theta, w.P, w.Q)
        b.run_to(end + LATE_S)
    first, second = b.sink.results
    assert (first.status, first.warm_start, second.status, second.warm_start) == ("ok", False, "ok", True)
    for res in (first, second):
        d = np.array([res.parameters.dynamic[k] for k in ("a", "b", "H2", "Tm")])
        assert np.all(np.abs(d / D_TRUE - 1) < 0.05), d


def test_noisy_inputs_are_smoothed_with_the_spectrum_of_the_windows_before_them_at_any_period(bench):
    """With a history of k = 3 windows (the service's default 6 makes the test longer, not different) and a period
    of 50 s: the buffer holds the three 10 s windows before the one identified, and the noisy bus's window is
    identified with their spectrum (the identifier's own mark in ``quality``); a bus whose data began too late for
    a full history, and one whose V and θ are exact, are identified alone."""
    from conftest import equation_window

    fs = 50.0
    rules = QualityRules(10.0, fs, 0.9, 0.2, 1e-5)
    b = bench(period_s=50.0, start=T0 + 1.0, fn="service.worker:identify_window", rules=rules, frame_rate=fs,
              options={"n_starts": 1}, input_history=3).start()
    assert b.store.capacity == int(np.ceil((10.0 + 30.0 + LATE_S + 3.0) * fs))
    rec = equation_window(seed=6, fs=fs, fine=4, duration=50.0)
    rng = np.random.default_rng(2)
    v_noisy = rec.V + 1e-3 * rng.standard_normal(rec.t.size)
    th_noisy = rec.theta + 1e-3 * rng.standard_normal(rec.t.size)
    for k in range(1, 6):
        end = T0 + 10 * k
        b.run_to(end)
        sel = (rec.t > 10 * (k - 1)) & (rec.t <= 10 * k)
        b.source.push_window("noisy", rec.t[sel] + T0, v_noisy[sel], th_noisy[sel], rec.P[sel], rec.Q[sel])
        b.source.push_window("exact", rec.t[sel] + T0, rec.V[sel], rec.theta[sel], rec.P[sel], rec.Q[sel])
        if k >= 3:  # its history would begin at 10 s
            b.source.push_window("late", rec.t[sel] + T0, v_noisy[sel], th_noisy[sel], rec.P[sel], rec.Q[sel])
    b.run_to(T0 + 50.0 + LATE_S)
    got = {bus: [r.parameters.quality.get("input_spectrum_windows") for r in b.sink.results if r.bus == bus]
           for bus in ("noisy", "late", "exact")}
    assert got == {"noisy": [3.0], "late": [None], "exact": [None]}
    assert all(r.status == "ok" and "weighted_chi2" in r.parameters.quality for r in b.sink.results if r.bus != "exact")


def test_the_service_runs_without_zenoh_on_a_manual_clock(tmp_path):
    from service_helpers import settings_for

    from service.app import Service

    clock = ManualClock(T0 + 1.0)
    settings = settings_for(tmp_path, 7447, sources=[], sinks=["storage"], period_s=10.0, window_s=WINDOW_S,
                            late_s=LATE_S, identify_fn=FAKE, diagnose_every=0, workers=1)
    svc = Service(settings, rest=False, clock=clock).start()
    try:
        clock.settle(30)
        inlet = Inlet(svc.store, max_future_s=settings.max_future_s, f0=settings.f0, clock=clock)
        feeder = MemorySource()
        feeder.start(inlet)
        clock.advance_to(T0 + 10)
        t = T0 + 10 - np.arange(150)[::-1] / FS
        rng = np.random.default_rng(0)
        feeder.push_window("b1", t, 1 + 0.01 * rng.standard_normal(t.size), np.zeros(t.size), np.full(t.size, 0.8),
                           np.full(t.size, 0.3))
        clock.advance_to(T0 + 10 + LATE_S)
        clock.settle(30)
        assert [(p.period, p.n_ok) for p in svc.storage.periods()] == [(T0 + 10, 1)]
        assert svc.latest.results["b1"].completed_at == T0 + 10 + LATE_S
        assert not svc.context.zenoh_opened  # neither a source nor a sink asked for Zenoh
    finally:
        svc.stop()


def test_the_scheduler_thread_survives_an_error_outside_a_period_and_reports_its_death(bench):
    b = bench(period_s=10.0, start=T0 + 1.0).start()
    b.scheduler.restart_delay_s = 0.0
    b.period(T0 + 10, "b1")
    plan = b.scheduler.period_s
    failures = ["period_s unreadable"]

    def flaky() -> float:
        if failures:
            raise RuntimeError(failures.pop())
        return plan()

    b.scheduler.period_s = flaky
    b.scheduler.replan()  # the loop plans again, reads T, and raises outside run_period
    b.clock.advance(0.0)
    b.clock.settle()
    assert b.scheduler.restarts == 1 and b.scheduler.alive
    assert "RuntimeError: period_s unreadable" in b.scheduler.problem()
    b.period(T0 + 20, "b1")
    assert [p.period for p in b.sink.periods] == [T0 + 10, T0 + 20]
    assert b.scheduler.problem() is None  # a period completed since the restart


def test_boundaries_skipped_while_a_period_ran_late_leave_overrun_records(bench):
    class Slow(MemorySink):
        """The first period's results take 25 s of the clock to report: T0+20 and T0+30 pass meanwhile."""

        def write_results(self, batch, payloads):
            super().write_results(batch, payloads)
            if len(self.results) == 2:
                b.clock.advance(25.0)

    b = bench(period_s=10.0, start=T0 + 1.0, sinks=(Slow("slow"),)).start()
    b.period(T0 + 10, "b1", "b2")
    assert b.scheduler.next_period == T0 + 40
    b.period(T0 + 40, "b1", "b2")
    got = [(p.period, p.status, p.no_result, p.n_ok) for p in b.sink.periods]
    assert got == [(T0 + 10, "completed", [], 2), (T0 + 20, "overrun", ["b1", "b2"], 0),
                   (T0 + 30, "overrun", ["b1", "b2"], 0), (T0 + 40, "completed", [], 2)]
    assert [p.completed_at for p in b.sink.periods[1:3]] == [T0 + 35.5, T0 + 35.5]  # when it was noticed
    assert b.scheduler.overruns == 2


class HoldingExecutor(InlineExecutor):
    """Identifications run inline; diagnoses (background tasks) wait until the test releases them."""

    def __init__(self, fn_path: str) -> None:
        super().__init__(fn_path)
        self.held: list = []
        self.order: list[tuple[str, str]] = []  # (kind, bus) in submission order

    def submit(self, task):
        self.order.append(("diagnosis" if task.background else "identify", task.bus))
        if not task.background:
            return super().submit(task)
        from concurrent.futures import Future
        fut = Future()
        self.held.append((task, fut))
        return fut

    def release(self, n: int = 1) -> None:
        from service.executors.base import TaskOutcome
        for _ in range(n):
            task, fut = self.held.pop(0)
            fut.set_result(TaskOutcome(ok=True, value={"verdict": "consistent"}))


def test_identification_never_waits_behind_diagnoses_and_late_diagnoses_are_shed(bench):
    b = bench(period_s=10.0, start=T0 + 1.0)
    ex = HoldingExecutor(FAKE)
    reports: list[tuple[str, float, str | None]] = []
    b.scheduler = Scheduler(
        b.store, ex, RULES, late_s=LATE_S, f0=50.0, period_s=lambda: b.period_s, on_results=b.chain.write_results,
        on_period=b.chain.write_period, warm_starts=b.warm, options={"n_starts": 3}, diagnose_every=1,
        on_diagnosis=lambda bus, period, outcome: reports.append((bus, period, outcome.reason)), clock=b.clock,
        diagnose_in_flight=1)
    b.start()
    buses = ("b1", "b2", "b3")
    b.period(T0 + 10, *buses)
    assert ex.order == [("identify", bus) for bus in buses] + [("diagnosis", "b1")]  # one at a time
    assert b.scheduler.diagnoses.waiting == 2
    ex.order.clear()
    b.period(T0 + 20, *buses)
    # The period's identifications went straight to the executor: b2 and b3's diagnoses of T0+10 were
    # still waiting, were not handed out during the period, and were shed when those of T0+20 came.
    assert ex.order == [("identify", bus) for bus in buses]
    assert reports == [("b2", T0 + 10, "shed"), ("b3", T0 + 10, "shed")]
    assert b.scheduler.diagnoses.shed == 2 and b.scheduler.diagnoses.waiting == 3
    ex.release()  # b1 of T0+10 finishes: the next one (b1 of T0+20) is handed out
    assert reports[-1] == ("b1", T0 + 10, None) and ex.order[-1] == ("diagnosis", "b1")
    assert len(ex.held) == 1
