"""Garbage collection while a service runs: automatic full collections off, one collection between periods.

Why: an automatic full (generation 2) collection holds the GIL for as long as it scans every live
object, which grows with the buses and stalled REST answers during periods (the figures are in
docs/service.md, "Scheduling and workers").  So startup objects are frozen (never scanned again), and a
collection runs between periods instead (min(T/4, 30 s) after one ends: the workers are idle then); it
freezes what survives, so it scans only what the last period left.  Frozen objects are still freed when
their last reference goes; only cycles among them wait for the complete collection every _FULL_GC_EVERY
periods, which unfreezes everything first.
"""

from __future__ import annotations

import gc
import logging
import threading
import time
from collections.abc import Callable

log = logging.getLogger(__name__)

_GEN2_THRESHOLD_OFF = 1_000_000_000
_FULL_GC_EVERY = 24
_gc_lock = threading.Lock()
_gc_state = {"services": 0, "threshold": (700, 10, 10)}  # services running in this process, thresholds before


def _gc_service_started() -> None:
    with _gc_lock:
        if _gc_state["services"] == 0:
            _gc_state["threshold"] = gc.get_threshold()
            gc.collect()
            gc.freeze()  # modules, schemas, routes, sessions: never scanned again
            gc.set_threshold(*_gc_state["threshold"][:2], _GEN2_THRESHOLD_OFF)
        _gc_state["services"] += 1


def _gc_service_stopped() -> None:
    with _gc_lock:
        _gc_state["services"] -= 1
        if _gc_state["services"] == 0:
            gc.set_threshold(*_gc_state["threshold"])
            gc.unfreeze()


class BetweenPeriodsGC:
    """The garbage-collection policy of one service instance (several may share a process).

    Parameters
    ----------
    busy : callable
        True while a collection must not run (a period is being computed, or the service stopped).
    """

    def __init__(self, busy: Callable[[], bool]) -> None:
        self._busy = busy
        self._started = False
        self._periods_done = 0
        self._complete_due = False

    def start(self) -> None:
        """Freeze what exists and switch automatic full collections off (first service in the process)."""
        _gc_service_started()
        self._started = True

    def stop(self) -> None:
        """Restore the thresholds and unfreeze (last service in the process); idempotent."""
        if self._started:
            self._started = False
            _gc_service_stopped()

    def period_done(self, period_s: float) -> None:
        """Schedule the collection after a period of length ``period_s`` [s]: min(T/4, 30 s) later."""
        self._periods_done += 1
        self._complete_due |= self._periods_done % _FULL_GC_EVERY == 0
        timer = threading.Timer(min(0.25 * period_s, 30.0), self._collect)
        timer.daemon = True
        timer.start()

    def _collect(self) -> None:
        """The collection automatic GC no longer does, between periods.

        Skipped if a period is running by then (periods run back to back): the next one's end retries.
        """
        if not self._started or self._busy():
            return
        complete, self._complete_due = self._complete_due, False
        t0 = time.perf_counter()
        with _gc_lock:
            if complete:
                gc.unfreeze()
            found = gc.collect()
            gc.freeze()
        log.debug("%s garbage collection between periods: %d objects freed in %.1f ms",
                  "complete" if complete else "young", found, 1e3 * (time.perf_counter() - t0))
