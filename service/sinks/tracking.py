"""Tracking sink: a tracked load model per bus (pooled since the last change) and its change events.

Runs in the scheduler process on each period's results (numpy only, :mod:`aslm_core.tracking`): every
successful result's D and standard errors update its bus's tracker.  The tracked models and the change
events are stored in SQLite (tables ``tracked`` and ``changes``, one transaction per batch; the trackers'
state too, so tracking resumes after a restart) and, when the service publishes on Zenoh, put on
``{prefix}/tracked/{bus}`` and ``{prefix}/changes/{bus}``.  REST serves them (``GET /buses/{bus}/tracked``,
``GET /buses/{bus}/changes``); docs/tracking.md has the method and its measured figures.  With
``track_joint_fit`` the pools' windows are kept and fitted jointly on the workers
(:mod:`service.joint_fit`); each tracked model says which estimator it carries (``estimator``).
"""

from __future__ import annotations

import json
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import replace

from aslm_core.params import DYNAMIC_NAMES
from aslm_core.tracking import Tracker, TrackerConfig
from service.busnames import check_bus_name
from service.context import Context
from service.joint_fit import JointFits
from service.models import BusResult, ChangeEvent, PeriodSummary, TrackedModel
from service.storage import Storage

log = logging.getLogger(__name__)


def _finite_or_none(x: float) -> float | None:
    return x if math.isfinite(x) else None


class TrackingSink:
    """Keeps one :class:`~aslm_core.tracking.Tracker` per bus, stores and publishes what it tracks.

    Parameters
    ----------
    storage : Storage
        Where the tracked models, the trackers' state and the change events go (and the state comes from).
    config : TrackerConfig
        Pool length and false-alarm rate (its ``period_s`` is replaced by each result's T).
    put : callable, optional
        ``put(key, json_text)``: the publication (a Zenoh put in the service); None publishes nothing.
    prefix : str
        Zenoh key prefix.
    on_error : callable, optional
        Called once per failed put.
    joint : JointFits, optional
        The joint pooled fits of the pools' windows (``track_joint_fit``): the tracked model is the joint
        fit of its pool once it has arrived, the mean of the windows' estimates until then; None: the mean.
    on_tracked : callable, optional
        Called with the bus after a joint fit arrived and was stored and published (executor thread).
    """

    name = "tracking"
    persists = True

    def __init__(self, storage: Storage, config: TrackerConfig, *, put: Callable[[str, str], None] | None = None,
                 prefix: str = "aslm", on_error: Callable[[], None] | None = None,
                 joint: JointFits | None = None, on_tracked: Callable[[str], None] | None = None) -> None:
        self.storage = storage
        self._on_tracked = on_tracked or (lambda bus: None)
        self.config = config
        self._put = put
        self.prefix = prefix
        self._on_error = on_error or (lambda: None)
        self.trackers: dict[str, Tracker] = {}
        # bus -> (period, static, static_local) of its newest successful result (the model's static part)
        self._newest: dict[str, tuple[float, dict, dict]] = {}
        # The scheduler's thread writes results, the executor's delivers joint fits: one at a time.
        self._lock = threading.RLock()
        self.joint = joint
        if joint is not None:
            joint.arrived = self._joint_arrived
        for bus, state in storage.tracker_states().items():
            try:
                self.trackers[bus] = Tracker.from_state(json.loads(state), config)
            except (ValueError, TypeError, KeyError):  # a state of another version: start that bus afresh
                log.warning("tracking: cannot resume the tracker of %s; it starts afresh", bus)

    def write_results(self, batch: list[BusResult], payloads: list[str]) -> None:  # noqa: ARG002 - Sink signature
        """Update the trackers with the batch's successful results; store, then publish."""
        tracked, changes, puts = [], [], []
        windows = getattr(batch, "windows", {})  # a ResultBatch from the scheduler carries them
        with self._lock:
            for res in batch:
                par = res.parameters
                if res.status != "ok" or par is None:
                    continue
                tr = self.trackers.get(res.bus)
                if tr is None:
                    tr = self.trackers[res.bus] = Tracker(config=self.config)
                if tr.config.period_s != res.period_s:
                    tr.config = replace(tr.config, period_s=res.period_s)
                se = [par.stderr.get(k) for k in DYNAMIC_NAMES]
                event = tr.update(res.period, [par.dynamic[k] for k in DYNAMIC_NAMES],
                                  [math.inf if s is None else s for s in se])
                if self.joint is not None:
                    self.joint.observe(res.bus, res.period, windows.get(res.bus), tr)
                self._newest[res.bus] = (res.period, par.static, par.static_local)
                body = self._body(res.bus, tr)
                if body is None:
                    continue
                tracked.append((res.bus, res.period, body, json.dumps(tr.to_state())))
                puts.append((f"{self.prefix}/tracked/{check_bus_name(res.bus)}", body))
                if event is not None:
                    ev = event.to_dict()
                    for side in ("before", "after"):
                        ev[side]["stderr"] = {k: _finite_or_none(v) for k, v in ev[side]["stderr"].items()}
                    js = ChangeEvent(bus=res.bus, **ev).model_dump_json()
                    changes.append((res.bus, event.t, js))
                    puts.append((f"{self.prefix}/changes/{check_bus_name(res.bus)}", js))
            if tracked:
                self.storage.save_tracking(tracked, changes)
        self._publish(puts)

    def _body(self, bus: str, tr: Tracker) -> str | None:
        """JSON of the bus's tracked model: the joint fit of its pool when it has arrived, else the mean."""
        model = tr.model()
        if model is None:
            return None
        joint = self.joint.current(bus) if self.joint is not None else None
        pooled = joint if joint is not None else model
        _, static, static_local = self._newest[bus]
        return TrackedModel(
            bus=bus, period=model["t"], since=model["since"], last_change=model["last_change"],
            suspect=model["suspect"], dynamic=pooled["dynamic"],
            stderr={k: None if v is None else _finite_or_none(v) for k, v in pooled["stderr"].items()},
            n_windows=pooled["n_windows"], static=static, static_local=static_local,
            pool_windows=tr.config.pool_windows, threshold=tr.config.threshold,
            estimator="mean" if joint is None else "joint",
            disturbance=None if joint is None else joint.get("disturbance")).model_dump_json()

    def _joint_arrived(self, bus: str) -> None:
        """A joint fit of the bus's current pool arrived (executor thread): store and publish the model."""
        with self._lock:
            tr = self.trackers.get(bus)
            body = self._body(bus, tr) if tr is not None and bus in self._newest else None
            if body is None:
                return
            self.storage.save_tracking([(bus, self._newest[bus][0], body, json.dumps(tr.to_state()))], [])
        self._publish([(f"{self.prefix}/tracked/{check_bus_name(bus)}", body)])
        try:
            self._on_tracked(bus)
        except Exception:  # noqa: BLE001 - a listener's failure never loses the fit
            self._on_error()
            log.exception("a listener of the tracked model of %s failed", bus)

    def _publish(self, puts: list[tuple[str, str]]) -> None:
        if self._put is None:
            return
        for key, js in puts:
            try:
                self._put(key, js)
            except Exception:  # noqa: BLE001 - one bus's publication never stops the others
                self._on_error()
                log.exception("publishing %s failed", key)

    def write_diagnosis(self, bus: str, period: float, payload: str) -> None:
        """Diagnoses do not move the tracked model."""

    def write_period(self, summary: PeriodSummary) -> None:
        """Hand the period's joint fits to the workers; forget the rings of buses gone idle."""
        if self.joint is not None:
            self.joint.submit_round(summary.period)
            self.joint.evict_idle(summary.period)

    def close(self) -> None:
        """Nothing held (the storage and the session are the instance's)."""


def build(ctx: Context) -> TrackingSink:
    """The tracking sink on the service's storage with the settings' ``track_pool_windows`` and
    ``track_false_alarms_per_day``; it publishes on the instance's Zenoh session when the ``zenoh`` sink is
    configured (failed puts count as ``aslm_internal_errors{where="publish"}``).  With ``track_joint_fit``
    (and the service's executor) the pools of the first ``track_joint_fit_buses`` buses are fitted jointly
    on the workers."""
    s = ctx.settings
    config = TrackerConfig(pool_windows=s.track_pool_windows, false_alarms_per_day=s.track_false_alarms_per_day,
                           period_s=s.period_s)
    put = None
    if "zenoh" in s.sinks:
        import zenoh

        session = ctx.zenoh_session()

        def put(key: str, payload: str) -> None:
            session.put(key, payload, encoding=zenoh.Encoding.APPLICATION_JSON,
                        congestion_control=zenoh.CongestionControl.BLOCK)

    joint = None
    if s.track_joint_fit and s.track_joint_fit_buses > 0 and ctx.executor is not None:
        joint = JointFits(ctx.executor, max_buses=s.track_joint_fit_buses, in_flight=max(1, s.workers - 1),
                          options={"lowpass_hz": s.lowpass_hz, "input_noise": s.identify_input_noise},
                          idle_s=s.bus_idle_s)
    def on_tracked(bus: str) -> None:
        for listener in list(ctx.tracked_listeners):
            listener(bus)

    return TrackingSink(ctx.storage, config, put=put, prefix=s.prefix,
                        on_error=ctx.metrics.request_errors.labels("publish").inc, joint=joint,
                        on_tracked=on_tracked)
