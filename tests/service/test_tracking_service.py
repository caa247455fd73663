"""The tracking sink: tracked model and change events stored, published, served over REST, resumed after a
restart, and used by the records sink."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from service_helpers import settings_for
from test_service_api import View

from aslm_core.records import Assumptions
from aslm_core.tracking import TrackerConfig
from service.api import create_app
from service.audit import AuditLog
from service.buffers import BufferStore
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import BusResult, ChangeEvent, TrackedModel
from service.sinks import SINKS
from service.sinks.base import SinkChain
from service.sinks.records import RecordsSink
from service.sinks.storage import StorageSink
from service.sinks.tracking import TrackingSink
from service.storage import Storage

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

D = np.array([22.796, 19.159, 1.0, 0.2])
SE = 0.02 * D
ZIP = {"Pz": 0.06, "Pi": 0.045, "Pp": 0.045, "Qz": 1.3105, "Qi": 0.03, "Qp": 0.03}


def _ok(bus: str, period: float, d: np.ndarray) -> BusResult:
    params = {"dynamic": dict(zip(("a", "b", "H2", "Tm"), d.tolist(), strict=True)), "static": ZIP,
              "objective": 0.1, "fit": {"fd_p": 0.99, "fd_q": 0.99},
              "stderr": dict(zip(("a", "b", "H2", "Tm"), SE.tolist(), strict=True))}
    return BusResult(bus=bus, period=period, period_s=900.0, status="ok", completed_at=period + 1, parameters=params)


def _sequence(n_before: int = 10, n_after: int = 3, seed: int = 2) -> list[BusResult]:
    """A bus whose motors go up 20 % (a, H2, Tm × 1.2) after n_before periods; 2 % noise per window."""
    rng = np.random.default_rng(seed)
    step = np.array([1.2, 1.0, 1.2, 1.2])
    return [_ok("bus-7", 900.0 * i, (D * (step if i >= n_before else 1.0)) + SE * rng.standard_normal(4))
            for i in range(n_before + n_after)]


@pytest.fixture
def tracked(tmp_path):
    settings = settings_for(tmp_path, 7447, period_s=900.0, window_s=10.0, late_s=1.0,
                            sinks=["storage", "tracking"], track_pool_windows=8)
    store = BufferStore(settings.window_s, settings.frame_rate, settings.late_s)
    storage = Storage(settings.storage_path)
    view = View(settings, store, storage, LatestResults(), ServiceMetrics(store), settings.period_s,
                AuditLog(settings.storage_path))
    puts = []
    sink = TrackingSink(storage, TrackerConfig(pool_windows=8), put=lambda k, p: puts.append((k, json.loads(p))))
    chain = SinkChain([StorageSink(storage, 1e9), sink, view.latest], on_error=pytest.fail)
    with TestClient(create_app(view)) as client:
        yield storage, chain, client, puts
    storage.close()


def test_a_step_is_recorded_published_and_served_and_the_pool_restarts(tracked):
    storage, chain, client, puts = tracked
    assert client.get("/buses/bus-7/tracked").status_code == 404
    for res in _sequence():
        chain.write_results([res])
    model = TrackedModel.model_validate(client.get("/buses/bus-7/tracked").json())
    assert model.last_change == 9000.0 and model.since == 9000.0 and model.n_windows == 3
    assert model.dynamic["Tm"] == pytest.approx(0.24, rel=0.05) and model.stderr["Tm"] < SE[3]
    assert model.static == ZIP and model.pool_windows == 8
    events = [ChangeEvent.model_validate(e) for e in client.get("/buses/bus-7/changes").json()]
    assert len(events) == 1
    ev = events[0]
    assert ev.t == 9000.0 and ev.detected_t == 9900.0 and ev.before.n_windows == 8 and ev.after.n_windows == 2
    assert ev.before.dynamic["Tm"] == pytest.approx(0.2, rel=0.05) and abs(ev.evidence.z[1]) > ev.evidence.threshold
    # Published: a tracked model per successful result, the change once, each as REST serves it.
    keys = [k for k, _ in puts]
    assert keys.count("aslm/tracked/bus-7") == 13 and keys.count("aslm/changes/bus-7") == 1
    assert dict(puts)["aslm/changes/bus-7"] == client.get("/buses/bus-7/changes").json()[0]
    assert client.get("/buses/bus-7/changes", params={"since": 9001.0}).json() == []
    # Records of the tracked model for a simulator, from REST.
    rec = client.get("/buses/bus-7/tracked", params={"format": "andes"})
    assert rec.status_code == 200 and rec.json()["bus"] == "bus-7"
    assert json.loads(rec.json()["content"])["Motor3"][0]["c1"] == pytest.approx(model.dynamic["Tm"])


def test_the_tracker_resumes_after_a_restart(tmp_path):
    seq = _sequence(n_before=10, n_after=2)
    path = tmp_path / "aslm.sqlite"
    storage = Storage(path)
    TrackingSink(storage, TrackerConfig(pool_windows=8)).write_results(seq[:11], [""] * 11)  # step window held out
    storage.close()
    storage = Storage(path)
    sink = TrackingSink(storage, TrackerConfig(pool_windows=8))
    assert sink.trackers["bus-7"].suspect is not None
    sink.write_results(seq[11:], [""])
    assert len(storage.changes("bus-7")) == 1  # confirmed across the restart
    storage.close()


def test_failed_and_skipped_results_leave_the_tracked_model_alone(tmp_path):
    storage = Storage(tmp_path / "a.sqlite")
    sink = TrackingSink(storage, TrackerConfig())
    sink.write_results([_ok("b1", 0.0, D)], [""])
    before = storage.tracked("b1")
    sink.write_results([BusResult(bus="b1", period=900.0, period_s=900.0, status="failed", reason="timeout",
                                  completed_at=901.0)], [""])
    assert storage.tracked("b1") == before
    storage.close()


def test_records_sink_writes_the_tracked_model_when_there_is_one(tmp_path):
    storage = Storage(tmp_path / "r.sqlite")
    track = TrackingSink(storage, TrackerConfig())
    puts = []
    records = RecordsSink(lambda k, p: puts.append((k, json.loads(p))), "aslm", Assumptions(f0=50.0),
                          formats=("andes",), tracked=storage.tracked)
    seq = [_ok("b1", 900.0 * i, D * (1.0 + 0.01 * (-1) ** i)) for i in range(4)]  # windows ±1 % around D
    track.write_results(seq, [""] * 4)
    records.write_results(seq[-1:], [""])
    payload = dict(puts)["aslm/records/andes/b1"]
    assert payload["model"] == "tracked"
    tm = json.loads(payload["content"])["Motor3"][0]["c1"]
    assert tm == pytest.approx(json.loads(storage.tracked("b1"))["dynamic"]["Tm"]) and tm != seq[-1].parameters.dynamic["Tm"]
    plain = RecordsSink(lambda k, p: puts.append((k, json.loads(p))), "aslm", Assumptions(f0=50.0), formats=("andes",))
    plain.write_results(seq[-1:], [""])
    assert puts[-1][1]["model"] == "window"
    assert SINKS["tracking"] == "service.sinks.tracking:build"
    storage.close()
