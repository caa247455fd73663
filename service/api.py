"""REST API (FastAPI): results, buses, configuration and metrics of a running service."""

from __future__ import annotations

import hmac
import json
import logging
import math
import time
from dataclasses import dataclass
from typing import Annotated, Literal, Protocol

from fastapi import Depends, FastAPI, Header, HTTPException, Query, Request, Response
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field

from service.audit import AuditEntry, AuditLog, token_identity
from service.buffers import BufferStore
from service.busnames import bus_name_problem
from service.dashboard import add_dashboard
from service.docs_assets import mount_docs
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import BusResult, ChangeEvent, LatestDiagnosis, PeriodSummary, TrackedModel
from service.settings import PERIOD_MAX_S, ServiceSettings
from service.storage import Storage

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunStatus:
    """Scheduling and worker state of a running service.

    Attributes
    ----------
    next_period : float or None
        Next boundary being waited for, UTC [s].
    running_period : float or None
        Boundary of the period being computed, if any [s].
    workers_replaced : int
        Worker processes replaced after a crash or timeout.
    problems : tuple of str
        ``"<component>: <reason>"`` for each part not doing its job (``/health`` is then ``degraded``).
    """

    next_period: float | None
    running_period: float | None
    workers_replaced: int
    problems: tuple[str, ...] = ()


class ServiceView(Protocol):
    """What the REST handlers read and change of a running service (:class:`service.app.Service` is one).

    Attributes
    ----------
    settings : ServiceSettings
        Settings in force (instance name, operator token, ``diagnose_every``).
    store : BufferStore
        Ingest accounting by bus.
    storage : Storage
        Read side: history, periods, latest successful result.
    latest : LatestResults
        Latest result and diagnosis of each bus, pre-serialised.
    metrics : ServiceMetrics
    period_s : float
        Period T in force [s].
    audit : AuditLog
        Run-time configuration changes: who, when, old → new.
    """

    settings: ServiceSettings
    store: BufferStore
    storage: Storage
    latest: LatestResults
    metrics: ServiceMetrics
    period_s: float
    audit: AuditLog

    def status(self) -> RunStatus:
        """Scheduling and worker state."""
        ...

    def set_period(self, period_s: float) -> None:
        """Change T [s] from the next period on and persist it; ValueError if it is too short."""
        ...


class Health(BaseModel):
    """Liveness and a summary of the service state."""

    status: Literal["ok", "degraded"] = Field(description="ok, or degraded while a part of the service is not "
                                                           "doing its job (see problems)")
    problems: list[str] = Field(default_factory=list, description="'<component>: <reason>' for each of scheduler, "
                                "storage, ingest, pool that is not doing its job")
    instance: str
    uptime_s: float
    period_s: float = Field(description="Period T in force [s]")
    next_period: float | None = Field(description="Next boundary being waited for, UTC [s]")
    running_period: float | None = Field(description="Boundary of the period being computed, if any")
    last_period: PeriodSummary | None
    buses: int = Field(description="Buses known to the ingest")
    frames_received: int
    frames_dropped: int
    workers_replaced: int = Field(description="Worker processes replaced after a crash or timeout")


class BusInfo(BaseModel):
    """One bus: ingest accounting and its latest result."""

    bus: str
    frames_buffered: int = Field(description="Frames accepted since start")
    frames_dropped: dict[str, int] = Field(description="Frames dropped by reason since start")
    messages_dropped: dict[str, int] = Field(description="Undecodable messages by reason since start")
    newest_t: float | None = Field(description="PMU time of the newest frame held [s]")
    last_status: str | None = Field(description="Status of the latest result")
    last_period: float | None = Field(description="Period of the latest result [s]")


class ConfigView(BaseModel):
    """Settings in force (operator token masked)."""

    settings: dict
    period_s: float = Field(description="Effective period T [s] (settings or the persisted run-time change)")
    startup_period_s: float = Field(
        description="T [s] from the settings (file < environment < flags), before any run-time change")
    period_source: str = Field(
        description="Where period_s comes from: settings, or run-time (a PUT /config change, persisted in "
                    "the SQLite file; it overrides the settings at every start)")


class ConfigUpdate(BaseModel):
    """Run-time changes; they take effect from the next period and are persisted.

    Unknown fields and non-finite numbers are refused (422): a field that is ignored looks applied.
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    period_s: float | None = Field(None, gt=0, le=PERIOD_MAX_S,
                                   description=f"New period T [s] (>= window_s + late_s, <= {PERIOD_MAX_S:g})")


def _json_safe(value: object) -> object:
    """``value`` with every non-finite float replaced by its text (``'nan'``, ``'inf'``), recursively."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:  # noqa: ARG001
    """FastAPI's 422, with non-finite inputs echoed as text: the default handler echoes the input as JSON
    numbers, which cannot hold NaN or inf, so ``{"period_s": NaN}`` became a 500."""
    return JSONResponse(status_code=422, content={"detail": jsonable_encoder(_json_safe(exc.errors()))})


RecordFormat = Literal["andes", "psse", "pslf"]


@dataclass(frozen=True)
class RecordQuery:
    """``?format=…`` and the record assumptions of the parameters endpoints (docs/records.md)."""

    fmt: RecordFormat | None
    xp: float | None
    td0: float | None
    loading: float
    v0: float


def record_query(
    fmt: Annotated[RecordFormat | None, Query(alias="format", description="records for a simulator instead of "
                                              "the identified parameters: andes, psse or pslf")] = None,
    xp: Annotated[float | None, Query(gt=0, description="record assumption: X' on the motor base [pu] "
                                      "(default 0.2)")] = None,
    td0: Annotated[float | None, Query(gt=0, description="record assumption: Td0 [s] instead of X'")] = None,
    loading: Annotated[float, Query(gt=0, le=1, description="record assumption: motor loading factor")] = 0.8,
    v0: Annotated[float, Query(gt=0, description="record assumption: power-flow voltage of the bus [pu]")] = 1.0,
) -> RecordQuery:
    """The record query parameters (a FastAPI dependency shared by the two parameters endpoints)."""
    return RecordQuery(fmt, xp, td0, loading, v0)


def _records(results: list, q: RecordQuery, f0: float) -> list[dict]:
    """The records of results (BusResult or JSON), 422 with the reason when one cannot be written."""
    from aslm_core.records import Assumptions, RecordError
    from service.records import record_payload

    asm = Assumptions(xp=q.xp, td0=q.td0, loading=q.loading, v0=q.v0, f0=f0)
    try:
        return [record_payload(r if isinstance(r, (BusResult, dict)) else BusResult.model_validate_json(r), q.fmt,
                               asm) for r in results]
    except RecordError as exc:
        raise HTTPException(422, str(exc)) from None


async def valid_bus(bus: str) -> str:
    """The ``{bus}`` path parameter, refused with 422 if it breaks :mod:`service.busnames` (``*``, ``a/**``).

    Async so that the pre-serialised ``latest`` handlers stay on the event loop (no thread hop).
    """
    problem = bus_name_problem(bus)
    if problem is not None:
        raise HTTPException(422, problem)
    return bus


BusPath = Annotated[str, Depends(valid_bus)]


def create_app(service: ServiceView) -> FastAPI:
    """FastAPI application bound to one running service (a :class:`ServiceView`)."""
    app = FastAPI(title="ASLM service", version="0.1.0", docs_url=None, redoc_url=None,
                  description="Ambient-signal load model identification from PMU streams.")
    app.add_exception_handler(RequestValidationError, _validation_error)
    mount_docs(app)  # Swagger UI from installed files: /docs works offline
    started = time.time()

    def operator(request: Request, authorization: Annotated[str | None, Header()] = None,
                 x_operator_token: Annotated[str | None, Header()] = None) -> str | None:
        """Require ``Authorization: Bearer <token>`` (or ``X-Operator-Token``); the token's fingerprint."""
        expected = service.settings.operator_token
        given = x_operator_token
        if authorization and authorization.lower().startswith("bearer "):
            given = authorization[7:].strip()
        if expected is None:
            log.warning("refused %s %s from %s: no operator token configured", request.method, request.url.path,
                        _address(request))
            raise HTTPException(401, "no operator token is configured (ASLM_OPERATOR_TOKEN): changes refused",
                                headers={"WWW-Authenticate": "Bearer"})
        if not given or not hmac.compare_digest(given.encode(), expected.get_secret_value().encode()):
            log.warning("refused %s %s from %s: missing or wrong operator token", request.method,
                        request.url.path, _address(request))
            raise HTTPException(401, "operator token required", headers={"WWW-Authenticate": "Bearer"})
        return token_identity(given)

    def config_view() -> ConfigView:
        startup = service.settings.period_s
        return ConfigView(settings=service.settings.public_dict(), period_s=service.period_s,
                          startup_period_s=startup,
                          period_source="settings" if service.period_s == startup else "run-time")

    @app.get("/health", response_model=Health)
    def health() -> Health:
        tot = service.store.totals()
        periods = service.storage.periods(limit=1)
        run = service.status()
        return Health(
            status="degraded" if run.problems else "ok", problems=list(run.problems),
            instance=service.settings.instance, uptime_s=time.time() - started,
            period_s=service.period_s, next_period=run.next_period, running_period=run.running_period,
            last_period=periods[0] if periods else None, buses=tot.buses,
            frames_received=tot.frames_received, frames_dropped=sum(tot.frames_rejected.values()),
            workers_replaced=run.workers_replaced,
        )

    @app.get("/buses", response_model=list[BusInfo])
    def buses() -> list[BusInfo]:
        latest = service.latest.snapshot()
        names = sorted(set(service.store.buses()) | set(latest))
        out = []
        for bus in names:
            c = service.store.counts(bus)
            res = latest.get(bus)
            out.append(BusInfo(
                bus=bus, frames_buffered=c.buffered if c else 0, frames_dropped=c.rejected if c else {},
                messages_dropped=c.messages_rejected if c else {}, newest_t=c.newest_t if c else None,
                last_status=res.status if res else None, last_period=res.period if res else None,
            ))
        return out

    @app.get("/buses/{bus:path}/parameters/latest", response_model=BusResult)
    async def latest(bus: BusPath, rq: Annotated[RecordQuery, Depends(record_query)],
                     ok: Annotated[bool, Query(description="latest successful result only")] = False) -> Response:
        # Async and pre-serialised: answered on the event loop without a thread hop or re-validation,
        # so it stays fast while a period is being computed.
        js = service.latest.results_json.get(bus)
        res = service.latest.results.get(bus)
        if ok and (res is None or res.status != "ok"):
            older = service.storage.latest(bus, ok_only=True)
            js = older.model_dump_json() if older is not None else None
        if js is None:
            raise HTTPException(404, f"no result for bus {bus!r} yet")
        if rq.fmt is not None:
            return JSONResponse(_records([js], rq, service.settings.f0)[0])
        return Response(js, media_type="application/json")

    @app.get("/buses/{bus:path}/parameters", response_model=list[BusResult])
    def history(bus: BusPath, rq: Annotated[RecordQuery, Depends(record_query)],
                since: Annotated[float | None, Query(description="earliest period, UTC [s]")] = None,
                until: Annotated[float | None, Query(description="latest period, UTC [s]")] = None,
                limit: Annotated[int, Query(ge=1, le=10000)] = 100) -> list[BusResult]:
        found = service.storage.history(bus, since, until, limit)
        if rq.fmt is not None:
            return JSONResponse(_records([r for r in found if r.status == "ok"], rq, service.settings.f0))
        return found

    @app.get("/buses/{bus:path}/diagnosis/latest", response_model=LatestDiagnosis)
    async def diagnosis(bus: BusPath) -> Response:
        """The bus's latest discrepancy diagnosis (DESIGN §3: verdict, located, missing_physics, fit).

        Served pre-serialised like ``parameters/latest``; the response model documents the payload.
        """
        js = service.latest.diagnoses_json.get(bus)
        if js is None:
            every = service.settings.diagnose_every
            when = f"every {every} periods" if every else "never (diagnose_every = 0)"
            raise HTTPException(404, f"no diagnosis for bus {bus!r} yet: the service diagnoses {when}")
        return Response(js, media_type="application/json")

    @app.get("/buses/{bus:path}/tracked", response_model=TrackedModel)
    def tracked(bus: BusPath, rq: Annotated[RecordQuery, Depends(record_query)]) -> Response:
        """The bus's tracked model: D pooled since the last change, its uncertainty, the last change
        (docs/tracking.md); with ``?format=…`` its records for a simulator."""
        js = service.storage.tracked(bus)
        if js is None:
            raise HTTPException(404, f"no tracked model for bus {bus!r} (the 'tracking' sink tracks every bus "
                                     "with a successful result)")
        if rq.fmt is not None:
            return JSONResponse(_records([json.loads(js)], rq, service.settings.f0)[0])
        return Response(js, media_type="application/json")

    @app.get("/buses/{bus:path}/changes", response_model=list[ChangeEvent])
    def changes(bus: BusPath, since: Annotated[float | None, Query(description="earliest change, UTC [s]")] = None,
                limit: Annotated[int, Query(ge=1, le=10000)] = 100) -> Response:
        """Detected changes of the bus's load model, newest first (time, before/after, evidence)."""
        return Response("[" + ",".join(service.storage.changes(bus, since, limit)) + "]",
                        media_type="application/json")

    @app.get("/periods", response_model=list[PeriodSummary])
    def periods(limit: Annotated[int, Query(ge=1, le=1000)] = 20) -> list[PeriodSummary]:
        return service.storage.periods(limit)

    @app.get("/config", response_model=ConfigView)
    def get_config() -> ConfigView:
        return config_view()

    @app.put("/config", response_model=ConfigView)
    def put_config(update: ConfigUpdate, request: Request,
                   token: str | None = Depends(operator)) -> ConfigView:  # noqa: B008 - FastAPI's idiom
        # Depends as a default, not in Annotated: with postponed annotations FastAPI cannot resolve the
        # local name `operator` from a string and would take `token` for a query parameter.
        if update.period_s is not None:
            old = service.period_s
            try:
                service.set_period(update.period_s)
            except ValueError as exc:
                raise HTTPException(422, str(exc)) from None
            entry = service.audit.record("period_s", old, service.period_s, token=token,
                                         address=_address(request))
            log.info("configuration: period_s %g -> %g s by token %s from %s", old, service.period_s,
                     entry.token, entry.address)
        return config_view()

    @app.get("/config/audit", response_model=list[AuditEntry])
    def config_audit(limit: Annotated[int, Query(ge=1, le=10000)] = 100) -> list[AuditEntry]:
        """Run-time configuration changes, newest first: who (token fingerprint, client address), when, old → new."""
        return service.audit.entries(limit)

    @app.get("/metrics", response_class=Response)
    def metrics() -> Response:
        return Response(service.metrics.render(), media_type="text/plain; version=0.0.4; charset=utf-8")

    add_dashboard(app, service)  # /ui (and / → /ui/), /fleet, /buses/{bus}/diagnoses, /buses/{bus}/playback
    return app


def _address(request: Request) -> str | None:
    """``host:port`` of the client (the direct peer: a reverse proxy in front shows as itself)."""
    client = request.client
    return f"{client.host}:{client.port}" if client else None
