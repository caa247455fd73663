"""What a sink is, and the chain that writes to every sink in order, isolating their failures.

Order: the sinks that persist (SQLite history) first, then the others in the order given, so that a
result is stored before anything publishes it.  A failing sink is logged and counted and never stops the
other sinks or the period.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

from service.models import BusResult, PeriodSummary

log = logging.getLogger(__name__)


class ResultBatch(list):
    """A batch of :class:`BusResult` (a list, as every sink takes it) with the windows identified.

    Attributes
    ----------
    windows : dict
        bus → the ``aslm_core.Window`` its ok result was identified on, for in-process sinks that need
        the samples (the tracking sink's joint fit); the scheduler drops the batch after the sinks wrote
        it, so no window outlives its period here.
    """

    def __init__(self, results=(), windows: dict | None = None) -> None:
        super().__init__(results)
        self.windows = windows if windows is not None else {}


class Sink(Protocol):
    """Where results, diagnosis reports and period summaries go.

    Attributes
    ----------
    name : str
        Name in logs and in the ``aslm_internal_errors{where=...}`` metric of its failures.
    persists : bool
        Written before the sinks that do not persist (results are stored before they are published).
    """

    name: str
    persists: bool

    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:
        """One batch of results of a period, with their JSON (serialised once for every sink)."""
        ...

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:
        """One diagnosis report (JSON with ``bus`` and ``period``) of ``bus`` for the period ``period`` [s]."""
        ...

    def write_period(self, summary: PeriodSummary) -> None:
        """A completed period, after all its results."""
        ...

    def close(self) -> None:
        """Release what the sink holds (idempotent)."""
        ...


class SinkChain:
    """Every sink in order: the persisting ones first, then the others as given.

    Parameters
    ----------
    sinks : list of Sink
    on_error : callable
        Called with the sink's name each time one of its calls raises (after logging it).
    """

    def __init__(self, sinks: list[Sink], on_error: Callable[[str], None]) -> None:
        self.sinks = [s for s in sinks if s.persists] + [s for s in sinks if not s.persists]
        self._on_error = on_error

    def _each(self, method: str, *args) -> None:
        for sink in self.sinks:
            try:
                getattr(sink, method)(*args)
            except Exception:  # noqa: BLE001 - one failing sink never stops the others or the period
                self._on_error(sink.name)
                log.exception("sink %s: %s failed", sink.name, method)

    def write_results(self, batch: list[BusResult]) -> None:
        """Serialise each result once, then write the batch to every sink."""
        payloads = [res.model_dump_json() for res in batch]
        self._each("write_results", batch, payloads)

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:
        """Write one diagnosis report (JSON) to every sink."""
        self._each("write_diagnosis", bus, period, payload)

    def write_period(self, summary: PeriodSummary) -> None:
        """Write a completed period to every sink."""
        self._each("write_period", summary)

    def close(self) -> None:
        """Close every sink, the publishing ones first (reverse order)."""
        for sink in reversed(self.sinks):
            try:
                sink.close()
            except Exception:  # noqa: BLE001 - closing the others matters more
                log.exception("closing sink %s failed", sink.name)
