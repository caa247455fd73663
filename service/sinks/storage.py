"""SQLite sink: results, diagnoses and periods appended to the history; old ones purged after each period.

The :class:`~service.storage.Storage` it writes to belongs to the service (it is also REST's read side and
holds the persisted configuration), so closing this sink leaves it open.
"""

from __future__ import annotations

from service.context import Context
from service.models import BusResult, PeriodSummary
from service.storage import Storage


class StorageSink:
    """Writes to one :class:`~service.storage.Storage`.

    Parameters
    ----------
    storage : Storage
    retention_s : float
        Results and periods older than this before each completed period are deleted [s].
    """

    name = "storage"
    persists = True

    def __init__(self, storage: Storage, retention_s: float) -> None:
        self.storage = storage
        self.retention_s = retention_s

    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:
        """Append the batch in one transaction."""
        self.storage.save_results(batch, payloads)

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:
        """Store the report (replacing an earlier one of the same bus and period)."""
        self.storage.save_diagnosis(bus, period, payload)

    def write_period(self, summary: PeriodSummary) -> None:
        """Record the period, then purge what is older than the retention."""
        self.storage.save_period(summary)
        self.storage.purge(summary.period - self.retention_s)

    def close(self) -> None:
        """Nothing: the service closes its storage after every sink."""


def build(ctx: Context) -> StorageSink:
    """The storage sink on the service's storage with the settings' ``retention_days``."""
    return StorageSink(ctx.storage, 86400.0 * ctx.settings.retention_days)
