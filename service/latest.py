"""The latest result and diagnosis of each bus, kept in memory for REST and the Zenoh queryable.

Each result is serialised once (by the sink chain) and its JSON kept beside it: REST "latest" answers
with that JSON without re-validating, and the Zenoh sink publishes the same bytes.
"""

from __future__ import annotations

from service.models import BusResult, PeriodSummary
from service.storage import Storage


class LatestResults:
    """bus → latest :class:`BusResult` (and its JSON), bus → latest diagnosis JSON.

    It is written as a sink of the service's own state (after the persisting sinks, before the
    publishing ones), so a result is in REST "latest" once it is stored and before it is on Zenoh.

    Parameters
    ----------
    results : dict
        bus → latest result at start (from storage).
    diagnoses : dict
        bus → JSON of its latest diagnosis report at start.
    """

    name = "latest"
    persists = False

    def __init__(self, results: dict[str, BusResult] | None = None, diagnoses: dict[str, str] | None = None) -> None:
        self.results: dict[str, BusResult] = dict(results or {})
        self.results_json: dict[str, str] = {b: r.model_dump_json() for b, r in self.results.items()}
        self.diagnoses_json: dict[str, str] = dict(diagnoses or {})

    @classmethod
    def from_storage(cls, storage: Storage) -> LatestResults:
        """The latest results and diagnoses persisted in ``storage``."""
        return cls(storage.latest_all(), storage.latest_diagnoses())

    def snapshot(self) -> dict[str, BusResult]:
        """A copy of bus → latest result (safe to iterate while periods write)."""
        return self.results.copy()

    # --- sink ----------------------------------------------------------------------------------------
    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:
        """Keep each result of ``batch`` (with its JSON) as its bus's latest."""
        for res, js in zip(batch, payloads, strict=True):
            self.results[res.bus] = res
            self.results_json[res.bus] = js

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:  # noqa: ARG002 - Sink signature
        """Keep ``payload`` as the bus's latest diagnosis report."""
        self.diagnoses_json[bus] = payload

    def forget_skipped(self, buses: list[str]) -> None:
        """Drop evicted buses whose latest result is a skip: a stray key never identified leaves no entry.

        Their rows stay in the history; a bus with an identification (or a failure) stays served.
        """
        for bus in buses:
            res = self.results.get(bus)
            if res is not None and res.status == "skipped":
                self.results_json.pop(bus, None)
                self.results.pop(bus, None)

    def write_period(self, summary: PeriodSummary) -> None:
        """Nothing to keep per period (REST reads periods from storage)."""

    def close(self) -> None:
        """Nothing to release."""
