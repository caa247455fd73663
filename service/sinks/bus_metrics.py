"""Per-bus Prometheus gauges: the latest parameters, their standard errors, fit degrees and verdict.

Grafana draws each bus's history from Prometheus with these (``deploy/grafana/``), with no store of its
own.  Each bus's sample lines are formatted when its result or diagnosis arrives, and a scrape only
joins them: prometheus_client's own formatting of 130,000 samples held the GIL for ~4 s per scrape.

Cardinality: 13 series per bus (4 parameters, 4 standard errors, 2 fit degrees, the verdict, the
period of the latest successful result and the latest status), 130,000 at 10,000 buses.  That is why
the gauges are a sink to opt in to (``sinks = [..., "bus_metrics"]``), not part of every ``/metrics``.
"""

from __future__ import annotations

import threading

from aslm_core.params import DYNAMIC_NAMES
from service.context import Context
from service.latest import LatestResults, verdict_of
from service.models import BusResult, PeriodSummary

#: Value of ``aslm_diagnosis_verdict`` for each verdict (Grafana's value mappings use the same table).
VERDICT_CODES = {"consistent": 0, "explained": 1, "unexplained": 2, "failed": 3, "ambiguous": 4}
#: Value of ``aslm_bus_status`` for the latest result's status.
STATUS_CODES = {"ok": 0, "skipped": 1, "failed": 2}

#: Every per-bus gauge: name → help.
FAMILIES = {
    "aslm_parameter": "Latest identified D of the bus, label name: a [1/s], b [1/s], H2 [s], Tm [pu]",
    "aslm_parameter_stderr": "Standard error of the latest identified D, same units",
    "aslm_fit_degree": "Fit degree of the latest identification (paper eq. 9), label channel: p, q [-]",
    "aslm_diagnosis_verdict": "Latest diagnosis verdict: 0 consistent, 1 explained, 2 unexplained, 3 failed, 4 ambiguous",
    "aslm_bus_result_period_timestamp_seconds": "Period of the latest successful result, UTC [s]",
    "aslm_bus_status": "Status of the latest result: 0 ok, 1 skipped, 2 failed",
}


def _label(value: str) -> str:
    """A label value escaped as the text exposition format requires."""
    return value.replace("\\", r"\\").replace("\n", r"\n").replace('"', r"\"")


class BusGauges:
    """The per-bus sample lines, kept per family and bus, and their exposition text.

    Parameters
    ----------
    latest : LatestResults
        Fills the gauges at start (the results and verdicts restored from storage).
    """

    def __init__(self, latest: LatestResults | None = None) -> None:
        self._lines: dict[str, dict[str, str]] = {name: {} for name in FAMILIES}
        self._lock = threading.Lock()
        if latest is not None:
            self.results([*latest.last_ok.values(), *latest.results.values()])
            for bus, ver in latest.verdicts.items():
                self.verdict(bus, ver.verdict)

    def results(self, batch: list[BusResult]) -> None:
        """Take each result's status, and its parameters if it succeeded."""
        new: dict[str, dict[str, str]] = {name: {} for name in FAMILIES}
        for res in batch:
            b = _label(res.bus)
            new["aslm_bus_status"][res.bus] = f'aslm_bus_status{{bus="{b}"}} {STATUS_CODES.get(res.status, 2)}\n'
            par = res.parameters
            if res.status != "ok" or par is None:
                continue
            new["aslm_parameter"][res.bus] = "".join(
                f'aslm_parameter{{bus="{b}",name="{k}"}} {float(par.dynamic[k])!r}\n' for k in DYNAMIC_NAMES)
            new["aslm_parameter_stderr"][res.bus] = "".join(
                f'aslm_parameter_stderr{{bus="{b}",name="{k}"}} {float(par.stderr[k])!r}\n'
                for k in DYNAMIC_NAMES if par.stderr.get(k) is not None)
            new["aslm_fit_degree"][res.bus] = "".join(
                f'aslm_fit_degree{{bus="{b}",channel="{ch}"}} {float(par.fit[f"fd_{ch}"])!r}\n'
                for ch in ("p", "q") if par.fit.get(f"fd_{ch}") is not None)
            new["aslm_bus_result_period_timestamp_seconds"][res.bus] = (
                f'aslm_bus_result_period_timestamp_seconds{{bus="{b}"}} {float(res.period)!r}\n')
        with self._lock:
            for name, lines in new.items():
                self._lines[name].update(lines)

    def verdict(self, bus: str, verdict: str) -> None:
        """Take a bus's latest diagnosis verdict."""
        line = f'aslm_diagnosis_verdict{{bus="{_label(bus)}"}} {VERDICT_CODES.get(verdict, 3)}\n'
        with self._lock:
            self._lines["aslm_diagnosis_verdict"][bus] = line

    def text(self) -> bytes:
        """The exposition text of every family (families with no bus yet are left out)."""
        with self._lock:
            snapshot = {name: list(lines.values()) for name, lines in self._lines.items() if lines}
        out = []
        for name, lines in snapshot.items():
            out.append(f"# HELP {name} {FAMILIES[name]}\n# TYPE {name} gauge\n")
            out.extend(lines)
        return "".join(out).encode()


class BusMetricsSink:
    """Keeps :class:`BusGauges` up to date and adds them to the service's ``/metrics`` while open."""

    name = "bus_metrics"
    persists = False

    def __init__(self, ctx: Context) -> None:
        self.gauges = BusGauges(ctx.latest)
        self._exposition = ctx.metrics.exposition
        self._exposition.append(self.gauges.text)

    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:  # noqa: ARG002 - Sink signature
        """Update the gauges of the batch's buses."""
        self.gauges.results(batch)

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:  # noqa: ARG002 - Sink signature
        """Update the bus's verdict gauge."""
        self.gauges.verdict(bus, verdict_of(payload).verdict)

    def write_period(self, summary: PeriodSummary) -> None:
        """Nothing to record per period."""

    def close(self) -> None:
        """Take the gauges out of ``/metrics`` (idempotent)."""
        if self.gauges.text in self._exposition:
            self._exposition.remove(self.gauges.text)


def build(ctx: Context) -> BusMetricsSink:
    """The per-bus gauges of the service's latest results in its ``/metrics``."""
    return BusMetricsSink(ctx)
