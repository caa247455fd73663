"""Hostile input on the ingest path (issue 17, defects 1, 4, 5 and 6's input items), one test per defect.

Each test reproduces what the attacker's trial did and states what must happen instead; every one of
them failed before the fix.
"""

from __future__ import annotations

import json
import struct
import time
import warnings

import numpy as np
import pytest
import zenoh
from service_helpers import client_session, settings_for, wait_for
from test_service_scheduler import LATE_S, T0, Bench

from service.api import create_app
from service.buffers import BufferStore
from service.busnames import MAX_BUS_LEN, bus_name_problem
from service.clock import ManualClock
from service.frames import BINARY_ENCODING, FrameBatch, encode_binary, encode_json
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.models import BusResult
from service.sources.base import Inlet
from service.sources.zenoh import ZenohSource
from service.storage import Storage
from service.zenoh_config import zenoh_config

with warnings.catch_warnings():  # Starlette warns at import that its TestClient will change HTTP client
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

NOW = 1_700_000_000.0
FS = 50.0


def frames_at(t: np.ndarray) -> FrameBatch:
    t = np.asarray(t, float)
    rng = np.random.default_rng(int(t.size))
    return FrameBatch(t=t, V=1.0 + 0.01 * rng.standard_normal(t.size), theta=0.01 * rng.standard_normal(t.size),
                      P=0.8 + 0 * t, Q=0.3 + 0 * t)


def second_of(t0: float) -> np.ndarray:
    return t0 + np.arange(50) / FS


def inlet(clock_at: float = NOW, **store_kw) -> tuple[Inlet, BufferStore, ManualClock]:
    clock = ManualClock(clock_at)
    store = BufferStore(10.0, FS, 1.0, **store_kw)
    return Inlet(store, max_future_s=5.0, f0=50.0, clock=clock), store, clock


# --- defect 1: wildcard bus names ------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["*", "**", "a/*/b", "b$*", "x?y", "x#y", "", "/a", "a/", "a//b", "a\nb",
                                  "b" * (MAX_BUS_LEN + 1)])
def test_bus_grammar_refuses_key_expression_characters_empty_chunks_and_long_names(name):
    assert bus_name_problem(name) is not None


@pytest.mark.parametrize("name", ["bus0002", "north/b1", "sub-7/pmu_3.v2", "Ünïcode", "b" * MAX_BUS_LEN])
def test_bus_grammar_accepts_plain_names(name):
    assert bus_name_problem(name) is None


def test_a_wildcard_bus_is_refused_at_the_inlet_and_counted():
    ingest, store, _ = inlet()
    payload = encode_binary(frames_at(second_of(NOW - 1)))
    for bus in ("*", "**", "a/*/b"):
        ingest.message(bus, payload, BINARY_ENCODING)
    ingest.frames("bus0002/*", frames_at(second_of(NOW - 1)))
    assert store.buses() == []
    tot = store.totals()
    assert tot.frames_rejected == {"bad_bus": 200} and tot.messages_rejected == {"bad_bus": 4}
    assert tot.frames_received == 200 and tot.messages == 4


def test_rest_refuses_a_wildcard_bus_in_the_path_with_422(tmp_path):
    from test_service_api import View

    settings = settings_for(tmp_path, 7447)
    store = BufferStore(settings.window_s, settings.frame_rate, settings.late_s)
    storage = Storage(settings.storage_path)
    view = View(settings, store, storage, LatestResults(), ServiceMetrics(store), settings.period_s)
    with TestClient(create_app(view)) as client:
        for path in ("/buses/*/parameters/latest", "/buses/a/**/parameters", "/buses/$*/diagnosis/latest"):
            r = client.get(path)
            assert r.status_code == 422 and "bus" in r.json()["detail"], path
        assert client.get("/buses/north/b1/parameters/latest").status_code == 404  # valid, no result yet
    storage.close()


def test_storage_refuses_a_wildcard_bus(tmp_path):
    storage = Storage(tmp_path / "s.sqlite")
    res = BusResult(bus="*", period=10.0, period_s=10.0, status="skipped", reason="no_data", completed_at=11.0)
    with pytest.raises(ValueError, match="bus"):
        storage.save_results([res])
    with pytest.raises(ValueError, match="bus"):
        storage.save_diagnosis("a/**", 10.0, "{}")
    assert storage.buses() == []
    storage.close()


@pytest.mark.slow
def test_a_put_on_a_wildcard_key_over_zenoh_creates_no_bus():
    port = 17_731
    store = BufferStore(10.0, FS, 1.0)
    session = zenoh.open(zenoh_config("peer", listen=[f"tcp/127.0.0.1:{port}"], connect=[]))
    source = ZenohSource(session, "aslm")
    source.start(Inlet(store, max_future_s=5.0, f0=50.0))
    pub = client_session(port)
    try:
        payload = encode_binary(frames_at(second_of(time.time() - 2)))
        time.sleep(0.5)
        for key in ("aslm/pmu/*", "aslm/pmu/**", "aslm/pmu/a/*/b", "aslm/pmu/bus0002"):
            pub.put(key, payload, encoding=zenoh.Encoding(BINARY_ENCODING))
        wait_for(lambda: store.totals().messages == 4, 10)
        assert store.buses() == ["bus0002"]
        assert store.totals().messages_rejected == {"bad_bus": 3} and source.internal_errors == 0
    finally:
        pub.close()
        source.close()
        session.close()


# --- defect 4: phantom buses ----------------------------------------------------------------------------
def test_junk_buses_filling_the_cap_never_lock_out_a_real_bus():
    ingest, store, clock = inlet(max_buses=100)
    for k in range(1000):  # one stray message each, then never again
        ingest.message(f"junk{k}", b'{"t": [1]}', "application/json")
        clock.advance(0.001)
    for _ in range(3):
        clock.advance(1.0)
        ingest.frames("real", frames_at(second_of(clock.now() - 1)))
    assert store.counts("real").buffered == 150
    tot = store.totals()
    assert tot.buses <= 100 and "too_many_buses" not in tot.frames_rejected
    assert tot.messages == 1003 and tot.frames_received == 1000 + 150  # evicted buses' counts are kept


def test_a_real_bus_survives_a_flood_of_junk_names_that_send_valid_frames():
    ingest, store, clock = inlet(max_buses=50)
    for k in range(5):
        clock.advance(1.0)
        ingest.frames("real", frames_at(second_of(clock.now() - 1)))
        for j in range(40):  # 200 junk names in all, each heard from once
            ingest.frames(f"junk{k}/{j}", frames_at(second_of(clock.now() - 1)))
    assert store.counts("real").buffered == 250


def test_idle_buses_are_evicted_and_their_counts_kept_in_the_totals():
    ingest, store, clock = inlet()
    ingest.frames("old", frames_at(second_of(NOW - 1)))
    clock.advance(100.0)
    ingest.frames("new", frames_at(second_of(clock.now() - 1)))
    before = store.totals()
    assert store.evict_idle(clock.now() - 50.0) == ["old"]
    assert store.buses() == ["new"]
    after = store.totals()
    assert (after.frames_received, after.frames_buffered, after.messages) == (
        before.frames_received, before.frames_buffered, before.messages)


def test_a_skipped_bus_is_written_once_per_change_of_state():
    b = Bench(period_s=10.0, start=T0 + 1.0).start()
    try:
        coverage = dict(keep=lambda t: np.arange(t.size) % 2 == 0)
        for k in range(1, 5):  # four periods in a row with half the frames
            b.run_to(T0 + 10 * k)
            b.feed("b1", T0 + 10 * k, **coverage)
            b.run_to(T0 + 10 * k + LATE_S)
        b.period(T0 + 50, "b1")  # ok
        for k in (6, 7):
            b.run_to(T0 + 10 * k)
            b.feed("b1", T0 + 10 * k, **coverage)
            b.run_to(T0 + 10 * k + LATE_S)
        rows = [(r.period, r.status, r.reason) for r in b.sink.results]
        assert rows == [(T0 + 10, "skipped", "coverage"), (T0 + 50, "ok", None), (T0 + 60, "skipped", "coverage")]
        assert [p.n_skipped for p in b.sink.periods] == [1, 1, 1, 1, 0, 1, 1]  # the periods still count them
    finally:
        b.stop()


def test_buses_that_never_buffered_a_frame_get_no_result_row():
    b = Bench(period_s=10.0, start=T0 + 1.0).start()
    try:
        b.run_to(T0 + 10)
        for k in range(20):
            b.source.push_message(f"junk{k}", b'{"t": [1], "V": [1]}', "application/json")
        b.feed("b1", T0 + 10)
        b.run_to(T0 + 10 + LATE_S)
        assert [r.bus for r in b.sink.results] == ["b1"]
    finally:
        b.stop()


def test_the_scheduler_evicts_buses_idle_longer_than_bus_idle_s():
    b = Bench(period_s=10.0, start=T0 + 1.0)
    b.scheduler.bus_idle_s = 25.0
    b.start()
    try:
        b.period(T0 + 10, "gone", "stays")
        for k in (2, 3, 4):
            b.period(T0 + 10 * k, "stays")
        assert b.store.buses() == ["stays"]
        gone = [(r.period, r.status, r.reason) for r in b.sink.results if r.bus == "gone"]
        assert gone == [(T0 + 10, "ok", None), (T0 + 20, "skipped", "no_data")]  # silent: said once, then forgotten
    finally:
        b.stop()


def test_nothing_kept_per_bus_outlives_a_bus_evicted_at_the_cap():
    b = Bench(period_s=10.0, start=T0 + 1.0)
    b.store.max_buses = 3
    evicted: list[str] = []
    b.scheduler.on_evicted = evicted.extend
    b.start()
    try:
        half = dict(keep=lambda t: np.arange(t.size) % 2 == 0)
        for k, names in ((1, "abc"), (2, "def")):
            b.run_to(T0 + 10 * k)
            for name in names:
                b.feed(name, T0 + 10 * k, **half)
            b.run_to(T0 + 10 * k + LATE_S)
        assert b.store.buses() == ["d", "e", "f"]
        assert set(b.scheduler._skip_state) == {"d", "e", "f"} and sorted(evicted) == ["a", "b", "c"]
    finally:
        b.stop()


def test_evicted_buses_leave_the_latest_results_only_if_they_were_skips():
    latest = LatestResults()
    rows = [BusResult(bus=b, period=10.0, period_s=10.0, status=st, reason=None if st == "ok" else "x",
                      completed_at=11.0) for b, st in (("junk", "skipped"), ("pmu", "ok"), ("broken", "failed"))]
    latest.write_results(rows, [r.model_dump_json() for r in rows])
    latest.forget_skipped(["junk", "pmu", "broken", "unknown"])
    assert sorted(latest.results) == sorted(latest.results_json) == ["broken", "pmu"]


# --- defect 5: blind spots and poisonable counters -----------------------------------------------------
def test_a_binary_header_claiming_n_0xffffffff_counts_only_the_frames_present():
    ingest, store, _ = inlet()
    ingest.message("b1", struct.pack("<4sBBHII", b"ASLM", 1, 0, 0, 0xFFFFFFFF, 0), BINARY_ENCODING)
    good = encode_binary(frames_at(second_of(NOW - 1)))
    ingest.message("b1", good[:16] + good[16:16 + 40 * 3 + 7], BINARY_ENCODING)  # 3 whole frames' bytes, cut short
    tot = store.totals()
    assert tot.messages_rejected == {"length_mismatch": 2}
    assert tot.frames_received == 3 and tot.frames_rejected == {"length_mismatch": 3}


@pytest.mark.parametrize("t", ["[1000000000000000000000000000000]", "[1e30]", "[-1000000000000000000000000000000]",
                               "[1e400]", "[" + "9" * 400 + "]"])
def test_absurd_json_times_are_counted_rejections_not_exceptions(t):
    ingest, store, _ = inlet()
    ingest.message("b1", f'{{"t": {t}, "V": [1], "theta": [0], "P": [1], "Q": [0]}}'.encode(), "application/json")
    tot = store.totals()
    assert tot.frames_received == 1 and tot.frames_buffered == 0 and sum(tot.frames_rejected.values()) == 1


def test_one_frame_from_the_future_does_not_make_the_next_real_frames_late():
    ingest, store, clock = inlet(NOW)
    ingest.frames("b1", frames_at(np.array([NOW + 4.8])))  # within max_future_s = 5
    sent = 1
    for _ in range(20):  # the next 20 s of real frames, arriving on time
        clock.advance(1.0)
        ingest.frames("b1", frames_at(second_of(clock.now() - 1.0)))
        sent += 50
    c = store.counts("b1")
    assert c.rejected.get("late", 0) == 0
    assert c.buffered + sum(c.rejected.values()) == sent and c.buffered >= sent - 1


# --- defect 6: weaker spots (input) ---------------------------------------------------------------------
def test_a_message_larger_than_the_limit_is_refused_before_decoding():
    ingest, store, _ = inlet()
    ingest.max_message_bytes = 4096
    big = encode_json(frames_at(NOW - 10 + np.arange(500) / FS))
    assert len(big) > 4096
    ingest.message("b1", big, "application/json")
    ingest.message("b1", encode_json(frames_at(second_of(NOW - 1))), "application/json")
    c = store.counts("b1")
    assert c.messages_rejected == {"too_large": 1} and c.buffered == 50


def test_timestamps_at_or_before_the_epoch_are_rejected_with_a_reason():
    ingest, store, _ = inlet()
    ingest.frames("b1", frames_at(np.array([0.0, -1e9, NOW - 1.0])))
    c = store.counts("b1")
    assert c.rejected == {"bad_time": 2} and c.buffered == 1


@pytest.mark.parametrize("behind", [30.0, 3600.0])
def test_a_pmu_clock_behind_is_reported_as_clock_offset_with_the_offset(behind):
    b = Bench(period_s=10.0, start=T0 + 1.0).start()
    try:
        for k in (1, 2):
            b.run_to(T0 + 10 * k)
            b.feed("late-clock", T0 + 10 * k - behind)  # frames arrive now, stamped `behind` s ago
            b.run_to(T0 + 10 * k + LATE_S)
        res = b.sink.results
        assert [(r.status, r.reason) for r in res] == [("skipped", "clock_offset")]  # once: the state held
        assert res[0].clock_offset_s == pytest.approx(-behind, abs=0.05)
    finally:
        b.stop()


@pytest.mark.parametrize("stat", ["[70000]", "[-1]", "[1.5]", "[65536]"])
def test_a_stat_word_outside_uint16_is_refused_not_wrapped(stat):
    ingest, store, _ = inlet()
    msg = f'{{"t": [{NOW - 1}], "V": [1], "theta": [0], "P": [1], "Q": [0], "stat": {stat}}}'
    ingest.message("b1", msg.encode(), "application/json")
    c = store.counts("b1")
    assert c.buffered == 0 and sum(c.rejected.values()) == 1 and c.messages_rejected == {"bad_type": 1}


def test_a_null_required_column_is_a_missing_field_not_a_key_error():
    # Found by tests/service/test_service_fuzz.py: {"V": null} passed the presence check, then raised KeyError.
    ingest, store, _ = inlet()
    ingest.message("b1", b'{"t": [1.0, 2.0], "V": null, "theta": [0, 0], "P": [1, 1], "Q": [0, 0]}',
                   "application/json")
    c = store.counts("b1")
    assert c.messages_rejected == {"missing_field": 1} and c.rejected == {"missing_field": 2}


def test_a_deeply_nested_json_message_is_a_counted_rejection():
    ingest, store, _ = inlet()
    ingest.message("b1", b"[" * 100_000 + b"]" * 100_000, "application/json")
    ingest.message("b1", json.dumps({"t": [[1, 2], [3]]}).encode(), "application/json")
    assert store.counts("b1").messages_rejected == {"malformed_json": 1, "missing_field": 1}

