"""The service: Zenoh ingest, buffers, scheduler, worker pool, storage, publication and REST, wired."""

from __future__ import annotations

import gc
import json
import logging
import threading
import time

import uvicorn
import zenoh

from service.api import create_app
from service.buffers import BufferStore
from service.executors import make_executor
from service.metrics import ServiceMetrics
from service.models import BusResult, PeriodSummary
from service.publish import ResultPublisher
from service.scheduler import QualityRules, Scheduler
from service.settings import ServiceSettings, check_period
from service.storage import Storage
from service.worker import TaskOutcome
from service.zenoh_config import from_settings

log = logging.getLogger(__name__)

# Automatic full (generation 2) collections are switched off while a service runs: one holds the GIL
# for as long as it scans every live object (measured 40–200 ms with 1,000 buses, more with 10,000),
# which stalled REST answers during periods.  Startup objects are frozen (never scanned again), and
# a collection runs between periods instead (min(T/4, 30 s) after one ends: the workers are idle
# then); it freezes what survives, so it scans only what the last period left (~10 ms at 1,000
# buses, ~70 ms at 10,000 with free cores).  Frozen objects are still freed when their last
# reference goes; only cycles among them wait for the complete collection every _FULL_GC_EVERY
# periods, which unfreezes everything first.
_GEN2_THRESHOLD_OFF = 1_000_000_000
_FULL_GC_EVERY = 24
_gc_lock = threading.Lock()
_gc_state = {"services": 0, "threshold": (700, 10, 10)}  # services running in this process, thresholds before


def _gc_service_started() -> None:
    with _gc_lock:
        if _gc_state["services"] == 0:
            _gc_state["threshold"] = gc.get_threshold()
            gc.collect()
            gc.freeze()  # modules, schemas, routes, sessions: never scanned again
            gc.set_threshold(*_gc_state["threshold"][:2], _GEN2_THRESHOLD_OFF)
        _gc_state["services"] += 1


def _gc_service_stopped() -> None:
    with _gc_lock:
        _gc_state["services"] -= 1
        if _gc_state["services"] == 0:
            gc.set_threshold(*_gc_state["threshold"])
            gc.unfreeze()


class Service:
    """One running service instance.

    Parameters
    ----------
    settings : ServiceSettings
    rest : bool
        Serve the REST API (uvicorn in a thread); off for embedded uses that need no HTTP.

    Notes
    -----
    Start order: storage (history, persisted period, warm starts) → workers (spawned before the Zenoh
    session opens) → Zenoh session, publisher, ingest → scheduler → REST.  Stop is the reverse.
    """

    def __init__(self, settings: ServiceSettings, *, rest: bool = True) -> None:
        self.settings = settings
        self.rest = rest
        self.storage = Storage(settings.storage_path)
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
        self.store = BufferStore(settings.window_s, settings.frame_rate, settings.late_s)
        self.metrics = ServiceMetrics(self.store)
        self.metrics.period_s.set(self.period_s)
        self.latest: dict[str, BusResult] = self.storage.latest_all()
        # JSON of each bus's latest result, serialised once: REST "latest" and Zenoh share it.
        self.latest_json: dict[str, str] = {b: r.model_dump_json() for b, r in self.latest.items()}
        self.latest_diagnosis_json: dict[str, str] = self.storage.latest_diagnoses()
        self.warm_starts: dict[str, list[float]] = {
            bus: [r.parameters.dynamic[k] for k in ("a", "b", "H2", "Tm")]
            for bus, r in self.storage.latest_all(ok_only=True).items() if r.parameters is not None
        }
        self.executor = None
        self.session: zenoh.Session | None = None
        self.ingest = None
        self.publisher: ResultPublisher | None = None
        self.scheduler: Scheduler | None = None
        self._server: uvicorn.Server | None = None
        self._server_thread: threading.Thread | None = None
        self.http_port: int | None = None
        self._stopped = False
        self._periods_done = 0
        self._gc_complete_due = False

    # --- lifecycle ------------------------------------------------------------------------------------
    def start(self, wait_workers: float = 120.0) -> Service:
        """Start every part; returns self once REST answers (if enabled)."""
        s = self.settings
        self.executor = make_executor(s.executor, s.workers, s.identify_fn, s.task_timeout_s)
        if hasattr(self.executor, "wait_ready") and not self.executor.wait_ready(wait_workers):
            log.warning("workers not ready after %g s; continuing", wait_workers)
        from service.ingest import Ingest

        self.session = zenoh.open(from_settings(s))
        self.publisher = ResultPublisher(self.session, s.prefix, s.instance, lambda: self.latest.copy())
        self.ingest = Ingest(self.session, s.prefix, self.store, max_future_s=s.max_future_s, f0=s.f0,
                             keys=s.pmu_keys)
        rules = QualityRules(s.window_s, s.frame_rate, s.min_coverage, s.max_gap_s, s.min_v_std)
        self.scheduler = Scheduler(
            self.store, self.executor, rules, late_s=s.late_s, f0=s.f0, period_s=lambda: self.period_s,
            on_results=self._on_results, on_period=self._on_period, warm_starts=self.warm_starts,
            options={"n_starts": s.n_starts, "lowpass_hz": s.lowpass_hz, "objective": s.objective}, n_starts_warm=s.n_starts_warm,
            diagnose_every=s.diagnose_every, on_diagnosis=self._on_diagnosis,
        )
        self.scheduler.start()
        if self.rest:
            self._start_rest()
        _gc_service_started()
        self._gc_managed = True
        return self

    def _start_rest(self) -> None:
        config = uvicorn.Config(create_app(self), host=self.settings.http_host, port=self.settings.http_port,
                                log_level="warning", access_log=False)
        self._server = uvicorn.Server(config)
        self._server_thread = threading.Thread(target=self._server.run, name="aslm-rest", daemon=True)
        self._server_thread.start()
        end = time.monotonic() + 20
        while not self._server.started:
            if not self._server_thread.is_alive() or time.monotonic() > end:
                raise RuntimeError(f"REST server did not start on {self.settings.http_host}:{self.settings.http_port}")
            time.sleep(0.02)
        self.http_port = self._server.servers[0].sockets[0].getsockname()[1]

    def stop(self) -> None:
        """Stop REST, scheduler, ingest, publication, workers, Zenoh and storage (idempotent)."""
        if self._stopped:
            return
        self._stopped = True
        if self._server is not None:
            self._server.should_exit = True
            self._server_thread.join(10)
        if self.scheduler is not None:
            self.scheduler.stop()
        if self.ingest is not None:
            self.ingest.close()
        if self.publisher is not None:
            self.publisher.close()
        if self.executor is not None:
            self.executor.close()
        if self.session is not None:
            self.session.close()
        self.storage.close()
        if getattr(self, "_gc_managed", False):
            _gc_service_stopped()

    def __enter__(self) -> Service:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def url(self) -> str:
        """Base URL of the REST API."""
        return f"http://{self.settings.http_host}:{self.http_port}"

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
    def _on_results(self, batch: list[BusResult]) -> None:
        # Persist first (history survives a crash), then publish; a failing publication is logged only.
        payloads = [res.model_dump_json() for res in batch]  # serialised once: SQLite, REST, Zenoh
        self.storage.save_results(batch, payloads)
        for res, js in zip(batch, payloads, strict=True):
            self.latest[res.bus] = res
            self.latest_json[res.bus] = js
        self.metrics.results(batch)
        for res, js in zip(batch, payloads, strict=True):
            try:
                self.publisher.publish(res, js)
            except Exception:  # noqa: BLE001 - one bus's publication never stops the others
                self.metrics.request_errors.labels("publish").inc()
                log.exception("publishing %s failed", res.bus)

    def _on_diagnosis(self, bus: str, period: float, outcome: TaskOutcome) -> None:
        # Persist, keep as latest, publish on {prefix}/diagnosis/{bus}; a failed diagnosis is recorded too.
        report = outcome.value if outcome.ok else {"verdict": "failed", "reason": outcome.reason,
                                                   "message": outcome.message}
        js = json.dumps({"bus": bus, "period": period, **report})
        self.storage.save_diagnosis(bus, period, js)
        self.latest_diagnosis_json[bus] = js
        self.metrics.diagnoses.labels(report.get("verdict", "failed")).inc()
        try:
            self.publisher.publish_diagnosis(bus, js)
        except Exception:  # noqa: BLE001 - publication trouble is logged, never fatal
            self.metrics.request_errors.labels("publish").inc()
            log.exception("publishing the diagnosis of %s failed", bus)

    def _on_period(self, summary: PeriodSummary) -> None:
        self.storage.save_period(summary)
        self.metrics.period(summary)
        self.storage.purge(summary.period - 86400.0 * self.settings.retention_days)
        self._periods_done += 1
        self._gc_complete_due |= self._periods_done % _FULL_GC_EVERY == 0
        timer = threading.Timer(min(0.25 * summary.period_s, 30.0), self._collect_garbage)
        timer.daemon = True
        timer.start()

    def _collect_garbage(self) -> None:
        """The collection automatic GC no longer does (see _GEN2_THRESHOLD_OFF), between periods.

        Skipped if a period is running by then (periods run back to back): the next one's end retries.
        """
        if self._stopped or (self.scheduler is not None and self.scheduler.running_period is not None):
            return
        complete, self._gc_complete_due = self._gc_complete_due, False
        t0 = time.perf_counter()
        with _gc_lock:
            if complete:
                gc.unfreeze()
            found = gc.collect()
            gc.freeze()
        log.debug("%s garbage collection between periods: %d objects freed in %.1f ms",
                  "complete" if complete else "young", found, 1e3 * (time.perf_counter() - t0))
