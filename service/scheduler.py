"""Periodic identification: every period T (wall-clock aligned) cut, check, submit, collect, publish.

Timeline of one period with boundary B (a multiple of T since the epoch)::

    B - window_s ........ B ........ B + late_s  -> cut windows (B - window_s, B] by PMU time
                                                 -> quality check, submit good ones
                                                 -> results persisted, then published
    latency = time of the last result published - (B + late_s)

A bus that never buffered a valid frame gets no result (its rejections are in the ingest accounting).
A skipped bus is reported once per change of state: the first period it is skipped for a reason gives
a result row; the following periods skipped for the same reason give none (the period summary still
counts them), until it is identified, fails or is skipped for another reason.  A bus whose frames keep
arriving stamped older than the window (a PMU clock behind) is skipped as ``clock_offset`` with the
measured offset.  After each period, buses not heard from for ``bus_idle_s`` are evicted.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass

from aslm_core.params import DYNAMIC_NAMES
from aslm_core.window import Window
from service.buffers import BufferStore
from service.clock import SYSTEM_CLOCK, Clock
from service.diagnosis_queue import DiagnosisQueue
from service.executors.base import Executor, TaskOutcome, WindowTask
from service.models import BusResult, Identified, PeriodSummary
from service.sinks.base import ResultBatch
from service.timefmt import utc_text

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class QualityRules:
    """Window acceptance rules.

    Attributes
    ----------
    window_s : float
        Window length [s].
    frame_rate : float
        Nominal frame rate [frames/s].
    min_coverage : float
        Minimum fraction of the expected frames [-].
    max_gap_s : float
        Longest tolerated gap between consecutive frames [s].
    min_v_std : float
        Minimum standard deviation of V (ambient excitation) [pu].
    """

    window_s: float
    frame_rate: float
    min_coverage: float
    max_gap_s: float
    min_v_std: float


def check_window(cut: Window, rules: QualityRules) -> str | None:
    """Reason a window is unusable (``no_data``, ``coverage``, ``gap``, ``no_excitation``), or None."""
    n = cut.n
    if n < 2:
        return "no_data"
    if n < rules.min_coverage * rules.window_s * rules.frame_rate:
        return "coverage"
    t = cut.t
    if float((t[1:] - t[:-1]).max()) > rules.max_gap_s:
        return "gap"
    dv = cut.V - cut.V.mean()
    if math.sqrt(float(dv @ dv) / n) < rules.min_v_std:  # std of V, without np.std's overhead
        return "no_excitation"
    return None


def next_boundary(now: float, period_s: float) -> float:
    """First multiple of ``period_s`` since the epoch strictly after ``now`` [s]."""
    return (math.floor(now / period_s) + 1) * period_s


class Scheduler:
    """Runs periods in its own thread.

    Parameters
    ----------
    store : BufferStore
    executor : Executor
    rules : QualityRules
    late_s : float
        Late-data allowance [s].
    f0 : float
        Nominal frequency [Hz].
    period_s : callable
        Returns the period T in force [s]; read before planning each period.
    on_results : callable
        Called with each batch of finished :class:`BusResult` (persist, then publish).
    on_period : callable
        Called with the :class:`PeriodSummary` of each completed period.
    warm_starts : dict
        bus → D [a, b, H2, Tm] of its previous successful result (kept up to date here).
    options : dict
        :class:`aslm_core.IdentifyConfig` keyword arguments for every task.
    n_starts_warm : int or None
        ``n_starts`` (random starts) of the tasks of buses that have a warm start; None: ``options``'
        for every task.
    diagnose_every : int
        Diagnose every bus identified in every k-th period run (0: never); diagnoses are queued after
        the period's identifications and reported asynchronously through ``on_diagnosis``.
    on_diagnosis : callable
        Called with (bus, period, :class:`TaskOutcome`) of each finished diagnosis.
    clock : Clock
        Boundaries, waits, ``completed_at`` and latencies (default the system clock).
    on_start : callable, optional
        Called with (boundary [s], T [s], the buses known) as a period starts, before any result: the
        service persists it so that a period a crash interrupts is recorded at the next start.
    diagnose_in_flight : int
        Diagnoses handed to the executor at a time (:class:`~service.diagnosis_queue.DiagnosisQueue`).
    bus_idle_s : float or None
        Buses with no message for this long are evicted from the buffers after a period [s] (None:
        never).
    on_evicted : callable, optional
        Called with the buses evicted after a period.
    input_history : int or None
        k: each bus's task carries the k windows just before its window, cut from its buffer (which must hold
        them: :class:`~service.buffers.BufferStore`'s ``history_s``), and the identifier's noisy-input
        refinement is given V's and θ's spectrum pooled from them (:func:`service.worker.history_spectrum`);
        only where all k pass the window rules, else the window alone.  None: each window alone.

    Notes
    -----
    The thread is supervised: an exception outside a period (planning, waiting) is logged, counted in
    ``restarts`` and the loop starts again after ``restart_delay_s`` [s]; :meth:`problem` reports it until
    a period completes.  Every boundary leaves a :class:`PeriodSummary`: ``completed``; ``overrun`` for a
    boundary that passed while the previous period was still running (or while the loop restarted);
    ``interrupted`` for a period that raised.
    """

    #: Overrun records written at most for one gap (a clock jump of days at a short T); the rest are logged.
    MAX_OVERRUN_RECORDS = 1000

    def __init__(self, store: BufferStore, executor: Executor, rules: QualityRules, *, late_s: float,
                 f0: float, period_s: Callable[[], float], on_results: Callable[[list[BusResult]], None],
                 on_period: Callable[[PeriodSummary], None], warm_starts: dict[str, list[float]],
                 options: dict | None = None, n_starts_warm: int | None = None, diagnose_every: int = 0,
                 on_diagnosis: Callable[[str, float, TaskOutcome], None] | None = None,
                 clock: Clock = SYSTEM_CLOCK, on_start: Callable[[float, float, list[str]], None] | None = None,
                 diagnose_in_flight: int = 1, bus_idle_s: float | None = None,
                 on_evicted: Callable[[list[str]], None] | None = None,
                 input_history: int | None = None) -> None:
        self.store = store
        self.clock = clock
        self.executor = executor
        self.rules = rules
        self.late_s = late_s
        self.f0 = f0
        self.period_s = period_s
        self.on_results = on_results
        self.on_period = on_period
        self.warm_starts = warm_starts
        self.options = options or {}
        self.warm_options = self.options if n_starts_warm is None else {**self.options, "n_starts": n_starts_warm}
        self.diagnose_every = diagnose_every
        self.on_diagnosis = on_diagnosis
        self.periods_run = 0
        self._stop = threading.Event()
        self._replan = threading.Event()
        self._thread: threading.Thread | None = None
        self.next_period: float | None = None
        self.running_period: float | None = None
        self.on_start = on_start
        self.diagnoses = DiagnosisQueue(executor, self._diagnosed, in_flight=diagnose_in_flight)
        self.restarts = 0
        self.restart_delay_s = 1.0
        self.overruns = 0
        self._death: str | None = None  # why the loop last died, until a period completes after it
        self._last = -math.inf  # boundary of the last period run (kept across restarts of the loop)
        self._reported: set[str] = set()  # buses with a result in the period running
        self.bus_idle_s = bus_idle_s
        self.on_evicted = on_evicted
        self._skip_state: dict[str, str] = {}  # bus -> reason of its last reported skip
        self.input_history = input_history

    def start(self) -> None:
        """Start the scheduling thread."""
        self._thread = threading.Thread(target=self._supervise, name="aslm-scheduler", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 10.0) -> None:
        """Stop after the period in progress (if any) and join."""
        self._stop.set()
        self._replan.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def replan(self) -> None:
        """Recompute the next boundary now (the period changed)."""
        self._replan.set()

    @property
    def alive(self) -> bool:
        """Whether the scheduling thread runs."""
        return self._thread is not None and self._thread.is_alive()

    def problem(self) -> str | None:
        """Why the scheduler is not doing its job (its thread dead, or restarted since the last completed
        period), or None."""
        if self._thread is not None and not self._thread.is_alive() and not self._stop.is_set():
            return f"scheduler thread dead ({self._death or 'no reason recorded'})"
        if self._death is not None:
            return f"scheduler restarted {self.restarts} time(s); last death: {self._death}"
        return None

    def _supervise(self) -> None:
        """Run the loop; restart it after any exception it lets through (it must never die silently)."""
        while not self._stop.is_set():
            try:
                self._loop()
            except Exception as exc:  # noqa: BLE001 - supervision: log, count, report, restart
                self.restarts += 1
                self._death = f"{type(exc).__name__}: {exc}"
                self.next_period = None
                log.exception("scheduler loop died (restart %d in %g s)", self.restarts, self.restart_delay_s)
                self._stop.wait(self.restart_delay_s)
            else:
                return

    def _loop(self) -> None:
        while not self._stop.is_set():
            period_s = self.period_s()
            boundary = next_boundary(max(self.clock.now() - self.late_s, self._last), period_s)
            self._record_overruns(boundary, period_s)
            self.next_period = boundary
            self._replan.clear()
            delay = boundary + self.late_s - self.clock.now()
            if delay > 0 and self.clock.wait(self._replan, delay):
                continue  # period changed or stopping: plan again
            if self._stop.is_set():
                break
            try:
                self.run_period(boundary, period_s)
            except Exception:  # noqa: BLE001 - one bad period must not end the service
                log.exception("period %s failed", utc_text(boundary))
                self._missed(boundary, period_s, "interrupted", sorted(set(self.store.buses()) - self._reported))
            finally:
                self.running_period = None
                self.diagnoses.resume()
            self._last = boundary

    def _record_overruns(self, boundary: float, period_s: float) -> None:
        """A record for each boundary after the last period run and before ``boundary`` (they were skipped)."""
        if not math.isfinite(self._last):
            return
        first = math.floor(self._last / period_s) + 1
        skipped = int(round(boundary / period_s)) - first
        if skipped <= 0:
            return
        self.overruns += skipped
        buses = sorted(self.store.buses())
        log.warning("%d period boundar%s from %.0f skipped (overrun: the previous period was still running); "
                    "%d buses got no result", skipped, "y" if skipped == 1 else "ies", first * period_s,
                    len(buses))
        for k in range(max(0, skipped - self.MAX_OVERRUN_RECORDS), skipped):
            self._missed((first + k) * period_s, period_s, "overrun", buses)

    def _missed(self, boundary: float, period_s: float, status: str, no_result: list[str]) -> None:
        """Report the period of ``boundary`` as ``overrun`` or ``interrupted`` (buses without a result)."""
        now = self.clock.now()
        try:
            self.on_period(PeriodSummary(period=boundary, period_s=period_s, n_ok=0, n_failed=0, n_skipped=0,
                                         latency_s=now - (boundary + self.late_s), completed_at=now,
                                         status=status, no_result=no_result))
        except Exception:  # noqa: BLE001 - reporting trouble must not stop the scheduling
            log.exception("reporting the %s period %s failed", status, boundary)

    def run_period(self, boundary: float, period_s: float) -> PeriodSummary:
        """Cut, check, identify and report every known bus for the period ending at ``boundary``."""
        self.running_period = boundary
        self._reported = set()
        self.diagnoses.pause()  # identification goes first: no diagnosis is handed out while a period runs
        if self.on_start is not None:
            try:
                self.on_start(boundary, period_s, list(self.store.buses()))
            except Exception:  # noqa: BLE001 - the period runs even if its start could not be recorded
                log.exception("recording the start of period %s failed", boundary)
        started = self.clock.now()
        done: list[BusResult] = []
        pending: dict[Future, tuple[str, Window, bool]] = {}
        # Finished futures are pushed here by their done-callbacks: O(1) per result, where calling
        # concurrent.futures.wait() on all pending futures after each completion is O(n²) per period.
        completed: queue.SimpleQueue[Future] = queue.SimpleQueue()
        skipped: list[BusResult] = []
        identified: dict[str, tuple[Window, dict]] = {}
        group: list[tuple[WindowTask, Window, bool]] = []
        quiet = 0  # skipped again for the same reason: counted, not written

        def submit(group: list[tuple[WindowTask, Window, bool]]) -> None:
            futs = self.executor.submit_many([task for task, _, _ in group])
            for fut, (task, cut, warm) in zip(futs, group, strict=True):
                pending[fut] = (task.bus, cut, warm)
                fut.add_done_callback(completed.put)

        for bus in self.store.buses():
            buf = self.store.buffer(bus, create=False)
            if buf is None or buf.buffered == 0:  # unknown, or nothing but rejected frames: no result
                continue
            newest = buf.newest
            end = min(boundary, newest)  # a PMU running slightly behind still gives its latest window
            cut = (buf.cut(end - self.rules.window_s, end, f0=self.f0, bus=bus)
                   if newest > boundary - self.rules.window_s else None)
            reason = "no_data" if cut is None else check_window(cut, self.rules)
            if reason is not None:
                offset = None
                if cut is None and buf.last_arrival > boundary - self.rules.window_s:
                    reason, offset = "clock_offset", newest - buf.last_arrival  # frames came, stamped too old
                if self._skip_state.get(bus) == reason:
                    quiet += 1
                    continue
                self._skip_state[bus] = reason
                skipped.append(self._record(bus, boundary, period_s, "skipped", reason, cut, False,
                                            clock_offset_s=offset))
                continue
            self._skip_state.pop(bus, None)
            warm = self.warm_starts.get(bus)
            task = WindowTask(cut, warm_start=list(warm) if warm is not None else None,
                              options=self.options if warm is None else self.warm_options,
                              history=self._history(buf, bus, end) if self.input_history else ())
            group.append((task, cut, warm is not None))
            if len(group) >= 64:  # submitted in groups: the workers start while the rest is cut
                submit(group)
                group = []
                time.sleep(0)  # let the REST/ingest threads have the GIL between groups
        if group:
            submit(group)
        if skipped:
            self._emit(skipped, done)
        batch = ResultBatch()
        last_emit = time.monotonic()
        while pending:
            finished = []
            try:
                finished.append(completed.get(timeout=0.25))
                while len(finished) < 256:
                    finished.append(completed.get_nowait())
            except queue.Empty:
                pass
            for fut in finished:
                bus, cut, warm = pending.pop(fut)
                outcome: TaskOutcome = fut.result()
                try:
                    if outcome.ok:
                        res = self._record(bus, boundary, period_s, "ok", None, cut, warm, outcome)
                        batch.windows[bus] = cut  # for the sinks that keep samples (tracking's joint fit)
                        self.warm_starts[bus] = [res.parameters.dynamic[k] for k in DYNAMIC_NAMES]
                        identified[bus] = (cut, outcome.value)
                    else:
                        res = self._record(bus, boundary, period_s, "failed", outcome.reason, cut, warm, outcome)
                except Exception as exc:  # noqa: BLE001 - e.g. a non-finite D: fails this bus only
                    log.warning("bus %s: unusable result: %s", bus, exc)
                    res = self._record(bus, boundary, period_s, "failed", "bad_result", cut, warm)
                batch.append(res)
            # Report in groups (one SQLite transaction each) rather than one by one.
            if batch and (not pending or len(batch) >= 64 or time.monotonic() - last_emit > 0.25):
                self._emit(batch, done)
                batch, last_emit = ResultBatch(), time.monotonic()
        finished_at = self.clock.now()
        summary = PeriodSummary(
            period=boundary, period_s=period_s,
            n_ok=sum(r.status == "ok" for r in done), n_failed=sum(r.status == "failed" for r in done),
            n_skipped=sum(r.status == "skipped" for r in done) + quiet,
            latency_s=finished_at - max(started, boundary + self.late_s), completed_at=finished_at,
        )
        self.on_period(summary)
        self._evict_idle()
        self.running_period = None
        self._death = None
        self.periods_run += 1
        if self.diagnose_every > 0 and self.on_diagnosis is not None and self.periods_run % self.diagnose_every == 0:
            self._submit_diagnoses(boundary, identified)
        self.diagnoses.resume()
        log.info("period %s: %d ok, %d failed, %d skipped in %.2f s", utc_text(boundary), summary.n_ok, summary.n_failed,
                 summary.n_skipped, summary.latency_s)
        return summary

    def _history(self, buf, bus: str, end: float) -> tuple[Window, ...]:
        """The k windows of ``window_s`` just before the one ending at ``end`` [s], oldest first, cut from the bus's
        buffer; empty unless every one passes the window rules (a partial history is one window's scatter again)."""
        w, k = self.rules.window_s, self.input_history
        pieces = tuple(buf.cut(end - (k + 1 - j) * w, end - (k - j) * w, f0=self.f0, bus=bus) for j in range(k))
        return pieces if all(check_window(p, self.rules) is None for p in pieces) else ()

    def _evict_idle(self) -> None:
        """Forget buses not heard from for ``bus_idle_s`` (after their last results were written).

        Buses the store evicted to make room at its cap are forgotten here too, so that nothing kept
        per bus outlives the bus.
        """
        evicted = [] if self.bus_idle_s is None else self.store.evict_idle(self.clock.now() - self.bus_idle_s)
        if evicted:
            log.info("evicted %d bus(es) idle for more than %g s", len(evicted), self.bus_idle_s)
        gone = set(evicted) | {b for b in self._skip_state if self.store.buffer(b, create=False) is None}
        for bus in gone:
            self._skip_state.pop(bus, None)
        if gone and self.on_evicted is not None:
            self.on_evicted(sorted(gone))

    def _submit_diagnoses(self, boundary: float, identified: dict[str, tuple[Window, dict]]) -> None:
        """Queue the discrepancy diagnosis of each bus identified this period (results come back async);
        diagnoses of an earlier period still waiting are shed."""
        self.diagnoses.enqueue(boundary, [
            WindowTask(cut, fn="service.worker:diagnose_window", previous=value, background=True,
                       options={"input_noise": self.options["input_noise"]} if "input_noise" in self.options else {})
            for cut, value in identified.values()])

    def _diagnosed(self, bus: str, boundary: float, outcome: TaskOutcome) -> None:
        try:
            self.on_diagnosis(bus, boundary, outcome)
        except Exception:  # noqa: BLE001 - one bus's diagnosis never stops the others
            log.exception("reporting the diagnosis of %s failed", bus)

    def _emit(self, batch: list[BusResult], done: list[BusResult]) -> None:
        try:
            self.on_results(batch)
        except Exception:  # noqa: BLE001 - storage/publication trouble must not stop the period
            log.exception("reporting %d results failed", len(batch))
        done.extend(batch)
        self._reported.update(r.bus for r in batch)

    def _record(self, bus: str, boundary: float, period_s: float, status: str, reason: str | None,
                cut: Window | None, warm: bool, outcome: TaskOutcome | None = None,
                clock_offset_s: float | None = None) -> BusResult:
        params = None
        if outcome is not None and outcome.ok:
            # run_task has replaced non-finite floats by None (a non-finite D then fails validation).
            params = Identified.model_validate(outcome.value)
            if not all(math.isfinite(v) for v in params.dynamic.values()):
                raise ValueError(f"non-finite D {params.dynamic}")
        if outcome is not None and not outcome.ok and outcome.message:
            log.warning("bus %s: %s: %s", bus, outcome.reason, outcome.message)
        has = cut is not None and cut.n > 0
        return BusResult(
            bus=bus, period=boundary, period_s=period_s, status=status, reason=reason,
            window_start=float(cut.t[0]) if has else None, window_end=float(cut.t[-1]) if has else None,
            n_frames=cut.n if cut is not None else 0, warm_start=warm, completed_at=self.clock.now(),
            parameters=params, clock_offset_s=clock_offset_s,
        )
