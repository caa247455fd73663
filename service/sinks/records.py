"""Records sink: ``{prefix}/records/{format}/{bus}``, the records of every successful result for ANDES, PSS/E
and PSLF, each payload stating its assumptions (docs/records.md).

The assumptions are the documented defaults of :class:`aslm_core.records.Assumptions` at the service's
``f0``; a planner who needs others asks REST (``?format=…&xp=…``) or runs ``aslm export``.  A result that
cannot be written (e.g. no motor, or X' outside its interval) is published as ``{"bus", "period",
"format", "error"}`` on the same key, so that a subscriber learns why there is no record.

With the ``tracking`` sink, a bus's records are those of its tracked model (D pooled since the last change,
docs/tracking.md) rather than of its latest window; ``model`` in the payload says which.  They are published
with each result and again when the tracked model changes between results (its pool's joint fit arrived).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable

from aslm_core.records import FORMATS, Assumptions, RecordError
from service.context import Context
from service.models import BusResult, PeriodSummary
from service.records import record_payload

log = logging.getLogger(__name__)


class RecordsSink:
    """Publishes the records of each successful result.

    Parameters
    ----------
    put : callable
        ``put(key, json_text)``: the publication (a Zenoh put in the service).
    prefix : str
        Zenoh key prefix.
    assumptions : Assumptions
    formats : tuple of str
        Record formats to publish (default all of :data:`aslm_core.records.FORMATS`).
    on_error : callable, optional
        Called once per failed put.
    tracked : callable, optional
        ``tracked(bus)``: JSON of the bus's tracked model or None; its records replace the window's.
    """

    name = "records"
    persists = False

    def __init__(self, put: Callable[[str, str], None], prefix: str, assumptions: Assumptions,
                 formats: tuple[str, ...] = FORMATS, on_error: Callable[[], None] | None = None,
                 tracked: Callable[[str], str | None] | None = None) -> None:
        self._put = put
        self.prefix = prefix
        self.assumptions = assumptions
        self.formats = formats
        self._on_error = on_error or (lambda: None)
        self._tracked = tracked
        self.published = 0

    def _payload(self, res: BusResult | None, bus: str, fmt: str) -> str | None:
        """The records of the bus's tracked model if it has one, else of ``res`` (None: neither)."""
        js = self._tracked(bus) if self._tracked is not None else None
        if js is None and res is None:
            return None
        model = json.loads(js) if js is not None else None
        try:
            if model is not None:
                return json.dumps({**record_payload(model, fmt, self.assumptions), "model": "tracked"})
            return json.dumps({**record_payload(res, fmt, self.assumptions), "model": "window"})
        except RecordError as exc:
            period = model["period"] if model is not None else res.period
            return json.dumps({"bus": bus, "period": period, "format": fmt, "error": str(exc)})

    def _put_records(self, bus: str, res: BusResult | None) -> None:
        for fmt in self.formats:
            try:
                payload = self._payload(res, bus, fmt)
                if payload is None:
                    return
                self._put(f"{self.prefix}/records/{fmt}/{bus}", payload)
                self.published += 1
            except Exception:  # noqa: BLE001 - one bus's records never stop the others
                self._on_error()
                log.exception("publishing the %s records of %s failed", fmt, bus)

    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:  # noqa: ARG002 - Sink signature
        """Put the records of each successful result; a failed put is logged and counted."""
        for res in batch:
            if res.status == "ok" and res.parameters is not None:
                self._put_records(res.bus, res)

    def tracked_changed(self, bus: str) -> None:
        """Put the records of the bus's tracked model again: it changed between results (a joint fit)."""
        if self._tracked is not None:
            self._put_records(bus, None)

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:
        """Diagnoses carry no records."""

    def write_period(self, summary: PeriodSummary) -> None:
        """Nothing is published per period."""

    def close(self) -> None:
        """Nothing held (the session is the instance's)."""


def build(ctx: Context) -> RecordsSink:
    """The records sink on the instance's Zenoh session; failed puts count as
    ``aslm_internal_errors{where="publish"}``."""
    import zenoh

    session = ctx.zenoh_session()

    def put(key: str, payload: str) -> None:
        session.put(key, payload, encoding=zenoh.Encoding.APPLICATION_JSON,
                    congestion_control=zenoh.CongestionControl.BLOCK)

    tracking = "tracking" in ctx.settings.sinks
    sink = RecordsSink(put, ctx.settings.prefix, Assumptions(f0=ctx.settings.f0),
                       on_error=ctx.metrics.request_errors.labels("publish").inc,
                       tracked=ctx.storage.tracked if tracking else None)
    if tracking:
        ctx.tracked_listeners.append(sink.tracked_changed)
    return sink
