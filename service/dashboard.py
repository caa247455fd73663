"""The dashboard's routes: the static pages (``/ui``, ``/`` redirects there) and the three endpoints they
read besides the REST API's own (``/fleet``, ``/buses/{bus}/diagnoses``, ``/buses/{bus}/playback``).

Everything runs in the service's process on the REST server; the pages' assets (HTML, JS, CSS and the
vendored uPlot chart library) are package data in ``service/ui/``, so the dashboard works offline.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from pathlib import Path
from typing import Annotated

from fastapi import FastAPI, HTTPException, Query
from fastapi.responses import RedirectResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, Field

from service import fleet
from service.executors.base import WindowTask

UI_DIR = Path(__file__).resolve().parent / "ui"

#: A playback is recomputed at most this often per bus [s]: several open pages cost one worker task.
PLAYBACK_TTL_S = 2.0
#: Playbacks in flight at most: the endpoint is unauthenticated, and each one is a worker task.
PLAYBACK_IN_FLIGHT = 4
#: Playbacks kept (about 30 kB each).
PLAYBACK_CACHE = 64
#: Longest wait for a worker to play a model back [s]; during a period the workers' queues are full.
PLAYBACK_TIMEOUT_S = 10.0


class DiagnosisEntry(BaseModel):
    """One diagnosis of a bus, in the timeline of its page."""

    period: float = Field(description="Period boundary of the diagnosed window, UTC [s]")
    verdict: str = Field(description="explained, ambiguous, consistent, unexplained or failed")
    cause: str | None = Field(description="The named cause when explained")
    causes: list[str] = Field(description="The candidates the data do not separate when ambiguous (the cause when explained)")
    message: str | None = Field(description="One sentence for people")
    channels: list[str] = Field(description="Channels (P, Q) where the residual exceeds the noise")
    fit_before: dict[str, float] | None = Field(description="Held-out fit of the plain model {fd_p, fd_q, ...}")
    fit_after: dict[str, float] | None = Field(description="Held-out fit with the named cause")


class PlaybackSeries(BaseModel):
    """The bus's newest frames against its last successful model played back on them."""

    bus: str
    model_period: float = Field(description="Period of the result whose model is played back, UTC [s]")
    t: list[float] = Field(description="PMU time [s] (decimated to at most 600 points)")
    P: list[float | None] = Field(description="Measured P [pu] (low-passed as the identifier sees it)")
    Q: list[float | None] = Field(description="Measured Q [pu]")
    P_model: list[float | None] = Field(description="Model P [pu]")
    Q_model: list[float | None] = Field(description="Model Q [pu]")
    fd_p: float | None = Field(description="Fit degree of P on this window [-]")
    fd_q: float | None = Field(description="Fit degree of Q on this window [-]")
    n: int = Field(description="Samples in the window before decimation")
    computed_at: float = Field(description="Server time of the playback, UTC [s]")


def _entry(payload: str) -> DiagnosisEntry:
    rep = json.loads(payload)
    located = rep.get("located") or {}
    return DiagnosisEntry(period=rep["period"], verdict=rep.get("verdict", "failed"), cause=rep.get("cause"),
                          causes=rep.get("causes") or [],
                          message=rep.get("message"), channels=located.get("channels") or [],
                          fit_before=rep.get("fit_before"), fit_after=rep.get("fit_after"))


def add_dashboard(app: FastAPI, service) -> None:
    """Add the dashboard's routes to the REST application of ``service`` (a ``ServiceView``).

    The playback needs the service's executor (``service.executor``); a view without one answers 503.
    """
    playbacks: dict[str, tuple[float, float, dict]] = {}  # bus → (monotonic time, model period, payload)
    # Released when the worker answers, not when the handler stops waiting: a playback abandoned at the
    # timeout still holds a worker's queue slot.
    slots = threading.BoundedSemaphore(PLAYBACK_IN_FLIGHT)

    @app.get("/", include_in_schema=False)
    def root() -> RedirectResponse:
        return RedirectResponse("/ui/")

    @app.get("/fleet", response_model=fleet.FleetPage)
    def fleet_page(
            q: Annotated[str, Query(description="substring of the bus name (case-insensitive)")] = "",
            state: Annotated[list[str] | None, Query(description=f"keep these states: {', '.join(fleet.STATES)}")] = None,
            verdict: Annotated[list[str] | None, Query(description=f"keep these verdicts: {', '.join(fleet.VERDICTS)}")] = None,
            sort: Annotated[str, Query(description=f"one of {', '.join(fleet.SORT_KEYS)}")] = "bus",
            desc: bool = False,
            offset: Annotated[int, Query(ge=0)] = 0,
            limit: Annotated[int, Query(ge=1, le=1000)] = 100) -> dict:
        now = time.time()
        rows = fleet.fleet_rows(service.latest, service.store.buses(), now, service.period_s)
        try:
            matched, page = fleet.select(rows, q=q, states=state, verdicts=verdict, sort=sort, desc=desc,
                                         offset=offset, limit=limit)
        except ValueError as exc:
            raise HTTPException(422, str(exc)) from None
        return {"total": len(rows), "matched": matched, "offset": offset, "limit": limit, "sort": sort,
                "desc": desc, "counts": fleet.counts(rows), "now": now, "period_s": service.period_s,
                "rows": page}

    @app.get("/buses/{bus:path}/diagnoses", response_model=list[DiagnosisEntry])
    def diagnoses(bus: str,
                  since: Annotated[float | None, Query(description="earliest period, UTC [s]")] = None,
                  limit: Annotated[int, Query(ge=1, le=1000)] = 100) -> list[DiagnosisEntry]:
        """The bus's diagnoses (verdict, named cause, located channels), newest first."""
        return [_entry(js) for js in service.storage.diagnoses(bus, since, limit)]

    @app.get("/buses/{bus:path}/playback", response_model=PlaybackSeries)
    async def playback(bus: str) -> dict:
        """The bus's last successful model played back on its newest ``window_s`` of frames (in a worker)."""
        ok = service.latest.last_ok.get(bus)
        if ok is None or ok.parameters is None:
            raise HTTPException(404, f"no successful result for bus {bus!r} yet")
        cached = playbacks.get(bus)
        if cached is not None and cached[1] == ok.period and time.monotonic() - cached[0] < PLAYBACK_TTL_S:
            return cached[2]
        executor = getattr(service, "executor", None)
        buf = service.store.buffer(bus, create=False)
        if executor is None:
            raise HTTPException(503, "this service has no workers to play the model back")
        if buf is None or not buf.size:
            raise HTTPException(404, f"no frames held for bus {bus!r}")
        if not slots.acquire(blocking=False):
            raise HTTPException(503, "too many playbacks in progress: retry")
        s = service.settings
        newest = buf.newest
        window = buf.cut(newest - s.window_s, newest, f0=s.f0, bus=bus)
        task = WindowTask(window, options={"lowpass_hz": s.lowpass_hz, "input_noise": s.identify_input_noise},
                          fn="service.playback:playback_window",
                          previous={"dynamic": ok.parameters.dynamic, "static": ok.parameters.static})
        try:
            future = executor.submit(task)
        except BaseException:
            slots.release()
            raise
        future.add_done_callback(lambda _: slots.release())
        try:
            # Shielded: a timeout must not cancel the executor's future, which its pool resolves later.
            outcome = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(future)), PLAYBACK_TIMEOUT_S)
        except asyncio.TimeoutError:
            raise HTTPException(503, "the workers are busy (a period is running): retry") from None
        if not outcome.ok:
            raise HTTPException(422, f"playback failed: {outcome.reason}: {outcome.message}")
        payload = {"bus": bus, "model_period": ok.period, "computed_at": time.time(), **outcome.value}
        if len(playbacks) >= PLAYBACK_CACHE:  # pages left open on many buses: keep the newest only
            for old in sorted(playbacks, key=lambda b: playbacks[b][0])[:len(playbacks) // 2]:
                del playbacks[old]
        playbacks[bus] = (time.monotonic(), ok.period, payload)
        return payload

    app.mount("/ui", StaticFiles(directory=UI_DIR, html=True), name="ui")
