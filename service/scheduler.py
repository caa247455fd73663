"""Periodic identification: every period T (wall-clock aligned) cut, check, submit, collect, publish.

Timeline of one period with boundary B (a multiple of T since the epoch)::

    B - window_s ........ B ........ B + late_s  -> cut windows (B - window_s, B] by PMU time
                                                 -> quality check, submit good ones
                                                 -> results persisted, then published
    latency = time of the last result published - (B + late_s)
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
from service.executors.base import Executor, TaskOutcome, WindowTask
from service.models import BusResult, Identified, PeriodSummary
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
    """

    def __init__(self, store: BufferStore, executor: Executor, rules: QualityRules, *, late_s: float,
                 f0: float, period_s: Callable[[], float], on_results: Callable[[list[BusResult]], None],
                 on_period: Callable[[PeriodSummary], None], warm_starts: dict[str, list[float]],
                 options: dict | None = None, n_starts_warm: int | None = None, diagnose_every: int = 0,
                 on_diagnosis: Callable[[str, float, TaskOutcome], None] | None = None,
                 clock: Clock = SYSTEM_CLOCK) -> None:
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

    def start(self) -> None:
        """Start the scheduling thread."""
        self._thread = threading.Thread(target=self._loop, name="aslm-scheduler", daemon=True)
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

    def _loop(self) -> None:
        last = -math.inf
        while not self._stop.is_set():
            period_s = self.period_s()
            boundary = next_boundary(max(self.clock.now() - self.late_s, last), period_s)
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
            last = boundary

    def run_period(self, boundary: float, period_s: float) -> PeriodSummary:
        """Cut, check, identify and report every known bus for the period ending at ``boundary``."""
        self.running_period = boundary
        started = self.clock.now()
        done: list[BusResult] = []
        pending: dict[Future, tuple[str, Window, bool]] = {}
        # Finished futures are pushed here by their done-callbacks: O(1) per result, where calling
        # concurrent.futures.wait() on all pending futures after each completion is O(n²) per period.
        completed: queue.SimpleQueue[Future] = queue.SimpleQueue()
        skipped: list[BusResult] = []
        identified: dict[str, tuple[Window, dict]] = {}
        group: list[tuple[WindowTask, Window, bool]] = []

        def submit(group: list[tuple[WindowTask, Window, bool]]) -> None:
            futs = self.executor.submit_many([task for task, _, _ in group])
            for fut, (task, cut, warm) in zip(futs, group, strict=True):
                pending[fut] = (task.bus, cut, warm)
                fut.add_done_callback(completed.put)

        for bus in self.store.buses():
            buf = self.store.buffer(bus, create=False)
            if buf is None:
                continue
            newest = buf.newest
            end = min(boundary, newest)  # a PMU running slightly behind still gives its latest window
            cut = (buf.cut(end - self.rules.window_s, end, f0=self.f0, bus=bus)
                   if newest > boundary - self.rules.window_s else None)
            reason = "no_data" if cut is None else check_window(cut, self.rules)
            if reason is not None:
                skipped.append(self._record(bus, boundary, period_s, "skipped", reason, cut, False))
                continue
            warm = self.warm_starts.get(bus)
            task = WindowTask(cut, warm_start=list(warm) if warm is not None else None,
                              options=self.options if warm is None else self.warm_options)
            group.append((task, cut, warm is not None))
            if len(group) >= 64:  # submitted in groups: the workers start while the rest is cut
                submit(group)
                group = []
                time.sleep(0)  # let the REST/ingest threads have the GIL between groups
        if group:
            submit(group)
        if skipped:
            self._emit(skipped, done)
        batch: list[BusResult] = []
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
                batch, last_emit = [], time.monotonic()
        finished_at = self.clock.now()
        summary = PeriodSummary(
            period=boundary, period_s=period_s,
            n_ok=sum(r.status == "ok" for r in done), n_failed=sum(r.status == "failed" for r in done),
            n_skipped=sum(r.status == "skipped" for r in done),
            latency_s=finished_at - max(started, boundary + self.late_s), completed_at=finished_at,
        )
        self.on_period(summary)
        self.running_period = None
        self.periods_run += 1
        if self.diagnose_every > 0 and self.on_diagnosis is not None and self.periods_run % self.diagnose_every == 0:
            self._submit_diagnoses(boundary, identified)
        log.info("period %s: %d ok, %d failed, %d skipped in %.2f s", utc_text(boundary), summary.n_ok, summary.n_failed,
                 summary.n_skipped, summary.latency_s)
        return summary

    def _submit_diagnoses(self, boundary: float, identified: dict[str, tuple[Window, dict]]) -> None:
        """Queue the discrepancy diagnosis of each bus identified this period (results come back async)."""
        for bus, (cut, value) in identified.items():
            task = WindowTask(cut, fn="service.worker:diagnose_window", previous=value)
            fut = self.executor.submit(task)
            fut.add_done_callback(lambda f, bus=bus: self._diagnosed(bus, boundary, f))

    def _diagnosed(self, bus: str, boundary: float, fut: Future) -> None:
        try:
            self.on_diagnosis(bus, boundary, fut.result())
        except Exception:  # noqa: BLE001 - one bus's diagnosis never stops the others
            log.exception("reporting the diagnosis of %s failed", bus)

    def _emit(self, batch: list[BusResult], done: list[BusResult]) -> None:
        try:
            self.on_results(batch)
        except Exception:  # noqa: BLE001 - storage/publication trouble must not stop the period
            log.exception("reporting %d results failed", len(batch))
        done.extend(batch)

    def _record(self, bus: str, boundary: float, period_s: float, status: str, reason: str | None,
                cut: Window | None, warm: bool, outcome: TaskOutcome | None = None) -> BusResult:
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
            parameters=params,
        )
