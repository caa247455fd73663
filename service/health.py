"""Whether each part of a running service does its job: what ``GET /health`` reports as ``degraded`` and
the ``aslm_component_ok{component}`` metric shows.

Parts: the scheduler (its thread alive, not restarted since the last completed period, no period overdue
or running past the next boundary), the storage (its writes succeed), the ingest (frames still reach the
buffers), the pool (its dispatcher and workers alive, the last period not failed throughout).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

from service.buffers import BufferStore
from service.clock import Clock
from service.models import PeriodSummary

COMPONENTS = ("scheduler", "storage", "ingest", "pool")
"""The parts of the service /health reports on, in its order."""

INGEST_STALE_S = 60.0
"""With sources configured, no frame buffered for this long is an ingest problem [s]."""

OVERDUE_GRACE_S = 5.0
"""A period not started this long after its boundary + late allowance is overdue [s]."""


class IngestWatch:
    """Notices when frames stop reaching the buffers (none arrive, or every one is dropped).

    Parameters
    ----------
    store : BufferStore
    clock : Clock
    stale_s : float
        How long without a frame buffered is a problem [s].

    Notes
    -----
    It compares the buffers' totals between calls (each ``/health`` or ``/metrics`` request), so the
    ingest's hot path does nothing for it; the time it reports is as fine as those requests are frequent.
    """

    def __init__(self, store: BufferStore, clock: Clock, stale_s: float = INGEST_STALE_S) -> None:
        self.store = store
        self.clock = clock
        self.stale_s = stale_s
        self._lock = threading.Lock()
        self._buffered = 0
        self._received = 0
        self._since = clock.now()  # when frames_buffered last grew (or the watch started)

    def problem(self) -> str | None:
        """Why the ingest is not doing its job, or None."""
        tot = self.store.totals()
        now = self.clock.now()
        with self._lock:
            if tot.frames_buffered != self._buffered:
                self._buffered, self._received, self._since = tot.frames_buffered, tot.frames_received, now
                return None
            idle = now - self._since
            if idle <= self.stale_s:
                return None
            dropped = tot.frames_received - self._received
        if dropped > 0:
            reasons = ", ".join(f"{k} {v}" for k, v in sorted(tot.frames_rejected.items()))
            return f"none of the {dropped} frames received in the last {idle:.0f} s was buffered (dropped: {reasons})"
        return f"no frames received for {idle:.0f} s"


def scheduler_problem(scheduler, clock: Clock, late_s: float, period_s: float) -> str | None:
    """Why the scheduler is not doing its job, or None.

    Parameters
    ----------
    scheduler : service.scheduler.Scheduler or None
    clock : Clock
    late_s, period_s : float
        Late-data allowance and period T in force [s].
    """
    if scheduler is None:
        return "not started"
    found = scheduler.problem()
    if found is not None:
        return found
    now = clock.now()
    running, upcoming = scheduler.running_period, scheduler.next_period
    if running is not None and now > running + late_s + period_s:
        return (f"period {running:.0f} still running {now - running - late_s:.0f} s after its start, longer than "
                f"T = {period_s:g} s: the next boundaries are skipped (overrun)")
    if running is None and upcoming is not None and now > upcoming + late_s + OVERDUE_GRACE_S:
        return f"period {upcoming:.0f} overdue by {now - upcoming - late_s:.0f} s"
    return None


def pool_problem(executor, last: PeriodSummary | None) -> str | None:
    """Why the executor is not doing its job (its own ``problem()``, or every identification of the last
    completed period failed), or None."""
    check = getattr(executor, "problem", None)
    found = check() if check is not None else None
    if found is not None:
        return found
    if last is not None and last.n_failed and not last.n_ok:
        return f"every identification of period {last.period:.0f} failed ({last.n_failed})"
    return None


class HealthCollector:
    """Prometheus collector: ``aslm_component_ok{component}`` and the supervision counters.

    Parameters
    ----------
    problems : callable
        Returns component → reason it is not doing its job (None: it is).
    counters : callable
        Returns ``scheduler_restarts`` and ``diagnoses_shed`` (counts since start).
    """

    def __init__(self, problems: Callable[[], dict[str, str | None]], counters: Callable[[], dict[str, int]]) -> None:
        self._problems = problems
        self._counters = counters

    def collect(self) -> Iterator:
        ok = GaugeMetricFamily("aslm_component_ok", "1 when the component does its job, 0 when /health reports "
                               "it degraded", labels=["component"])
        for component, reason in self._problems().items():
            ok.add_metric([component], 0.0 if reason else 1.0)
        yield ok
        counts = self._counters()
        restarts = CounterMetricFamily("aslm_scheduler_restarts", "Restarts of the scheduling thread after it died")
        restarts.add_metric([], counts["scheduler_restarts"])
        shed = CounterMetricFamily("aslm_diagnoses_shed", "Diagnoses dropped before they started: a newer round "
                                   "was queued (reason 'shed')")
        shed.add_metric([], counts["diagnoses_shed"])
        yield from (restarts, shed)
