"""The tracked model's joint pooled fit in the service: the pools' windows and the background fits.

The tracking sink's tracker pools the per-window estimates (their information-weighted mean); the mean
misses the σ target at k = 16 where one fit of D to the pool's windows meets it (docs/tracking.md).  Here,
for at most ``max_buses`` buses, the windows of each tracker's pool are kept (:class:`WindowRing`: the
pool's windows and a held suspect, at most k + 1), and after each period every bus whose pool changed gets
a background worker task (``service.worker:pooled_window``) fitting D to them, started from the bus's
previous joint D since its last change (else the tracker's mean).  A fit's result is the tracked model's
until the pool changes again; a fit that fails, times out, is shed or arrives after its pool changed is
dropped, and the mean stays.  The change detector is untouched: it keeps testing each window's own
estimate against the pool.

Which windows a fit takes: the pool's, and with ``fit_suspects`` off not a suspect that the next window
did not confirm (the tracker lets it in winsorised, with its estimate clipped at ±h; a fit cannot clip a
window's samples, so it would leave the window out).  A suspect still held (the newest window, awaiting the
next) is never fitted.  After a restart the ring is empty and the pool's older windows are gone: the
mean stays until the pool holds only windows seen since (at most k periods, or the next change).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from aslm_core.params import DYNAMIC_NAMES
from aslm_core.tracking import Tracker
from aslm_core.window import Window
from service.diagnosis_queue import DiagnosisQueue
from service.executors.base import Executor, TaskOutcome, WindowTask
from service.window_ring import WindowRing

log = logging.getLogger(__name__)

#: The fewest windows worth a joint fit (one window's fit is its own identification).
MIN_WINDOWS = 2


@dataclass
class _Bus:
    """What the joint fit keeps of one bus."""

    ring: WindowRing
    suspect: float | None = None  # period of the suspect the tracker held after the previous window
    winsorised: set[float] = field(default_factory=set)  # suspects that joined the pool clipped: left out
    last_change: float | None = None
    start: list[float] | None = None  # the latest joint D since last_change
    key: tuple[float, ...] | None = None  # periods of the windows the current pool's fit takes
    submitted: tuple[float, ...] | None = None  # the pool of the latest fit handed out
    joint: dict | None = None  # the latest joint fit's value, of the pool ``joint_key``
    joint_key: tuple[float, ...] | None = None
    newest: float = float("-inf")  # period of the newest window seen [s]


class JointFits:
    """The windows of each tracked pool and their joint fits on the executor's workers.

    Parameters
    ----------
    executor : Executor
        The service's worker pool; the fits are background tasks queued as the diagnoses are
        (:class:`~service.diagnosis_queue.DiagnosisQueue`: a round not started when the next period's is
        queued is shed).
    arrived : callable, optional
        Called with the bus whose tracked model has a new joint fit (in the executor's thread); the
        tracking sink sets it to its publication.
    max_buses : int
        Buses with a ring; the others keep the mean.
    in_flight : int
        Fits in the executor at a time.
    options : dict
        :class:`aslm_core.IdentifyConfig` keyword arguments of the fits (the service's preprocessing).
    idle_s : float or None
        A bus without a new window for this long loses its ring after a period [s] (None: never).
    fit_suspects : bool
        Fit a suspect that the next window did not confirm with the rest of the pool (its window is
        stationary data: one window's estimate stood out, the joint fit has one optimum for all); off, it is
        left out as the mean clips it.  Chosen on development seeds (docs/tracking.md).
    """

    def __init__(self, executor: Executor, arrived: Callable[[str], None] | None = None, *, max_buses: int,
                 in_flight: int = 1, options: dict | None = None, idle_s: float | None = None,
                 fit_suspects: bool = True) -> None:
        self.arrived = arrived or (lambda bus: None)
        self.fit_suspects = fit_suspects
        self.max_buses = max_buses
        self.options = options or {}
        self.idle_s = idle_s
        self.buses: dict[str, _Bus] = {}
        self.failed = 0  # fits that failed, timed out or lost their worker
        self.shed = 0  # fits not started before the next period's were queued
        self.stale = 0  # fits that arrived after their pool had changed
        self.done = 0  # fits that returned a D
        self.cpu_s = 0.0  # the workers' CPU time of those fits [s]
        self._round: list[WindowTask] = []
        self._round_keys: dict[str, tuple[float, ...]] = {}
        self._queued: dict[tuple[str, float], tuple[float, ...]] = {}  # (bus, round) -> the pool fitted
        self._lock = threading.RLock()
        self.queue = DiagnosisQueue(executor, self._finished, in_flight=in_flight, what="joint fits")

    def observe(self, bus: str, period: float, window: Window | None, tracker: Tracker) -> None:
        """Follow ``tracker`` after its update with the window of ``period`` [s]; plan the pool's fit.

        ``window`` None (not attached): the pool cannot be fitted until that window has left it.
        """
        with self._lock:
            b = self.buses.get(bus)
            if b is None:
                if len(self.buses) >= self.max_buses:
                    return
                b = self.buses[bus] = _Bus(WindowRing(bus), last_change=tracker.last_change)
            held = tracker.suspect.t if tracker.suspect is not None else None
            if tracker.last_change != b.last_change:  # a change restarted the pool: the old D is no start
                b.last_change, b.start = tracker.last_change, None
            elif b.suspect is not None and b.suspect != held and not self.fit_suspects:
                b.winsorised.add(b.suspect)  # not confirmed: it joined the pool clipped
            b.suspect = held
            if window is not None:
                b.ring.add(period, window)
                b.newest = max(b.newest, period)
            pool = [e.t for e in tracker.pool]
            b.winsorised.intersection_update(pool)
            fitted = [p for p in pool if p not in b.winsorised]
            b.ring.keep(fitted + ([held] if held is not None else []))
            b.key = tuple(fitted) if len(fitted) >= MIN_WINDOWS and b.ring.covers(fitted) else None
            if b.key is None or b.key in (b.submitted, b.joint_key):
                return
            b.submitted = b.key
            if b.start is not None:
                start = b.start
            else:
                mean = tracker.model()["dynamic"]
                start = [mean[k] for k in DYNAMIC_NAMES]
            pool_windows = b.ring.get(fitted)
            self._round.append(WindowTask(pool_windows[-1], warm_start=list(start), options=self.options,
                                          fn="service.worker:pooled_window", background=True, pool=pool_windows))
            self._round_keys[bus] = b.key

    def current(self, bus: str) -> dict | None:
        """The joint fit of the bus's current pool (``dynamic``, ``stderr``, ``n_windows``, ...), or None."""
        with self._lock:
            b = self.buses.get(bus)
            return b.joint if b is not None and b.key is not None and b.key == b.joint_key else None

    def submit_round(self, period: float) -> None:
        """Queue the fits planned since the last round (those of an earlier round still waiting are shed)."""
        with self._lock:
            tasks, self._round = self._round, []
            keys, self._round_keys = self._round_keys, {}
            self._queued.update({(bus, period): key for bus, key in keys.items()})
        if tasks:
            self.queue.enqueue(period, tasks)

    def evict_idle(self, now: float) -> None:
        """Drop the rings of buses without a new window for ``idle_s`` before ``now`` [s]."""
        if self.idle_s is None:
            return
        with self._lock:
            for bus in [bus for bus, b in self.buses.items() if b.newest < now - self.idle_s]:
                del self.buses[bus]

    @property
    def pending(self) -> int:
        """Fits handed to the queue whose outcome has not come back."""
        with self._lock:
            return len(self._queued)

    @property
    def nbytes(self) -> int:
        """Bytes of the windows held in every ring."""
        with self._lock:
            return sum(b.ring.nbytes for b in self.buses.values())

    def _finished(self, bus: str, period: float, outcome: TaskOutcome) -> None:
        with self._lock:
            key = self._queued.pop((bus, period), None)
            b = self.buses.get(bus)
            if b is None or key is None:
                return
            if not outcome.ok:
                if outcome.reason == "shed":  # never ran: the bus's next window may plan it again
                    self.shed += 1
                    if b.submitted == key:
                        b.submitted = None
                    return
                self.failed += 1  # not retried on the same windows: the mean stays until the pool changes
                log.warning("joint fit of %s failed (%s: %s); its tracked model stays the mean", bus,
                            outcome.reason, outcome.message)
                return
            self.done += 1
            self.cpu_s += outcome.cpu_s
            value = outcome.value or {}
            dynamic = value.get("dynamic") or {}
            if any(dynamic.get(k) is None for k in DYNAMIC_NAMES):
                self.failed += 1
                return
            b.start = [dynamic[k] for k in DYNAMIC_NAMES]
            if key != b.key:
                self.stale += 1  # the pool moved on while it ran: a start for the next fit, not the model
                return
            b.joint, b.joint_key = value, key
        self.arrived(bus)
