"""The service's clock: wall-clock time and timed waits, injectable so periods can run in virtual time.

The scheduler reads period boundaries, waits, ``completed_at`` and latencies from a :class:`Clock`.  The
running service uses :data:`SYSTEM_CLOCK`; fast tests use a :class:`ManualClock`, whose time moves only
when the test calls :meth:`ManualClock.advance`, so several periods run in milliseconds.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Time source of the scheduler and the ingest."""

    def now(self) -> float:
        """Current time, UTC since the epoch [s]."""
        ...

    def wait(self, event: threading.Event, timeout: float) -> bool:
        """Block until ``event`` is set or ``timeout`` [s] of this clock's time has passed.

        Returns
        -------
        bool
            Whether ``event`` is set (as :meth:`threading.Event.wait`).
        """
        ...


class SystemClock:
    """The wall clock (``time.time``) and real waits."""

    def now(self) -> float:
        """Current time, UTC since the epoch [s]."""
        return time.time()

    def wait(self, event: threading.Event, timeout: float) -> bool:
        """``event.wait(timeout)`` [s]."""
        return event.wait(timeout)


SYSTEM_CLOCK = SystemClock()
"""The one system clock (it has no state)."""

# A waiter on a ManualClock is released by advance() through a condition variable, but an Event set by
# another thread notifies no condition: waiters look at their event this often [s of real time].
_EVENT_POLL_S = 0.001


class ManualClock:
    """A clock whose time moves only by :meth:`advance` (tests).

    Parameters
    ----------
    start : float
        Initial time, UTC since the epoch [s].

    Notes
    -----
    :meth:`settle` lets a test wait until the thread using the clock has done everything due at the
    current time: it returns once a thread waits on the clock again after the last :meth:`advance`.
    """

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)
        self._cond = threading.Condition()
        self._advances = 0
        # thread ident -> the advance count at which it last (re)checked its deadline while waiting
        self._waiting: dict[int, int] = {}

    def now(self) -> float:
        """Current time [s]."""
        with self._cond:
            return self._now

    def wait(self, event: threading.Event, timeout: float) -> bool:
        """Block until ``event`` is set or the clock reaches now + ``timeout`` [s]."""
        me = threading.get_ident()
        with self._cond:
            deadline = self._now + timeout
            try:
                while not event.is_set() and self._now < deadline:
                    self._waiting[me] = self._advances
                    self._cond.notify_all()
                    self._cond.wait(_EVENT_POLL_S)
            finally:
                self._waiting.pop(me, None)
                self._cond.notify_all()
        return event.is_set()

    def advance(self, seconds: float) -> None:
        """Move the time forward by ``seconds`` [s] and release the waiters whose timeout has passed."""
        if seconds < 0:
            raise ValueError(f"a clock does not go back (advance by {seconds} s)")
        with self._cond:
            self._now += seconds
            self._advances += 1
            self._cond.notify_all()

    def advance_to(self, t: float) -> None:
        """Move the time forward to ``t`` [s] (no-op if it is there already)."""
        self.advance(max(0.0, t - self.now()))

    def settle(self, timeout: float = 5.0) -> None:
        """Block until a thread waits on this clock with the current time seen (real ``timeout`` [s]).

        Raises
        ------
        TimeoutError
            No thread came back to wait within ``timeout``.
        """
        end = time.monotonic() + timeout
        with self._cond:
            while self._advances not in self._waiting.values():
                left = end - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no thread waited on the clock within {timeout} s")
                self._cond.wait(left)
