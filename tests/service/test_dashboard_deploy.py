"""Prometheus and Grafana provisioning (deploy/, the compose 'monitoring' profile) checked against the
metrics the service exports: every metric and label a query names is one /metrics has."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest
from prometheus_client.parser import text_string_to_metric_families
from test_dashboard_api import report, result

from service.buffers import BufferStore
from service.context import Context
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import PeriodSummary
from service.settings import load_settings
from service.sinks.base import SinkChain
from service.sinks.bus_metrics import STATUS_CODES, VERDICT_CODES, BusMetricsSink
from service.sources.base import Inlet
from service.storage import Storage
from service.testing import MemorySource

yaml = pytest.importorskip("yaml")
ROOT = Path(__file__).resolve().parents[2]
GRAFANA = ROOT / "deploy" / "grafana"
DASHBOARD = json.loads((GRAFANA / "dashboards" / "aslm.json").read_text())
SERVICES = yaml.safe_load((ROOT / "docker-compose.yml").read_text())["services"]
# PromQL words that look like metric names but are functions, keywords or the dashboard's variables.
_PROMQL = {"sum", "by", "rate", "count", "or", "vector", "time", "scalar", "histogram_quantile", "le",
           "label_values", "bus", "name", "channel", "status", "reason", "on", "group_left"}
_SELECTOR = re.compile(r"(aslm_[a-z0-9_]+)(?:\{([^}]*)\})?")


def exported() -> dict[str, set[str]]:
    """Sample name → label names, from the /metrics of a service with the bus_metrics sink and some of
    everything (a dropped frame, ok, failed and skipped results, a diagnosis, a period)."""
    store = BufferStore(10.0, 50.0, 2.0)
    source = MemorySource()
    source.start(Inlet(store, max_future_s=5.0, f0=50.0))
    source.push_window("b1", [time.time()], [float("nan")], [0.0], [0.5], [0.2])
    latest, metrics = LatestResults(), ServiceMetrics(store)
    ctx = Context(load_settings(storage_url=":memory:"), Storage(":memory:"), latest, metrics)
    chain = SinkChain([latest, metrics, BusMetricsSink(ctx)], on_error=pytest.fail)
    chain.write_results([result("b1", 1000.0), result("b2", 1000.0, "failed"), result("b3", 1000.0, "skipped")])
    chain.write_diagnosis("b1", 1000.0, report("b1", 1000.0, "explained", "second_motor"))
    chain.write_period(PeriodSummary(period=1000.0, period_s=20.0, n_ok=1, n_failed=1, n_skipped=1,
                                     latency_s=0.5, completed_at=1001.0))
    metrics.period_s.set(20.0)
    out: dict[str, set[str]] = {}
    for fam in text_string_to_metric_families(metrics.render().decode()):
        for s in fam.samples:
            out.setdefault(s.name, set()).update(s.labels)
    return out


def queries() -> list[str]:
    """Every PromQL expression of the dashboard: panel targets and template variable queries."""
    exprs = [t["expr"] for p in DASHBOARD["panels"] for t in p.get("targets", [])]
    exprs += [v["query"]["query"] for v in DASHBOARD["templating"]["list"] if v["type"] == "query"]
    return exprs


def test_every_metric_and_label_the_dashboard_queries_is_exported():
    names = exported()
    used = set()
    for expr in queries():
        for metric, matchers in _SELECTOR.findall(expr):
            assert metric in names, f"{metric} (in {expr!r}) is not exported; exported: {sorted(names)}"
            used.add(metric)
            for label in re.findall(r"([a-z_]+)\s*=~?", matchers):
                assert label in names[metric], f"{metric} has no label {label!r} (in {expr!r})"
        for word in re.findall(r"\b([a-z_]+)\s*\(", expr):  # PromQL functions only, no stray names
            assert word in _PROMQL, (word, expr)
        for label in re.findall(r"by \(([a-z_, ]+)\)", expr):
            metric = _SELECTOR.search(expr).group(1)
            assert {x.strip() for x in label.split(",")} <= names[metric] | {"le"}, expr
    # The per-bus gauges and the service's health are both drawn.
    assert {"aslm_parameter", "aslm_parameter_stderr", "aslm_fit_degree", "aslm_diagnosis_verdict",
            "aslm_bus_status", "aslm_bus_result_period_timestamp_seconds", "aslm_buses",
            "aslm_windows_total", "aslm_period_latency_seconds_bucket"} <= used


def test_dashboard_variable_panels_and_value_mappings():
    var = {v["name"]: v for v in DASHBOARD["templating"]["list"]}
    assert var["bus"]["query"]["query"] == "label_values(aslm_parameter, bus)"
    ids = [p["id"] for p in DASHBOARD["panels"]]
    assert len(ids) == len(set(ids)) and DASHBOARD["uid"] and DASHBOARD["schemaVersion"] >= 36
    # The verdict and status timelines name the codes the gauges use.
    maps = {p["title"]: p["fieldConfig"]["defaults"]["mappings"][0]["options"]
            for p in DASHBOARD["panels"] if p["type"] == "state-timeline"}
    assert {int(k): v["text"] for k, v in maps["Diagnosis verdict"].items()} == {c: n for n, c in VERDICT_CODES.items()}
    assert {int(k): v["text"] for k, v in maps["Latest result status"].items()} == {c: n for n, c in STATUS_CODES.items()}
    # The ±2 SE band fills between the series the panel draws under those names.
    for p in DASHBOARD["panels"]:
        for o in p.get("fieldConfig", {}).get("overrides", []):
            for prop in o["properties"]:
                if prop["id"] == "custom.fillBelowTo":
                    assert prop["value"] in {t["legendFormat"] for t in p["targets"]}, p["title"]


def test_provisioning_points_at_the_compose_services_and_mounts():
    ds = yaml.safe_load((GRAFANA / "provisioning/datasources/prometheus.yml").read_text())["datasources"]
    assert len(ds) == 1 and ds[0]["type"] == "prometheus"
    uids = {t["datasource"]["uid"] for p in DASHBOARD["panels"] for t in p.get("targets", [])}
    assert uids == {ds[0]["uid"]} and DASHBOARD["templating"]["list"][0]["datasource"]["uid"] == ds[0]["uid"]
    prom, grafana, aslm = SERVICES["prometheus"], SERVICES["grafana"], SERVICES["aslm"]
    assert prom["profiles"] == grafana["profiles"] == ["monitoring"]
    prom_port = prom["ports"][0].rsplit(":", 2)[-1]
    assert ds[0]["url"] == f"http://prometheus:{prom_port}"
    mounts = {}
    for svc in (prom, grafana):
        for vol in svc["volumes"]:
            src, dst = vol.split(":")[:2]
            if src.startswith("./"):
                assert (ROOT / src).exists(), src
                mounts[dst] = ROOT / src
    # Grafana reads the dashboards folder its provider names, which is where the JSON is mounted.
    provider = yaml.safe_load((GRAFANA / "provisioning/dashboards/aslm.yml").read_text())["providers"][0]
    assert (mounts[provider["options"]["path"]] / "aslm.json").is_file()
    assert grafana["environment"]["GF_DASHBOARDS_DEFAULT_HOME_DASHBOARD_PATH"].startswith(provider["options"]["path"])
    # Prometheus scrapes the aslm service on its REST port, and the service exports the per-bus gauges.
    conf = yaml.safe_load(mounts[prom["command"][0].split("=", 1)[1]].read_text())
    job = conf["scrape_configs"][0]
    assert job["metrics_path"] == "/metrics"
    assert job["static_configs"][0]["targets"] == [f"aslm:{aslm['environment']['ASLM_HTTP_PORT']}"]
    sinks = re.fullmatch(r"\$\{ASLM_SINKS:-(.*)\}", aslm["environment"]["ASLM_SINKS"]).group(1)
    assert "bus_metrics" in load_settings(sinks=json.loads(sinks), storage_url=":memory:").sinks
    # Host ports of the monitoring tools are bound to loopback only.
    assert all(p.startswith("127.0.0.1:") for p in prom["ports"] + grafana["ports"])
