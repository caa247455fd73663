"""The dashboard's server side on a ServiceView that is not a Service: static pages, the fleet table's
filter/sort/paging, the diagnosis timeline, the model playback and the per-bus Prometheus gauges."""

from __future__ import annotations

import re
import shutil
import subprocess
import time
import warnings
from concurrent.futures import Future
from pathlib import Path

import numpy as np
import pytest
from conftest import D_TRUE, ZIP_P, ZIP_Q, equation_window
from prometheus_client.parser import text_string_to_metric_families
from service_helpers import settings_for
from test_service_api import View

from service.api import create_app
from service.buffers import BufferStore
from service.context import Context
from service.dashboard import UI_DIR
from service.executors.base import TaskOutcome
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import BusResult
from service.sinks.base import SinkChain
from service.sinks.bus_metrics import FAMILIES, VERDICT_CODES, BusMetricsSink
from service.sinks.storage import StorageSink
from service.sources.base import Inlet
from service.storage import Storage
from service.testing import InlineExecutor, MemorySource

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient


def result(bus: str, period: float, status: str = "ok", a: float = 40.0, completed_at: float | None = None,
           stderr: float | None = 2.0) -> BusResult:
    """A result recorded ``completed_at`` (default: now), D = [a, 10, 1, 0.3] when ok."""
    params = None if status != "ok" else {
        "dynamic": {"a": a, "b": 10.0, "H2": 1.0, "Tm": 0.3}, "static": {"Pz": 0.1, "Pi": 0.2, "Pp": 0.5},
        "objective": 0.1, "fit": {"fd_p": 0.9, "fd_q": 0.8}, "flags": ["at_bound:H2"] if a > 60 else [],
        "stderr": {k: stderr for k in ("a", "b", "H2", "Tm")}, "elapsed_s": 0.002,
        "static_local": {"V0": 1.0, "P0": 0.8, "P0_se": 0.01, "kpv": 0.75, "kpv_se": 0.05}}
    return BusResult(bus=bus, period=period, period_s=10.0, status=status,
                     reason=None if status == "ok" else "coverage",
                     completed_at=time.time() if completed_at is None else completed_at, parameters=params)


def report(bus: str, period: float, verdict: str, cause: str | None = None) -> str:
    """The JSON of a diagnosis report with the fields the timeline reads."""
    import json

    return json.dumps({"bus": bus, "period": period, "verdict": verdict, "cause": cause,
                       "located": {"channels": ["P"] if verdict != "consistent" else []},
                       "fit_before": {"fd_p": 0.8, "fd_q": 0.9, "rms_p": 0.01, "rms_q": 0.01},
                       "fit_after": {"fd_p": 0.95, "fd_q": 0.9, "rms_p": 0.005, "rms_q": 0.01},
                       "message": f"{bus} is {verdict}"})


@pytest.fixture
def dash(tmp_path):
    settings = settings_for(tmp_path, 7447, period_s=20.0, window_s=10.0, late_s=0.5)
    store = BufferStore(settings.window_s, settings.frame_rate, settings.late_s)
    storage = Storage(settings.storage_path)
    view = View(settings, store, storage, LatestResults(), ServiceMetrics(store), settings.period_s)
    view.executor = InlineExecutor(settings.identify_fn)
    gauges = BusMetricsSink(Context(settings, storage, view.latest, view.metrics))
    chain = SinkChain([StorageSink(storage, 1e9), view.latest, view.metrics, gauges], on_error=pytest.fail)
    source = MemorySource()
    source.start(Inlet(store, max_future_s=5.0, f0=50.0))
    with TestClient(create_app(view)) as client:
        yield view, chain, client, source
    storage.close()


def test_root_redirects_to_the_pages_and_every_asset_they_name_is_served(dash):
    _, _, client, _ = dash
    root = client.get("/", follow_redirects=False)
    assert root.status_code == 307 and root.headers["location"] == "/ui/"
    page = client.get("/ui/")
    assert page.status_code == 200 and "<title>ASLM dashboard</title>" in page.text
    assets = [a for a in re.findall(r'(?:src|href)="([^"#]+)"', page.text) if not a.startswith("data:")]
    assert {"app.js", "app.css", "vendor/uPlot.iife.min.js", "vendor/uPlot.min.css"} <= set(assets)
    for asset in assets:  # all local: nothing fetched from the internet
        got = client.get(f"/ui/{asset}")
        assert got.status_code == 200 and len(got.content) > 500, asset
    assert "MIT" in (UI_DIR / "vendor" / "uPlot.LICENSE").read_text()
    assert "v1.6.32" in client.get("/ui/vendor/uPlot.iife.min.js").text[:100]


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_the_page_script_parses():
    # The browser test (slow) runs it; this catches a syntax error in a second.
    check = subprocess.run(["node", "--check", str(UI_DIR / "app.js")], capture_output=True, text=True)
    assert check.returncode == 0, check.stderr


def test_fleet_rows_carry_the_last_known_values_state_and_verdict(dash):
    view, chain, client, source = dash
    now = time.time()
    chain.write_results([result("b1", 1000.0), result("b2", 1000.0, a=70.0), result("b3", 1000.0)])
    chain.write_results([result("b1", 1010.0, "skipped"), result("b3", 1010.0, "failed")])
    chain.write_results([result("old", 900.0, completed_at=now - 3 * view.period_s)])
    chain.write_diagnosis("b2", 1000.0, report("b2", 1000.0, "explained", "second_motor"))
    chain.write_diagnosis("b3", 1000.0, report("b3", 1000.0, "unexplained"))
    source.push_window("new", [now - 1.0], [1.0], [0.0], [0.5], [0.2])  # known to the ingest, no result
    page = client.get("/fleet").json()
    rows = {r["bus"]: r for r in page["rows"]}
    assert (page["total"], page["matched"], list(rows)) == (5, 5, ["b1", "b2", "b3", "new", "old"])
    assert {b: r["state"] for b, r in rows.items()} == {
        "b1": "skipped", "b2": "ok", "b3": "failed", "new": "pending", "old": "stale"}
    # A skipped bus keeps showing its last successful values, with the period they come from.
    assert rows["b1"]["dynamic"]["a"] == 40.0 and rows["b1"]["ok_period"] == 1000.0 and rows["b1"]["period"] == 1010.0
    assert rows["b1"]["stderr"]["a"] == 2.0 and rows["b1"]["fit"] == {"fd_p": 0.9, "fd_q": 0.8}
    assert rows["b2"]["flags"] == ["at_bound:H2"] and rows["b2"]["static"]["Pp"] == 0.5
    # What ambient data identify of the static part travels with the row (the dashboard shows it, not the split).
    assert rows["b2"]["static_local"]["P0"] == 0.8 and rows["b2"]["static_local"]["kpv_se"] == 0.05
    assert rows["new"]["static_local"] is None
    assert (rows["b2"]["verdict"], rows["b2"]["cause"]) == ("explained", "second_motor")
    assert rows["new"]["dynamic"] is None and rows["new"]["age_s"] is None
    assert rows["old"]["age_s"] == pytest.approx(3 * view.period_s, abs=5.0)
    assert page["counts"] == {"state": {"ok": 1, "stale": 1, "failed": 1, "skipped": 1, "pending": 1},
                              "verdict": {"explained": 1, "ambiguous": 0, "unexplained": 1, "consistent": 0,
                                          "failed": 0}}


def test_fleet_filters_sorts_and_pages_on_the_server(dash):
    _, chain, client, _ = dash
    chain.write_results([result(f"bus{i:03d}", 1000.0, a=30.0 + (i * 37) % 100) for i in range(250)])
    chain.write_results([result("bus007", 1010.0, "failed")])
    chain.write_diagnosis("bus012", 1000.0, report("bus012", 1000.0, "unexplained"))

    def get(**params):
        return client.get("/fleet", params=params).json()

    first = get(limit=100)
    assert [r["bus"] for r in first["rows"]] == [f"bus{i:03d}" for i in range(100)]
    last = get(offset=200, limit=100)
    assert (last["matched"], len(last["rows"]), last["rows"][-1]["bus"]) == (250, 50, "bus249")
    by_a = get(sort="a", desc=True, limit=250)["rows"]
    assert [r["dynamic"]["a"] for r in by_a] == sorted((r["dynamic"]["a"] for r in by_a), reverse=True)
    by_a_up = get(sort="a", limit=3)["rows"]
    assert by_a_up[0]["dynamic"]["a"] == 30.0 and by_a_up[1]["dynamic"]["a"] <= by_a_up[2]["dynamic"]["a"]
    assert [r["bus"] for r in get(q="BUS01", limit=5)["rows"]] == [f"bus{i:03d}" for i in range(10, 15)]
    assert [r["bus"] for r in get(state="failed")["rows"]] == ["bus007"]
    assert [r["bus"] for r in get(verdict="unexplained")["rows"]] == ["bus012"]
    assert get(state=["failed", "ok"], q="bus00")["matched"] == 10
    # Missing values sort last in both directions (a bus with no verdict after those with one).
    assert get(sort="verdict", desc=True, limit=1)["rows"][0]["bus"] == "bus012"
    assert get(sort="verdict", limit=1)["rows"][0]["bus"] == "bus012"
    assert client.get("/fleet", params={"sort": "nope"}).status_code == 422
    assert client.get("/fleet", params={"limit": 5000}).status_code == 422


def test_diagnosis_timeline_is_newest_first_with_named_causes(dash):
    _, chain, client, _ = dash
    chain.write_diagnosis("b1", 1000.0, report("b1", 1000.0, "consistent"))
    chain.write_diagnosis("b1", 1040.0, report("b1", 1040.0, "explained", "frequency_dependence"))
    chain.write_diagnosis("b1", 1080.0, '{"bus": "b1", "period": 1080.0, "verdict": "failed", '
                                        '"reason": "timeout", "message": "took too long"}')
    chain.write_diagnosis("b2", 1000.0, report("b2", 1000.0, "unexplained"))
    timeline = client.get("/buses/b1/diagnoses").json()
    assert [(e["period"], e["verdict"], e["cause"]) for e in timeline] == [
        (1080.0, "failed", None), (1040.0, "explained", "frequency_dependence"), (1000.0, "consistent", None)]
    assert timeline[1]["channels"] == ["P"] and timeline[1]["fit_after"]["fd_p"] == 0.95
    assert timeline[0]["message"] == "took too long" and timeline[0]["fit_before"] is None
    assert [e["period"] for e in client.get("/buses/b1/diagnoses", params={"since": 1040.0, "limit": 1}).json()] == [1080.0]
    assert client.get("/buses/none/diagnoses").json() == []


def test_playback_replays_the_true_model_on_the_newest_frames(dash):
    view, chain, client, source = dash
    assert client.get("/buses/eq/playback").status_code == 404  # no result yet
    w = equation_window(fs=50.0, seed=3)
    shift = time.time() - 1.0 - w.t[-1]
    source.push_window("eq", w.t + shift, w.V, w.theta, w.P, w.Q)

    def model(period: float, d) -> BusResult:
        res = result("eq", period)
        res.parameters.dynamic = dict(zip(("a", "b", "H2", "Tm"), map(float, d), strict=True))
        res.parameters.static = dict(zip(("Pz", "Pi", "Pp", "Qz", "Qi", "Qp"), (*ZIP_P, *ZIP_Q), strict=True))
        return res

    chain.write_results([model(1000.0, D_TRUE)])
    pb = client.get("/buses/eq/playback").json()
    assert pb["model_period"] == 1000.0 and pb["n"] == len(w.t) - 1  # the window (end − 10 s, end]
    assert len(pb["t"]) == len(pb["P"]) == len(pb["P_model"]) == len(pb["Q_model"]) <= 600
    assert pb["t"][-1] == pytest.approx(w.t[-1] + shift)
    # The data were made by this model: it reproduces them (fit degree near 1) ...
    assert pb["fd_p"] > 0.98 and pb["fd_q"] > 0.98
    # ... and a wrong one (b a third of the truth) does not; one with no motor equilibrium cannot be played.
    chain.write_results([model(1010.0, [40.0, 5.0, 1.3, 1.2])])
    wrong = client.get("/buses/eq/playback").json()
    assert wrong["model_period"] == 1010.0 and wrong["fd_q"] < 0.5
    chain.write_results([model(1020.0, [20.0, 15.0, 1.3, 1.2])])
    none = client.get("/buses/eq/playback")
    assert none.status_code == 422 and "NoEquilibriumError" in none.json()["detail"]


def test_bus_gauges_are_the_latest_values_with_escaped_names(dash):
    view, chain, client, _ = dash
    chain.write_results([result("b1", 1000.0, a=41.5), result('we"ird\\bus', 1000.0, stderr=None)])
    chain.write_results([result("b1", 1010.0, "failed")])
    chain.write_diagnosis("b1", 1000.0, report("b1", 1000.0, "unexplained"))
    families = {f.name: f for f in text_string_to_metric_families(client.get("/metrics").text)}
    samples = {(f.name, tuple(sorted(s.labels.items()))): s.value
               for f in families.values() for s in f.samples}
    assert samples[("aslm_parameter", (("bus", "b1"), ("name", "a")))] == 41.5  # the last ok result
    assert samples[("aslm_parameter_stderr", (("bus", "b1"), ("name", "Tm")))] == 2.0
    assert samples[("aslm_fit_degree", (("bus", "b1"), ("channel", "q")))] == 0.8
    assert samples[("aslm_bus_status", (("bus", "b1"),))] == 2  # failed
    assert samples[("aslm_bus_result_period_timestamp_seconds", (("bus", "b1"),))] == 1000.0
    assert samples[("aslm_diagnosis_verdict", (("bus", "b1"),))] == VERDICT_CODES["unexplained"]
    assert samples[("aslm_parameter", (("bus", 'we"ird\\bus'), ("name", "H2")))] == 1.0
    assert not [k for k in samples if k[0] == "aslm_parameter_stderr" and k[1][0][1] != "b1"]
    # 13 series for a bus with everything (4 + 4 + 2 + verdict + period + status).
    per_bus = [k for k in samples if k[0] in FAMILIES and ("bus", "b1") in k[1]]
    assert len(per_bus) == 13
    # Closing the sink takes the gauges out of /metrics, and the service's own metrics stay.
    chain.close()
    text = client.get("/metrics").text
    assert "aslm_parameter{" not in text and "aslm_windows_total" in text


def test_bus_gauges_start_from_the_restored_latest_results(tmp_path):
    latest = LatestResults({"b1": result("b1", 1010.0, "skipped")}, {"b1": report("b1", 1000.0, "explained")},
                           last_ok={"b1": result("b1", 1000.0, a=55.0)})
    settings = settings_for(tmp_path, 7447)
    metrics = ServiceMetrics(BufferStore(10.0, 50.0, 2.0))
    BusMetricsSink(Context(settings, Storage(":memory:"), latest, metrics))
    text = metrics.render().decode()
    assert 'aslm_parameter{bus="b1",name="a"} 55.0' in text and 'aslm_bus_status{bus="b1"} 1' in text
    assert 'aslm_diagnosis_verdict{bus="b1"} 1' in text


def test_latest_results_restores_last_ok_and_verdicts_from_storage(tmp_path):
    storage = Storage(Path(tmp_path) / "s.sqlite")
    storage.save_results([result("b1", 1000.0, a=44.0), result("b1", 1010.0, "failed")])
    storage.save_diagnosis("b1", 1000.0, report("b1", 1000.0, "explained", "second_motor"))
    latest = LatestResults.from_storage(storage)
    assert latest.results["b1"].status == "failed" and latest.last_ok["b1"].parameters.dynamic["a"] == 44.0
    assert latest.verdicts["b1"] == ("explained", "second_motor", 1000.0)
    storage.close()


def test_playbacks_in_flight_are_bounded_until_the_workers_answer(dash, monkeypatch):
    import service.dashboard as dashboard

    view, chain, client, source = dash
    monkeypatch.setattr(dashboard, "PLAYBACK_TIMEOUT_S", 0.05)
    pending: list[Future] = []

    class Stalled:  # a pool busy with a period: nothing comes back until told
        def submit(self, task):
            pending.append(Future())
            return pending[-1]

    view.executor = Stalled()
    now = time.time()
    source.push_window("b1", now - 2.0 + np.arange(100) / 50.0, np.ones(100), np.zeros(100),
                       np.full(100, 0.5), np.full(100, 0.2))
    chain.write_results([result("b1", 1000.0)])
    busy = [client.get("/buses/b1/playback") for _ in range(dashboard.PLAYBACK_IN_FLIGHT)]
    assert all(r.status_code == 503 and "busy" in r.json()["detail"] for r in busy)
    full = client.get("/buses/b1/playback")
    assert full.status_code == 503 and "too many" in full.json()["detail"]
    assert len(pending) == dashboard.PLAYBACK_IN_FLIGHT  # the abandoned ones still hold their slots
    for fut in pending:  # the workers answer (late): the slots are free again
        fut.set_result(TaskOutcome(ok=False, reason="window:gaps", message="late"))
    again = client.get("/buses/b1/playback")
    assert again.status_code == 503 and "busy" in again.json()["detail"] and len(pending) == 5
