"""The running service on loopback (real Zenoh, uvicorn, SQLite, spawned workers) with stand-in numerics:
period changes over REST, restarts, a worker killed mid-task, bad input on the wire."""

from __future__ import annotations

import gc
import json
import os
import signal

import httpx
import pytest
import zenoh
from service_helpers import NoiseStreamer, client_session, free_port, periods, settings_for, wait_for

from service.app import Service

FAST = dict(window_s=2.0, late_s=0.5, frame_rate=50.0, identify_fn="service_helpers:fake_identify")
BUSES = ["b01", "b02", "b03"]


@pytest.fixture
def running(tmp_path):
    """Start a service + noise stream; yields a factory so tests can choose settings."""
    made = []

    def start(**overrides):
        zport = free_port()
        buses = overrides.pop("buses", BUSES)
        svc = Service(settings_for(tmp_path, zport, **{**FAST, **overrides})).start()
        sess = client_session(zport)
        stream = NoiseStreamer(sess, buses).start()
        made.append((svc, sess, stream))
        return svc, sess, stream

    yield start
    for svc, sess, stream in made:
        stream.stop()
        sess.close()
        svc.stop()


def test_put_config_requires_token_and_next_period_uses_new_T(running):
    svc, _, _ = running(period_s=4.0)
    url = svc.url
    assert httpx.put(f"{url}/config", json={"period_s": 3.0}).status_code == 401
    r = httpx.put(f"{url}/config", json={"period_s": 3.0}, headers={"Authorization": "Bearer wrong"})
    assert r.status_code == 401
    r = httpx.put(f"{url}/config", json={"period_s": 1.0}, headers={"Authorization": "Bearer op-secret"})
    assert r.status_code == 422 and "window_s + late_s" in r.json()["detail"]
    assert httpx.get(f"{url}/config").json()["period_s"] == 4.0
    r = httpx.put(f"{url}/config", json={"period_s": 3.0}, headers={"Authorization": "Bearer op-secret"})
    assert r.status_code == 200 and r.json()["period_s"] == 3.0
    assert r.json()["settings"]["operator_token"] == "***"
    done = wait_for(lambda: [p for p in periods(url) if p["period_s"] == 3.0 and p["n_ok"] == 3], 30)
    assert done[0]["period"] % 3.0 == 0  # aligned to the wall clock with the new T
    assert svc.storage.get_config() == {"period_s": 3.0}  # persisted
    assert "aslm_period_seconds 3.0" in httpx.get(f"{url}/metrics").text


def test_restart_keeps_history_and_warm_starts(tmp_path, running):
    svc, _, stream = running(period_s=3.0)
    first = wait_for(lambda: [p for p in periods(svc.url) if p["n_ok"] == 3], 30)[0]
    before = httpx.get(f"{svc.url}/buses/b01/parameters").json()
    assert before and before[0]["period"] >= first["period"]
    assert before[-1]["parameters"]["n_starts"] == 3  # cold: n_starts random starts
    stream.stop()
    svc.stop()

    svc2, _, _ = running(period_s=3.0)
    hist = httpx.get(f"{svc2.url}/buses/b01/parameters").json()
    assert [r["period"] for r in hist][-len(before):] == [r["period"] for r in before]  # history intact
    latest_before = before[0]["parameters"]["dynamic"]["a"]
    fresh = wait_for(lambda: [p for p in periods(svc2.url) if p["period"] > before[0]["period"] and p["n_ok"] == 3],
                     30)[-1]
    res = httpx.get(f"{svc2.url}/buses/b01/parameters", params={"since": fresh["period"], "until": fresh["period"]}
                    ).json()[0]
    assert res["warm_start"] is True and res["parameters"]["warm_start_given"] is True
    assert res["parameters"]["n_starts"] == 1  # warm start + n_starts_warm random starts
    # The stand-in adds 1 to the warm start's a: the first period after the restart continues the chain.
    first_after = [r for r in httpx.get(f"{svc2.url}/buses/b01/parameters").json() if r["period"] > before[0]["period"]][-1]
    assert first_after["parameters"]["dynamic"]["a"] == latest_before + 1


def test_worker_killed_mid_task_fails_that_bus_only(tmp_path, running, monkeypatch):
    marker = tmp_path / "marker"
    monkeypatch.setenv("ASLM_TEST_HANG_BUS", "b02")
    monkeypatch.setenv("ASLM_TEST_MARKER", str(marker))
    svc, _, _ = running(period_s=3.0, identify_fn="service_helpers:hang_once_identify", task_timeout_s=120)
    wait_for(marker.exists, 40, 0.05)
    os.kill(int(marker.read_text()), signal.SIGKILL)
    bad = wait_for(lambda: [p for p in periods(svc.url) if p["n_failed"] == 1], 30)[0]
    got = {b: httpx.get(f"{svc.url}/buses/{b}/parameters", params={"since": bad["period"], "until": bad["period"]}
                        ).json()[0] for b in BUSES}
    assert (got["b02"]["status"], got["b02"]["reason"]) == ("failed", "worker_crashed")
    assert got["b01"]["status"] == got["b03"]["status"] == "ok"
    wait_for(lambda: [p for p in periods(svc.url) if p["period"] > bad["period"] and p["n_ok"] == 3], 30)
    assert httpx.get(f"{svc.url}/buses/b02/parameters/latest").json()["status"] == "ok"
    health = httpx.get(f"{svc.url}/health").json()
    assert health["workers_replaced"] == 1
    assert 'aslm_windows_failed_total{reason="worker_crashed"} 1.0' in httpx.get(f"{svc.url}/metrics").text


def test_bad_input_on_the_wire_is_counted_and_others_unaffected(running):
    svc, sess, stream = running(period_s=3.0)
    key = "aslm/pmu/"
    sess.put(key + "junk", b"{not json", encoding=zenoh.Encoding.APPLICATION_JSON)
    sess.put(key + "junk", b"\x00\x01", encoding=zenoh.Encoding("application/x-aslm-pmu"))
    sess.put(key + "junk", b"hello", encoding=zenoh.Encoding.TEXT_PLAIN)
    sess.put(key + "junk", json.dumps({"t": [1.0, 2.0], "V": [1.0], "theta": [0], "P": [1], "Q": [0]}),
             encoding=zenoh.Encoding.APPLICATION_JSON)
    sess.put(key + "b01", json.dumps({"t": [1.0], "V": [float("nan")], "theta": [0], "P": [1], "Q": [0]}).replace(
        "NaN", "null"), encoding=zenoh.Encoding.APPLICATION_JSON)
    import time as _time

    now = _time.time()
    fresh = {"t": [now - 1.0 + k / 50 for k in range(10)], "V": [1.0] * 10, "theta": [0.0] * 10,
             "P": [0.5] * 10, "Q": [0.1] * 10}
    old = {**fresh, "t": [x - 30.0 for x in fresh["t"]]}
    swapped = {**fresh, "t": [x + 0.5 for x in fresh["t"]][::-1]}  # newer, reversed: reordered, kept
    for obj in (fresh, fresh, old, swapped):  # 2nd: duplicates; 3rd: late (30 s > late_s)
        sess.put(key + "dup", json.dumps(obj), encoding=zenoh.Encoding.APPLICATION_JSON)
    dup = wait_for(lambda: [b for b in httpx.get(f"{svc.url}/buses").json()
                            if b["bus"] == "dup" and b["frames_buffered"] == 20], 10)[0]
    assert dup["frames_dropped"] == {"duplicate": 10, "late": 10}
    info = wait_for(lambda: {b["bus"]: b for b in httpx.get(f"{svc.url}/buses").json()
                             if b["bus"] == "junk" and sum(b["messages_dropped"].values()) == 4}, 10)
    assert info["junk"]["messages_dropped"] == {"malformed_json": 1, "bad_header": 1, "unknown_encoding": 1,
                                               "shape_mismatch": 1}
    wait_for(lambda: [p for p in periods(svc.url) if p["n_ok"] == 3], 30)
    b01 = [b for b in httpx.get(f"{svc.url}/buses").json() if b["bus"] == "b01"][0]
    assert b01["frames_dropped"].get("non_finite") == 1
    metrics = httpx.get(f"{svc.url}/metrics").text
    assert 'aslm_messages_dropped_total{reason="malformed_json"} 1.0' in metrics
    r = httpx.get(f"{svc.url}/buses/b01/diagnosis/latest")
    assert r.status_code == 404 and "diagnosis" in r.json()["detail"]
    assert httpx.get(f"{svc.url}/buses/nope/parameters/latest").status_code == 404
    assert httpx.get(f"{svc.url}/health").json()["status"] == "ok"


def test_unusable_result_fails_that_bus_only(running):
    svc, _, _ = running(period_s=3.0, identify_fn="service_helpers:nan_for_b02_identify")
    p = wait_for(lambda: [p for p in periods(svc.url) if p["n_ok"] + p["n_failed"] == 3], 30)[0]
    assert (p["n_ok"], p["n_failed"]) == (2, 1)
    b02 = httpx.get(f"{svc.url}/buses/b02/parameters/latest").json()
    assert (b02["status"], b02["reason"]) == ("failed", "bad_result")


def test_instance_ingests_only_its_shard(running):
    svc, _, _ = running(period_s=3.0, pmu_keys="north/**", buses=["north/b1", "north/b2", "south/b3"])
    p = wait_for(lambda: [p for p in periods(svc.url) if p["n_ok"] == 2], 30)[0]
    assert p["n_ok"] + p["n_failed"] + p["n_skipped"] == 2
    assert [b["bus"] for b in httpx.get(f"{svc.url}/buses").json()] == ["north/b1", "north/b2"]
    assert httpx.get(f"{svc.url}/buses/north/b1/parameters/latest").json()["status"] == "ok"


def test_no_automatic_full_gc_while_running(running):
    # A generation-2 collection holds the GIL for as long as it scans every live object (REST stalls):
    # off while a service runs, startup objects frozen; restored when the last service stops.
    before = gc.get_threshold()
    svc, _, stream = running(period_s=3.0)
    assert gc.get_threshold()[2] >= 10**9 and gc.get_freeze_count() > 0
    wait_for(lambda: [p for p in periods(svc.url) if p["n_ok"] == 3], 30)
    stream.stop()
    svc.stop()
    assert gc.get_threshold() == before and gc.get_freeze_count() == 0
