"""The latest result and diagnosis of each bus, kept in memory for REST and the Zenoh queryable.

Each result is serialised once (by the sink chain) and its JSON kept beside it: REST "latest" answers
with that JSON without re-validating, and the Zenoh sink publishes the same bytes.
"""

from __future__ import annotations

import json
from typing import NamedTuple

from service.models import BusResult, PeriodSummary
from service.storage import Storage


class Verdict(NamedTuple):
    """The headline of a bus's latest diagnosis (what the fleet table and the per-bus gauges show)."""

    verdict: str
    """explained, ambiguous, consistent, unexplained or failed."""
    cause: str | None
    """The named cause when explained (else None)."""
    period: float
    """Period boundary of the diagnosed window, UTC [s]."""


def verdict_of(payload: str) -> Verdict:
    """:class:`Verdict` of a diagnosis report's JSON (``failed`` when it has no verdict)."""
    report = json.loads(payload)
    return Verdict(report.get("verdict", "failed"), report.get("cause"), float(report.get("period", 0.0)))


class LatestResults:
    """bus → latest :class:`BusResult` (and its JSON), bus → latest diagnosis JSON and its :class:`Verdict`.

    It is written as a sink of the service's own state (after the persisting sinks, before the
    publishing ones), so a result is in REST "latest" once it is stored and before it is on Zenoh.

    Parameters
    ----------
    results : dict
        bus → latest result at start (from storage).
    diagnoses : dict
        bus → JSON of its latest diagnosis report at start.
    last_ok : dict
        bus → latest successful result at start, where it is not the latest result.
    """

    name = "latest"
    persists = False

    def __init__(self, results: dict[str, BusResult] | None = None, diagnoses: dict[str, str] | None = None,
                 last_ok: dict[str, BusResult] | None = None) -> None:
        self.results: dict[str, BusResult] = dict(results or {})
        # The last successful result of each bus: the dashboard shows the last known D of a bus whose
        # latest window was skipped or failed (REST "latest?ok=true" still reads storage).
        self.last_ok: dict[str, BusResult] = {b: r for b, r in self.results.items() if r.status == "ok"}
        self.last_ok.update(last_ok or {})
        self.results_json: dict[str, str] = {b: r.model_dump_json() for b, r in self.results.items()}
        self.diagnoses_json: dict[str, str] = dict(diagnoses or {})
        # Parsed once per report (reports are kB and come at most once per bus and diagnosis period), so
        # the fleet view can read 10,000 verdicts without parsing 10,000 reports per request.
        self.verdicts: dict[str, Verdict] = {b: verdict_of(js) for b, js in self.diagnoses_json.items()}

    @classmethod
    def from_storage(cls, storage: Storage) -> LatestResults:
        """The latest results and diagnoses persisted in ``storage``."""
        return cls(storage.latest_all(), storage.latest_diagnoses(), storage.latest_all(ok_only=True))

    def snapshot(self) -> dict[str, BusResult]:
        """A copy of bus → latest result (safe to iterate while periods write)."""
        return self.results.copy()

    # --- sink ----------------------------------------------------------------------------------------
    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:
        """Keep each result of ``batch`` (with its JSON) as its bus's latest."""
        for res, js in zip(batch, payloads, strict=True):
            self.results[res.bus] = res
            self.results_json[res.bus] = js
            if res.status == "ok":
                self.last_ok[res.bus] = res

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:  # noqa: ARG002 - Sink signature
        """Keep ``payload`` as the bus's latest diagnosis report."""
        self.diagnoses_json[bus] = payload
        self.verdicts[bus] = verdict_of(payload)

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
