"""SQLite sink: results, diagnoses and periods appended to the history; old ones purged after each period.

The :class:`~service.storage.Storage` it writes to belongs to the service (it is also REST's read side and
holds the persisted configuration), so closing this sink leaves it open.

When a write fails (disk full, I/O error), what it was given is kept, in order, and written before the
next write; the failure still raises, so the sink chain logs and counts it and the other sinks (REST
"latest", Zenoh) get the results as usual.  Beyond ``backlog_limit`` records the oldest are dropped and
counted as lost.
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable

from service.context import Context
from service.models import BusResult, PeriodSummary
from service.storage import Storage


class StorageSink:
    """Writes to one :class:`~service.storage.Storage`, keeping what failed for a retry.

    Parameters
    ----------
    storage : Storage
    retention_s : float
        Results and periods older than this before each completed period are deleted [s].
    backlog_limit : int
        Records (results, diagnoses, periods) kept for a retry at the most; older ones are dropped.
    on_lost : callable, optional
        Called with (kind, count) when records are dropped from the backlog (``results``, ``diagnosis``,
        ``period``).
    """

    name = "storage"
    persists = True

    def __init__(self, storage: Storage, retention_s: float, *, backlog_limit: int = 100_000,
                 on_lost: Callable[[str, int], None] | None = None) -> None:
        self.storage = storage
        self.retention_s = retention_s
        self.backlog_limit = backlog_limit
        self._on_lost = on_lost or (lambda kind, n: None)
        self._backlog: collections.deque[tuple[str, tuple, int]] = collections.deque()
        self.held = 0  # records in the backlog
        self.lost: collections.Counter[str] = collections.Counter()
        self.last_error: str | None = None
        self._lock = threading.Lock()  # results come from the scheduler, diagnoses from executor threads

    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:
        """Append the batch in one transaction (after anything kept from failed writes)."""
        self._write("results", (batch, payloads), len(batch))

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:
        """Store the report (replacing an earlier one of the same bus and period)."""
        self._write("diagnosis", (bus, period, payload), 1)

    def write_period(self, summary: PeriodSummary) -> None:
        """Record the period, then purge what is older than the retention."""
        self._write("period", (summary,), 1)

    def problem(self) -> str | None:
        """Why storage is not doing its job (its last write failed), or None."""
        if not self._backlog:
            return None
        lost = f", {sum(self.lost.values())} lost" if self.lost else ""
        return f"storage writes failing ({self.last_error}); {self.held} records kept for a retry{lost}"

    def close(self) -> None:
        """Nothing: the service closes its storage after every sink."""

    def _write(self, kind: str, args: tuple, n: int) -> None:
        with self._lock:
            self._backlog.append((kind, args, n))
            self.held += n
            while self.held > self.backlog_limit and len(self._backlog) > 1:
                old, _, k = self._backlog.popleft()
                self.held -= k
                self.lost[old] += k
                self._on_lost(old, k)
            while self._backlog:
                kind, args, n = self._backlog[0]
                try:
                    self._apply(kind, args)
                except Exception as exc:
                    self.last_error = f"{type(exc).__name__}: {exc}"
                    raise
                self._backlog.popleft()
                self.held -= n
            self.last_error = None

    def _apply(self, kind: str, args: tuple) -> None:
        if kind == "results":
            self.storage.save_results(*args)
        elif kind == "diagnosis":
            self.storage.save_diagnosis(*args)
        else:
            (summary,) = args
            self.storage.save_period(summary)
            self.storage.purge(summary.period - self.retention_s)


def build(ctx: Context) -> StorageSink:
    """The storage sink on the service's storage with the settings' ``retention_days``; records dropped
    from its backlog count in ``aslm_storage_lost_total{kind}``, those kept in ``aslm_storage_backlog``."""
    sink = StorageSink(ctx.storage, 86400.0 * ctx.settings.retention_days,
                       on_lost=lambda kind, n: ctx.metrics.storage_lost.labels(kind).inc(n))
    ctx.metrics.storage_backlog.set_function(lambda: sink.held)
    return sink
