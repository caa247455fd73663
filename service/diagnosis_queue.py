"""The diagnoses waiting for the executor: handed out a few at a time, never while a period runs, and
shed when a newer round arrives before they started.

Why a queue of its own: handing every diagnosis of a round to the executor at once put them all ahead
of the next period's identifications (200 buses: the identifications waited 76.7 s and five period
boundaries were skipped, issue 17).  Here at most ``in_flight`` diagnoses are in the executor; none is
handed out while the scheduler runs a period; a round queued while an earlier one still waits replaces
it, and each diagnosis dropped that way is reported as failed with reason ``shed``.
"""

from __future__ import annotations

import collections
import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future

from service.executors.base import Executor, TaskOutcome, WindowTask

log = logging.getLogger(__name__)


class DiagnosisQueue:
    """Diagnosis tasks between the scheduler and the executor.

    Parameters
    ----------
    executor : Executor
    report : callable
        Called with (bus, period [s], :class:`TaskOutcome`) of each diagnosis done or shed.
    in_flight : int
        Diagnoses in the executor at a time (the service: workers − 1, so one worker is always free for
        identification when a period starts).
    what : str
        What the tasks are, in the log (the tracking sink queues its joint pooled fits the same way).
    """

    def __init__(self, executor: Executor, report: Callable[[str, float, TaskOutcome], None], *,
                 in_flight: int = 1, what: str = "diagnoses") -> None:
        self.executor = executor
        self.report = report
        self.what = what
        self.in_flight = max(1, int(in_flight))
        self.shed = 0
        self._waiting: collections.deque[tuple[float, WindowTask]] = collections.deque()
        self._running = 0
        self._paused = False
        self._pumping = False
        self._lock = threading.Lock()

    @property
    def waiting(self) -> int:
        """Diagnoses not handed to the executor yet."""
        return len(self._waiting)

    def enqueue(self, period: float, tasks: list[WindowTask]) -> None:
        """Queue the diagnoses of one period [s]; those of earlier periods still waiting are shed."""
        with self._lock:
            dropped = list(self._waiting)
            self._waiting = collections.deque((period, task) for task in tasks)
            self.shed += len(dropped)
        if dropped:
            log.warning("%d %s of period %.0f shed: not started when the %s of period %.0f were queued (add "
                        "workers%s)", len(dropped), self.what, dropped[0][0], self.what, period,
                        ", or raise diagnose_every" if self.what == "diagnoses" else "")
        for old, task in dropped:
            self._report(task.bus, old, TaskOutcome(ok=False, reason="shed", message=(
                f"not started before the {self.what} of period {period:.0f} were queued")))
        self._pump()

    def pause(self) -> None:
        """Hand out nothing more until :meth:`resume` (a period runs)."""
        with self._lock:
            self._paused = True

    def resume(self) -> None:
        """Hand out waiting diagnoses again."""
        with self._lock:
            self._paused = False
        self._pump()

    def _pump(self) -> None:
        # Iterative, and re-entered only through the flag: an executor may finish a task inside submit()
        # (the inline one does), which calls _finished() and _pump() again from within this loop.
        with self._lock:
            if self._pumping:
                return
            self._pumping = True
        while True:
            with self._lock:
                if self._paused or not self._waiting or self._running >= self.in_flight:
                    self._pumping = False  # decided under the lock: a caller arriving now pumps itself
                    return
                period, task = self._waiting.popleft()
                self._running += 1
            try:
                fut = self.executor.submit(task)
            except BaseException:
                with self._lock:
                    self._running -= 1
                    self._pumping = False
                raise
            fut.add_done_callback(lambda f, bus=task.bus, period=period: self._finished(bus, period, f))

    def _finished(self, bus: str, period: float, fut: Future) -> None:
        with self._lock:
            self._running -= 1
        self._report(bus, period, fut.result())
        self._pump()

    def _report(self, bus: str, period: float, outcome: TaskOutcome) -> None:
        try:
            self.report(bus, period, outcome)
        except Exception:  # noqa: BLE001 - one bus's report never stops the others
            log.exception("reporting the %s of %s failed", self.what, bus)
