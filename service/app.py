"""The service: sources, buffers, scheduler, worker pool, sinks and REST, wired."""

from __future__ import annotations

import json
import logging

from aslm_core.params import DYNAMIC_NAMES
from service import registry
from service.api import RunStatus, create_app
from service.audit import AuditLog
from service.buffers import BufferStore
from service.clock import SYSTEM_CLOCK, Clock
from service.context import Context
from service.executors import make_executor
from service.gc_policy import BetweenPeriodsGC
from service.health import COMPONENTS, HealthCollector, IngestWatch, pool_problem, scheduler_problem
from service.http_server import HttpServer
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import PeriodSummary
from service.scheduler import QualityRules, Scheduler
from service.settings import ServiceSettings, check_period
from service.sinks import SINKS
from service.sinks.base import SinkChain
from service.sources import SOURCES
from service.sources.base import Inlet, Source
from service.storage import Storage
from service.worker import TaskOutcome

log = logging.getLogger(__name__)


class Service:
    """One running service instance.

    Parameters
    ----------
    settings : ServiceSettings
    rest : bool
        Serve the REST API (uvicorn in a thread); off for embedded uses that need no HTTP.
    clock : Clock
        Time of the scheduler and the ingest (default the system clock).

    Notes
    -----
    Start order: storage (history, persisted period, warm starts) → workers (spawned before any Zenoh
    session opens) → sinks → sources (frames flow once their outputs exist) → scheduler → REST.  Stop is
    the reverse.
    """

    def __init__(self, settings: ServiceSettings, *, rest: bool = True, clock: Clock = SYSTEM_CLOCK) -> None:
        self.settings = settings
        self.rest = rest
        self.clock = clock
        self.storage = Storage(settings.storage_path)
        self.audit = AuditLog(settings.storage_path)
        persisted = self.storage.get_config()
        self.period_s = settings.period_s
        if "period_s" in persisted:
            try:
                check_period(float(persisted["period_s"]), settings)
                self.period_s = float(persisted["period_s"])
                log.info("period_s=%g from the run-time configuration persisted in %s", self.period_s,
                         settings.storage_path)
            except (TypeError, ValueError) as exc:
                log.warning("ignoring persisted period_s: %s", exc)
        self.store = BufferStore(settings.window_s, settings.frame_rate, settings.late_s, settings.max_buses,
                                 history_s=settings.input_history_windows * settings.window_s)
        self.metrics = ServiceMetrics(self.store)
        self.metrics.period_s.set(self.period_s)
        self.latest = LatestResults.from_storage(self.storage)
        self.warm_starts: dict[str, list[float]] = {
            bus: [r.parameters.dynamic[k] for k in DYNAMIC_NAMES]
            for bus, r in self.storage.latest_all(ok_only=True).items() if r.parameters is not None
        }
        self.context = Context(settings, self.storage, self.latest, self.metrics, clock)
        self.executor = None
        self.sinks: SinkChain | None = None
        self.sources: list[Source] = []
        self.scheduler: Scheduler | None = None
        self._server: HttpServer | None = None
        self.http_port: int | None = None
        self._stopped = False
        self.gc = BetweenPeriodsGC(busy=lambda: self._stopped or (
            self.scheduler is not None and self.scheduler.running_period is not None))
        self._storage_sink = None
        self._last_summary: PeriodSummary | None = None
        self._ingest = IngestWatch(self.store, clock)
        self.metrics.registry.register(HealthCollector(self.problems, lambda: {
            "scheduler_restarts": self.scheduler.restarts if self.scheduler else 0,
            "diagnoses_shed": self.scheduler.diagnoses.shed if self.scheduler else 0}))

    # --- lifecycle ------------------------------------------------------------------------------------
    def start(self, wait_workers: float = 120.0) -> Service:
        """Start every part; returns self once REST answers (if enabled)."""
        s = self.settings
        self.executor = make_executor(s.executor, s.workers, s.identify_fn, s.task_timeout_s)
        self.context.executor = self.executor  # before the sinks: the tracking sink's joint fits run on it
        if hasattr(self.executor, "wait_ready") and not self.executor.wait_ready(wait_workers):
            log.warning("workers not ready after %g s; continuing", wait_workers)
        # The service's own state (latest results, metrics) goes after the persisting sinks and before
        # the publishing ones: a result is in REST "latest" once stored and before it is on Zenoh.
        named = [registry.load(SINKS, name)(self.context) for name in s.sinks]
        self.sinks = SinkChain([self.latest, self.metrics, *named],
                               on_error=lambda where: self.metrics.request_errors.labels(where).inc())
        self._storage_sink = next((sink for sink in named if sink.name == "storage"), None)
        self._record_interrupted()
        inlet = Inlet(self.store, max_future_s=s.max_future_s, f0=s.f0, clock=self.clock,
                      max_message_bytes=s.max_message_bytes)
        for name in s.sources:
            source = registry.load(SOURCES, name)(self.context)
            source.start(inlet)
            self.sources.append(source)
        rules = QualityRules(s.window_s, s.frame_rate, s.min_coverage, s.max_gap_s, s.min_v_std)
        self.scheduler = Scheduler(
            self.store, self.executor, rules, late_s=s.late_s, f0=s.f0, period_s=lambda: self.period_s,
            on_results=self.sinks.write_results, on_period=self._on_period, warm_starts=self.warm_starts,
            options={"n_starts": s.n_starts, "lowpass_hz": s.lowpass_hz, "objective": s.objective,
                     "input_noise": s.identify_input_noise}, n_starts_warm=s.n_starts_warm,
            diagnose_every=s.diagnose_every, on_diagnosis=self._on_diagnosis, clock=self.clock,
            on_start=self._period_started, diagnose_in_flight=max(1, s.workers - 1),
            bus_idle_s=s.bus_idle_s, on_evicted=self.latest.forget_skipped,
            input_history=s.input_history_windows or None,
        )
        self.scheduler.start()
        if self.rest:
            self._server = HttpServer(create_app(self), s.http_host, s.http_port)
            self._server.start()
            self.http_port = self._server.port
        self.gc.start()
        return self

    def stop(self) -> None:
        """Stop REST, scheduler, sources, sinks, workers, Zenoh and storage (idempotent)."""
        if self._stopped:
            return
        self._stopped = True
        if self._server is not None:
            self._server.stop()
        for source in reversed(self.sources):
            try:
                source.close()
            except Exception:  # noqa: BLE001 - the rest must still stop
                log.exception("closing source %s failed", source.name)
        if self.scheduler is not None:
            self.scheduler.stop()
        # The executor closes before the sinks: its pending tasks resolve (`shutdown`), so a period or a
        # diagnosis still running writes its last results while the sinks and the database are open.
        if self.executor is not None:
            self.executor.close()
        if self.scheduler is not None:
            self.scheduler.stop()
        if self.sinks is not None:
            self.sinks.close()
        self.context.close()
        self.storage.close()
        self.audit.close()
        self.gc.stop()

    def __enter__(self) -> Service:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def url(self) -> str:
        """Base URL of the REST API."""
        return f"http://{self.settings.http_host}:{self.http_port}"

    def status(self) -> RunStatus:
        """Scheduling and worker state for ``GET /health``."""
        sched = self.scheduler
        return RunStatus(next_period=sched.next_period if sched else None,
                         running_period=sched.running_period if sched else None,
                         workers_replaced=getattr(self.executor, "replaced", 0),
                         problems=tuple(f"{part}: {why}" for part, why in self.problems().items() if why))

    def problems(self) -> dict[str, str | None]:
        """Each part of the service (:data:`service.health.COMPONENTS`) → why it is not doing its job, or
        None; ``/health`` is ``degraded`` while any has a reason."""
        if self._stopped:
            return dict.fromkeys(COMPONENTS)
        storage = self._storage_sink.problem() if self._storage_sink is not None else None
        return {
            "scheduler": scheduler_problem(self.scheduler, self.clock, self.settings.late_s, self.period_s),
            "storage": storage,
            "ingest": self._ingest.problem() if self.settings.sources else None,
            "pool": pool_problem(self.executor, self._last_summary) if self.executor is not None else "not started",
        }

    # --- run-time configuration --------------------------------------------------------------------
    def set_period(self, period_s: float) -> None:
        """Change T from the next period on, and persist it.

        Raises
        ------
        ValueError
            A period shorter than window + late allowance.
        """
        check_period(period_s, self.settings)
        self.storage.set_config({"period_s": float(period_s)})
        self.period_s = float(period_s)
        self.metrics.period_s.set(self.period_s)
        if self.scheduler is not None:
            self.scheduler.replan()

    # --- results --------------------------------------------------------------------------------------
    def _on_diagnosis(self, bus: str, period: float, outcome: TaskOutcome) -> None:
        # A failed diagnosis is recorded too; the sinks persist it, keep it as latest, count it by verdict
        # and publish it on {prefix}/diagnosis/{bus}, in that order.
        report = outcome.value if outcome.ok else {"verdict": "failed", "reason": outcome.reason,
                                                   "message": outcome.message}
        js = json.dumps({"bus": bus, "period": period, **report})
        self.sinks.write_diagnosis(bus, period, js)

    def _on_period(self, summary: PeriodSummary) -> None:
        self.sinks.write_period(summary)
        if summary.status != "completed":
            return
        self._last_summary = summary
        try:
            self.storage.clear_running(summary.period)
        except Exception:  # noqa: BLE001 - a stale mark is dropped at the next start (its period is stored)
            log.exception("clearing the running mark of period %s failed", summary.period)
        self.gc.period_done(summary.period_s)

    # --- crash recovery -------------------------------------------------------------------------------
    def _period_started(self, boundary: float, period_s: float, buses: list[str]) -> None:
        # Persisted before any result, so that a kill -9 during the period is recorded at the next start.
        self.storage.mark_running(boundary, period_s, buses)

    def _record_interrupted(self) -> None:
        """Record each period a previous run started and never completed (killed, or failed) as
        ``interrupted``, with the buses that got no result."""
        try:
            found = self.storage.interrupted(self.clock.now(), self.settings.late_s)
        except Exception:  # noqa: BLE001 - the service starts anyway; the marks stay for the next start
            log.exception("reading the periods a previous run left running failed")
            return
        for summary in found:
            log.warning("period %.0f was interrupted (the service stopped while it ran): %d results stored, "
                        "%d buses got none", summary.period, summary.n_ok + summary.n_failed + summary.n_skipped,
                        len(summary.no_result))
            self.sinks.write_period(summary)
            self.storage.clear_running(summary.period)
