"""REST handlers on a ServiceView that is not a Service: no Zenoh, no workers, no HTTP server.

Results reach the view through the same sink chain as in the service (storage, latest, metrics), so
these tests also check that REST answers with what the sinks wrote.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass

import pytest
from service_helpers import settings_for

from service.api import RunStatus, create_app
from service.audit import AuditLog, token_identity
from service.buffers import BufferStore
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import BusResult, PeriodSummary
from service.settings import ServiceSettings, check_period
from service.sinks.base import SinkChain
from service.sinks.storage import StorageSink
from service.sources.base import Inlet
from service.storage import Storage
from service.testing import MemorySource

with warnings.catch_warnings():  # Starlette warns at import that its TestClient will change HTTP client
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient


@dataclass
class View:
    """The smallest ServiceView: the parts REST reads, a period it can change."""

    settings: ServiceSettings
    store: BufferStore
    storage: Storage
    latest: LatestResults
    metrics: ServiceMetrics
    period_s: float
    audit: AuditLog | None = None  # None: one in the storage's SQLite file, as the service has

    def __post_init__(self) -> None:
        if self.audit is None:
            self.audit = AuditLog(self.settings.storage_path)

    def status(self) -> RunStatus:
        return RunStatus(next_period=1020.0, running_period=None, workers_replaced=2)

    def set_period(self, period_s: float) -> None:
        check_period(period_s, self.settings)
        self.period_s = period_s


def _result(bus: str, period: float, status: str = "ok") -> BusResult:
    params = None if status != "ok" else {
        "dynamic": {"a": 40.0, "b": 10.0, "H2": 1.0, "Tm": 0.3}, "static": {"Pz": 0.0}, "objective": 0.1,
        "fit": {"fd_p": 0.9, "fd_q": 0.8}, "elapsed_s": 0.002}
    return BusResult(bus=bus, period=period, period_s=10.0, status=status, reason=None if status == "ok" else "gap",
                     completed_at=period + 0.5, parameters=params)


@pytest.fixture
def rest(tmp_path):
    settings = settings_for(tmp_path, 7447, period_s=10.0, window_s=2.0, late_s=0.5)
    store = BufferStore(settings.window_s, settings.frame_rate, settings.late_s)
    storage = Storage(settings.storage_path)
    view = View(settings, store, storage, LatestResults(), ServiceMetrics(store), settings.period_s,
                AuditLog(settings.storage_path))
    chain = SinkChain([StorageSink(storage, 1e9), view.latest, view.metrics], on_error=pytest.fail)
    with TestClient(create_app(view)) as client:
        yield view, chain, client
    storage.close()


def test_latest_history_and_periods_are_what_the_sinks_wrote(rest):
    view, chain, client = rest
    assert client.get("/buses/b1/parameters/latest").status_code == 404
    chain.write_results([_result("b1", 1000.0), _result("b2", 1000.0)])
    chain.write_results([_result("b1", 1010.0, "skipped")])
    chain.write_period(PeriodSummary(period=1010.0, period_s=10.0, n_ok=0, n_failed=0, n_skipped=1,
                                     latency_s=0.25, completed_at=1010.75))
    latest = client.get("/buses/b1/parameters/latest")
    assert latest.text == view.latest.results_json["b1"] and latest.json()["status"] == "skipped"
    assert client.get("/buses/b1/parameters/latest", params={"ok": True}).json()["period"] == 1000.0
    history = client.get("/buses/b1/parameters", params={"since": 1000.0, "limit": 10}).json()
    assert [(r["period"], r["status"]) for r in history] == [(1010.0, "skipped"), (1000.0, "ok")]
    assert [p["period"] for p in client.get("/periods").json()] == [1010.0]
    metrics = client.get("/metrics").text
    assert 'aslm_windows_total{status="ok"} 2.0' in metrics and "aslm_last_period_timestamp_seconds 1010.0" in metrics


def test_buses_and_health_read_the_ingest_and_the_run_status(rest):
    view, chain, client = rest
    source = MemorySource()
    source.start(Inlet(view.store, max_future_s=5.0, f0=50.0))
    source.push_message("b3", b"{}", "application/json")
    chain.write_results([_result("b1", 1000.0)])
    buses = {b["bus"]: b for b in client.get("/buses").json()}
    assert sorted(buses) == ["b1", "b3"]
    assert buses["b1"]["last_status"] == "ok" and buses["b1"]["frames_buffered"] == 0
    assert buses["b3"]["last_status"] is None and sum(buses["b3"]["messages_dropped"].values()) == 1
    health = client.get("/health").json()
    assert (health["next_period"], health["running_period"], health["workers_replaced"]) == (1020.0, None, 2)
    assert (health["buses"], health["period_s"], health["instance"]) == (1, 10.0, "test-7447")


def test_diagnosis_latest_is_the_payload_the_sinks_kept(rest):
    view, chain, client = rest
    missing = client.get("/buses/b1/diagnosis/latest")
    assert missing.status_code == 404 and "every 4 periods" in missing.json()["detail"]
    payload = '{"bus": "b1", "period": 1000.0, "verdict": "consistent"}'
    chain.write_diagnosis("b1", 1000.0, payload)
    assert client.get("/buses/b1/diagnosis/latest").text == payload
    assert view.storage.latest_diagnoses() == {"b1": payload}
    assert 'aslm_diagnoses_total{verdict="consistent"} 1.0' in client.get("/metrics").text


def test_put_config_changes_the_period_through_the_view(rest):
    view, _, client = rest
    assert client.put("/config", json={"period_s": 20.0}).status_code == 401
    bad = client.put("/config", json={"period_s": 1.0}, headers={"Authorization": "Bearer op-secret"})
    assert bad.status_code == 422 and "window_s + late_s" in bad.json()["detail"]
    ok = client.put("/config", json={"period_s": 20.0}, headers={"X-Operator-Token": "op-secret"})
    assert ok.status_code == 200 and ok.json()["period_s"] == 20.0 and view.period_s == 20.0
    assert client.get("/config").json()["settings"]["operator_token"] == "***"


@pytest.mark.parametrize("body", [
    '{"period_s": 1e999}', '{"period_s": 1e12}', '{"period_s": NaN}', '{"period_s": Infinity}',
    '{"period_s": -Infinity}', '{"window_s": 3}', '{"period_s": 20, "window_s": 3}',
])
def test_put_config_refuses_non_finite_huge_and_unknown_values_with_422(rest, body):
    view, _, client = rest
    r = client.put("/config", content=body, headers={"Authorization": "Bearer op-secret",
                                                    "Content-Type": "application/json"})
    assert r.status_code == 422, (body, r.status_code, r.text)
    assert view.period_s == 10.0  # nothing changed


def test_config_shows_the_startup_period_next_to_the_one_in_force(rest):
    view, _, client = rest
    before = client.get("/config").json()
    assert (before["period_s"], before["startup_period_s"], before["period_source"]) == (10.0, 10.0, "settings")
    client.put("/config", json={"period_s": 30.0}, headers={"X-Operator-Token": "op-secret"})
    after = client.get("/config").json()
    assert (after["period_s"], after["startup_period_s"], after["period_source"]) == (30.0, 10.0, "run-time")


def test_config_changes_are_audited_with_who_when_old_and_new(rest, tmp_path):
    view, _, client = rest
    assert client.get("/config/audit").json() == []
    # Refused changes (no token, wrong token, invalid value) leave no entry and change nothing.
    client.put("/config", json={"period_s": 20.0})
    client.put("/config", json={"period_s": 20.0}, headers={"X-Operator-Token": "wrong"})
    client.put("/config", json={"period_s": 1.0}, headers={"X-Operator-Token": "op-secret"})
    assert client.get("/config/audit").json() == []
    client.put("/config", json={"period_s": 20.0}, headers={"Authorization": "Bearer op-secret"})
    client.put("/config", json={"period_s": 40.0}, headers={"X-Operator-Token": "op-secret"})
    entries = client.get("/config/audit").json()
    assert [(e["field"], e["old"], e["new"]) for e in entries] == [("period_s", 20.0, 40.0),
                                                                     ("period_s", 10.0, 20.0)]
    newest = entries[0]
    assert newest["token"] == token_identity("op-secret") and "op-secret" not in str(entries)
    assert newest["address"].startswith("testclient:")  # the TestClient's peer; a real client's IP:port
    assert newest["at_utc"].endswith("Z") and newest["at"] > 1.7e9
    assert client.get("/config/audit", params={"limit": 1}).json() == entries[:1]
    # Stored in the service's SQLite file: a restarted service shows the same log.
    view.audit.close()
    view.audit = AuditLog(view.settings.storage_path)
    assert client.get("/config/audit").json() == entries


def test_docs_page_loads_swagger_ui_from_the_service_itself(rest):
    _, _, client = rest
    page = client.get("/docs")
    assert page.status_code == 200 and "SwaggerUIBundle" in page.text
    # Every script, stylesheet and icon is a path on this server: nothing from a CDN, so it works offline.
    refs = re.findall(r'(?:src|href)="([^"]+)"', page.text)
    assert refs and all(r.startswith("/docs/assets/") for r in refs), refs
    assert "http://" not in page.text and "https://" not in page.text
    for ref in refs:
        asset = client.get(ref)
        assert asset.status_code == 200 and len(asset.content) > 500, ref
    spec = client.get("/openapi.json").json()
    assert spec["paths"]["/config/audit"]
    # Swagger UI 4 shows "Unable to render this definition" for OpenAPI 3.1: the shipped one must be 5+.
    from swagger_ui_bundle import swagger_ui_path

    major = int(re.search(r"swagger-ui-(\d+)\.", str(swagger_ui_path)).group(1))
    assert spec["openapi"].startswith("3.1") and major >= 5
    assert client.get("/redoc").status_code == 404  # ReDoc would need a CDN: off rather than blank


def test_docs_without_swagger_ui_files_still_serves_rest(monkeypatch):
    import swagger_ui_bundle
    from fastapi import FastAPI

    from service.docs_assets import mount_docs

    monkeypatch.setattr(swagger_ui_bundle, "swagger_ui_path", "/nonexistent/swagger-ui")
    app = FastAPI(docs_url=None, redoc_url=None)
    mount_docs(app)
    with TestClient(app) as client:
        page = client.get("/docs")
    assert page.status_code == 200 and 'href="/openapi.json"' in page.text
