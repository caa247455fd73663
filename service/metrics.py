"""Prometheus metrics of one service instance (own registry, so several instances can coexist).

Frame counters are read from the buffers at scrape time (a collector), which keeps the ingest hot path
free of metric calls.
"""

from __future__ import annotations

import json
from collections.abc import Callable

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

from service.buffers import BufferStore
from service.models import BusResult, PeriodSummary

_ID_BUCKETS = (0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 30, 60)
_LAT_BUCKETS = (0.1, 0.25, 0.5, 1, 2, 5, 10, 20, 30, 60, 120, 300)


class _FrameCollector:
    def __init__(self, store: BufferStore) -> None:
        self.store = store

    def collect(self):
        tot = self.store.totals()
        received = CounterMetricFamily("aslm_frames_received", "PMU frames received (buffered + dropped)")
        received.add_metric([], tot.frames_received)
        buffered = CounterMetricFamily("aslm_frames_buffered", "PMU frames accepted into the bus buffers")
        buffered.add_metric([], tot.frames_buffered)
        dropped = CounterMetricFamily("aslm_frames_dropped", "PMU frames dropped, by reason", labels=["reason"])
        for reason, k in sorted(tot.frames_rejected.items()):
            dropped.add_metric([reason], k)
        messages = CounterMetricFamily("aslm_messages_received", "PMU messages received")
        messages.add_metric([], tot.messages)
        mdrop = CounterMetricFamily("aslm_messages_dropped", "Undecodable PMU messages, by reason", labels=["reason"])
        for reason, k in sorted(tot.messages_rejected.items()):
            mdrop.add_metric([reason], k)
        buses = GaugeMetricFamily("aslm_buses", "Buses known to the ingest")
        buses.add_metric([], tot.buses)
        evicted = CounterMetricFamily("aslm_buses_evicted", "Buses forgotten (idle, or to make room at max_buses)")
        evicted.add_metric([], tot.buses_evicted)
        yield from (received, buffered, dropped, messages, mdrop, buses, evicted)


class ServiceMetrics:
    """All metrics; :meth:`render` gives the Prometheus text exposition.

    Also a sink of the service's own state (``write_*``): results, diagnoses and periods are counted
    after the persisting sinks and before the publishing ones, as they were before sinks existed.
    """

    name = "metrics"
    persists = False

    def __init__(self, store: BufferStore) -> None:
        self.registry = CollectorRegistry()
        self.registry.register(_FrameCollector(store))
        r = self.registry
        self.windows = Counter("aslm_windows", "Windows by outcome (ok, failed, skipped)", ["status"], registry=r)
        self.skipped = Counter("aslm_windows_skipped", "Windows skipped, by reason", ["reason"], registry=r)
        self.failed = Counter("aslm_windows_failed", "Identifications failed, by reason", ["reason"], registry=r)
        self.identify_s = Histogram("aslm_identification_seconds", "Identification time per window in the worker",
                                    buckets=_ID_BUCKETS, registry=r)
        self.latency_s = Histogram("aslm_period_latency_seconds",
                                   "End of late-data allowance to last result published",
                                   buckets=_LAT_BUCKETS, registry=r)
        self.period_s = Gauge("aslm_period_seconds", "Period T in force", registry=r)
        self.last_period = Gauge("aslm_last_period_timestamp_seconds", "Boundary of the last completed period",
                                 registry=r)
        self.diagnoses = Counter("aslm_diagnoses", "Discrepancy diagnoses by verdict", ["verdict"], registry=r)
        self.request_errors = Counter("aslm_internal_errors", "Internal errors caught, by place", ["where"],
                                      registry=r)
        self.periods_missed = Counter("aslm_periods_missed", "Period boundaries without a completed period, "
                                      "by status (overrun, interrupted)", ["status"], registry=r)
        self.storage_lost = Counter("aslm_storage_lost", "Records never stored: dropped from the storage "
                                    "backlog while storage failed, by kind", ["kind"], registry=r)
        self.storage_backlog = Gauge("aslm_storage_backlog", "Records kept for a retry while storage fails",
                                     registry=r)
        # Families whose owners render their own text (the per-bus gauges: prometheus_client takes ~4 s of
        # GIL to format 130,000 samples, a cached text ~0.05 s); appended to the registry's output.
        self.exposition: list[Callable[[], bytes]] = []

    def results(self, batch: list[BusResult]) -> None:
        """Count a batch of results."""
        for res in batch:
            self.windows.labels(res.status).inc()
            if res.status == "skipped":
                self.skipped.labels(res.reason or "unknown").inc()
            elif res.status == "failed":
                self.failed.labels(res.reason or "unknown").inc()
            elif res.parameters is not None:
                self.identify_s.observe(res.parameters.elapsed_s)

    def period(self, summary: PeriodSummary) -> None:
        """Record a completed period, or count a missed one (overrun, interrupted) by its status."""
        if summary.status != "completed":
            self.periods_missed.labels(summary.status).inc()
            return
        self.latency_s.observe(summary.latency_s)
        self.last_period.set(summary.period)

    # --- sink ----------------------------------------------------------------------------------------
    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:  # noqa: ARG002 - Sink signature
        """Count a batch of results (:meth:`results`)."""
        self.results(batch)

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:  # noqa: ARG002 - Sink signature
        """Count one diagnosis report (JSON) by its verdict (``failed`` when it has none)."""
        self.diagnoses.labels(json.loads(payload).get("verdict", "failed")).inc()

    def write_period(self, summary: PeriodSummary) -> None:
        """Record a completed period (:meth:`period`)."""
        self.period(summary)

    def close(self) -> None:
        """Nothing to release (the registry lives as long as the service object)."""

    def render(self) -> bytes:
        """Prometheus text format (the registry, then each of :attr:`exposition`)."""
        return generate_latest(self.registry) + b"".join(part() for part in self.exposition)
