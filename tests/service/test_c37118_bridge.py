"""The C37.118 bridge against an independent PMU on 127.0.0.1: frames into Zenoh, bad streams, recovery,
and the service identifying the load the phasors encode.

The PMU is the ``synchrophasor`` package's server (TCP) or a small UDP sender of the package's frames
(tests/c37118_peers.py).  Real sockets and a real Zenoh session: marked slow.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from c37118_peers import A, SynchroPmu, UdpPmu, config2, data_frame, free_port
from conftest import D_TRUE
from service_helpers import wait_for
from zenoh_tap import ZenohTap

from aslm_core.params import DYNAMIC_NAMES
from service.buffers import BufferStore
from service.clock import ManualClock
from service.protocols.mapping import parse_mapping
from service.scheduler import QualityRules, Scheduler
from service.sinks.base import SinkChain
from service.sources.base import Inlet
from service.sources.c37118 import C37118Client, C37118Source, StreamSettings
from service.testing import InlineExecutor, MemorySink

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
VLN = 230e3 / np.sqrt(3)
BUSES = {"feeder": {"pmu": "Station A", "voltage": ["VA", "VB", "VC"], "current": "I1", "base_kv": 230.0}}


def phasors_of(V, theta, P, Q, s_base=100e6):
    """Per-phase V and the feeder current that carry (V, θ, P, Q) in pu on 230 kV / ``s_base``."""
    va = V * VLN * np.exp(1j * theta)
    i = np.conj((P + 1j * Q) * s_base / (3 * va))
    return [va, va * A * A, va * A, i]


def expected(carried: np.ndarray) -> np.ndarray:
    """V, θ, P, Q per frame from the phasors the PMU sent (volts, amperes), by the formula in the docs."""
    va, vb, vc, i1 = carried.T
    v1 = (va + A * vb + A * A * vc) / 3
    s = 3 * v1 * np.conj(i1) / 100e6
    return np.stack([np.abs(v1) / VLN, np.angle(v1), s.real, s.imag])


def frames_of(cfg2, t0: float, n: int, rate: float):
    """n frames from t0 (moved onto the rate's grid, as a PMU stamps them) and the phasors they carry."""
    t0 = round(t0 * rate) / rate
    rng = np.random.default_rng(3)
    out = [data_frame(cfg2, t0 + k / rate, phasors_of(1 + 0.01 * rng.standard_normal(), 0.1 + 0.01 * k / n,
                                                      0.8 + 0.01 * rng.standard_normal(), 0.3),
                      freq_dev=0.01) for k in range(n)]
    return [f for f, _ in out], np.array([c for _, c in out])


@pytest.fixture
def tap():
    t = ZenohTap()
    yield t
    t.close()


def bridge_client(tap: ZenohTap, stream: StreamSettings):
    import zenoh

    from service.replay import FramePublisher
    from service.zenoh_config import zenoh_config

    session = zenoh.open(zenoh_config("peer", connect=[f"tcp/127.0.0.1:{tap.port}"], listen=[]))
    pub = FramePublisher(session, "aslm")
    client = C37118Client(stream, parse_mapping({"buses": BUSES}), pub.send)
    return client, pub, session


@pytest.mark.parametrize("transport", ["tcp", "udp"])
@pytest.mark.parametrize("floating", [False, True])
def test_frames_into_zenoh_match_the_phasors_sent(tap, transport, floating):
    cfg2 = config2(7734, floating=floating, rate=50)
    udp_port = free_port(2)  # SOCK_DGRAM
    peer = SynchroPmu(cfg2) if transport == "tcp" else UdpPmu(cfg2, udp_port)
    stream = StreamSettings(port=peer.port, idcode=7734, transport=transport, udp_port=udp_port,
                            udp_host="127.0.0.1", batch_s=0.1)
    client, pub, session = bridge_client(tap, stream)
    try:
        client.start_thread()
        if transport == "tcp":
            wait_for(lambda: peer.clients() and client.decoder.cfg, 10, 0.05)
        else:
            wait_for(lambda: peer.data_on.is_set(), 10, 0.05)
        frames, carried = frames_of(cfg2, time.time() - 2, 100, 50.0)
        for f in frames:
            peer.send(f)
        wait_for(lambda: sum(len(b) for _, b in tap.batches) >= 100, 20, 0.1)
        got = tap.columns()
        assert {k for k, _ in tap.batches} == {"aslm/pmu/feeder"}
        np.testing.assert_allclose(got[0], [f.get_soc() + f.get_frasec()[0] / 1e6 for f in frames], atol=1e-9)
        np.testing.assert_allclose(got[1:], expected(carried), rtol=1e-12, atol=1e-15)
        counts = client.counts()
        assert counts["frames"] == counts["delivered"] == 100 and counts["rejected"] == {}
    finally:
        client.close()
        pub.close()
        session.close()
        peer.close()


def test_bad_streams_are_counted_and_the_bridge_recovers(tap):
    cfg2 = config2(7734, rate=50)
    udp_port = free_port(2)
    peer = UdpPmu(cfg2, udp_port)
    stream = StreamSettings(port=peer.port, idcode=7734, transport="udp", udp_port=udp_port, udp_host="127.0.0.1",
                            batch_s=0.1)
    client, pub, session = bridge_client(tap, stream)
    try:
        client.start_thread()
        wait_for(lambda: peer.data_on.is_set(), 10, 0.05)
        frames, _ = frames_of(cfg2, time.time() - 2, 60, 50.0)
        raw = [f.convert2bytes() for f in frames]
        peer.send(raw[0][:20])  # truncated
        bad = bytearray(raw[1])
        bad[-1] ^= 0x01
        peer.send(bytes(bad))  # wrong CRC
        other = config2(7734, polar=True, floating=True, rate=50)  # new configuration: float polar from now on
        peer.send(other.convert2bytes())
        new_frames, carried = frames_of(other, time.time() - 1, 10, 50.0)
        peer.send(raw[2])  # a frame of the old layout after the change
        for f in new_frames:
            peer.send(f)
        offrate, _ = frames_of(other, time.time() - 0.5, 1, 50.0)
        offrate[0].set_frasec((offrate[0].get_frasec()[0] + 10000) % 1000000)  # 10 ms off the 50/s grid
        peer.send(offrate[0])
        wait_for(lambda: client.decoder.frames >= 12, 10, 0.05)
        wait_for(lambda: sum(len(b) for _, b in tap.batches) >= 10, 10, 0.05)
        c = client.counts()
        assert c["bad_frames"] == {"truncated": 1, "bad_crc": 1}
        assert c["rejected"] == {"size_mismatch": 1, "off_rate": 1}
        assert c["config_changes"] == 1
        assert c["frames"] == c["delivered"] + sum(c["rejected"].values()) == 12
        np.testing.assert_allclose(tap.columns()[1:], expected(carried), rtol=1e-12, atol=1e-15)
    finally:
        client.close()
        pub.close()
        session.close()
        peer.close()


def test_a_dropped_connection_is_reopened_and_data_resumes(tap):
    cfg2 = config2(7734, rate=50)
    peer = SynchroPmu(cfg2)
    stream = StreamSettings(port=peer.port, idcode=7734, batch_s=0.1, backoff_s=(0.2, 1.0))
    client, pub, session = bridge_client(tap, stream)
    try:
        client.start_thread()
        wait_for(lambda: peer.clients() and client.decoder.cfg, 10, 0.05)
        first, _ = frames_of(cfg2, time.time() - 3, 20, 50.0)
        for f in first:
            peer.send(f)
        wait_for(lambda: client.decoder.frames >= 20, 10, 0.05)
        peer.pmu.clients[0].terminate()  # the PMU side drops the connection
        wait_for(lambda: peer.clients() == 2 and client.connected.is_set() and client.decoder.configs == 2, 10, 0.05)
        second, _ = frames_of(cfg2, time.time() - 1, 20, 50.0)
        for f in second:
            peer.pmu.client_buffers[1].put(f)
        wait_for(lambda: sum(len(b) for _, b in tap.batches) >= 40, 10, 0.05)
        c = client.counts()
        assert c["connects"] == 2 and c["disconnects"] == {"closed_after_data": 1}
        assert c["delivered"] == 40 and c["rejected"] == {}
    finally:
        client.close()
        pub.close()
        session.close()
        peer.close()


def test_aslm_bridge_publishes_and_reports_its_counts(tap, tmp_path):
    cfg2 = config2(7734, rate=50)
    peer = SynchroPmu(cfg2)
    mapping = tmp_path / "pdc.toml"
    mapping.write_text(f"""
[c37118]
host = "127.0.0.1"
port = {peer.port}
idcode = 7734
batch_s = 0.1

[buses.feeder]
pmu = "Station A"
voltage = ["VA", "VB", "VC"]
current = "I1"
base_kv = 230.0
""")
    proc = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "bridge", "c37118", str(mapping), "--duration", "8",
         "--connect", f"tcp/127.0.0.1:{tap.port}", "--log-level", "WARNING"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        wait_for(lambda: peer.clients(), 20, 0.1)
        time.sleep(0.5)
        frames, carried = frames_of(cfg2, time.time() - 2, 50, 50.0)
        for f in frames:
            peer.send(f)
        wait_for(lambda: sum(len(b) for _, b in tap.batches) >= 50, 20, 0.1)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        peer.close()
    counts = json.loads(out.strip().splitlines()[-1])
    assert (counts["frames"], counts["delivered"], counts["published"], counts["rejected"]) == (50, 50, 50, {}), err
    np.testing.assert_allclose(tap.columns()[1:], expected(carried), rtol=1e-12, atol=1e-15)


def test_the_service_identifies_the_load_the_phasors_encode(eq_window):
    """The equation window's V, θ, P, Q as phasors of a PMU at 100 frames/s, through the source, the
    buffers and the scheduler into the real identifier."""
    w = eq_window
    t0 = 1_000_000.0
    cfg2 = config2(7734, floating=True, rate=100)
    peer = SynchroPmu(cfg2, send_rate=5000)
    clock = ManualClock(t0 + 1.0)
    rules = QualityRules(10.0, 100.0, min_coverage=0.9, max_gap_s=0.2, min_v_std=1e-5)
    store = BufferStore(10.0, 100.0, 0.5)
    sink = MemorySink()
    scheduler = Scheduler(store, InlineExecutor("service.worker:identify_window"), rules, late_s=0.5, f0=50.0,
                          period_s=lambda: 20.0, on_results=SinkChain([sink], on_error=print).write_results,
                          on_period=lambda s: None, warm_starts={}, options={"n_starts": 3, "lowpass_hz": 2.0},
                          n_starts_warm=1, clock=clock)
    # The peer sends nothing once its frames are out: no silence timeout while the period runs.
    source = C37118Source(StreamSettings(port=peer.port, idcode=7734, batch_s=0.1, timeout_s=3600.0),
                          parse_mapping({"buses": {"eq": BUSES["feeder"]}}))
    source.start(Inlet(store, max_future_s=5.0, f0=50.0, clock=clock))
    scheduler.start()
    try:
        wait_for(lambda: peer.clients() and source.client.decoder.cfg, 10, 0.05)
        end = t0 + 20
        clock.advance_to(end)
        clock.settle()
        t = w.t - w.t[-1] + end
        for k in range(t.size):
            peer.send(data_frame(cfg2, t[k], phasors_of(w.V[k], w.theta[k], w.P[k], w.Q[k]))[0])
        # The bus exists from its first buffered frame on (None before): the peer sends ~80 frames/s.
        wait_for(lambda: (c := store.counts("eq")) is not None and c.buffered >= t.size, 60, 0.1)
        peer.close()  # its connection handler polls without sleeping: stop it before the identifier runs
        clock.advance_to(end + 0.5)
        wait_for(lambda: sink.results, 600, 0.5)  # the identifier runs inline (numba compiles on first use)
    finally:
        scheduler.stop()
        source.close()
        peer.close()
    res = sink.results[0]
    d = np.array([res.parameters.dynamic[k] for k in DYNAMIC_NAMES])
    assert res.status == "ok" and np.all(np.abs(d / D_TRUE - 1) < 0.05), d


def test_aslm_bridge_pmu_serves_the_real_pcap_capture_at_its_rate():
    capture = ROOT.parent / "shared" / "data" / "real" / "c37118-1pmu-tcp.pcap"
    if not capture.is_file():
        pytest.skip("real recording not present")
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "bridge", "pmu", str(capture), "--port", str(port), "--duration", "30",
         "--log-level", "WARNING"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    got: list = []
    buses = {"blue": {"pmu": "Blue PMU", "voltage": "V1LPM", "current": "VALPM", "base_kv": 1.0}}
    client = C37118Client(StreamSettings(port=port, idcode=241, batch_s=0.1, backoff_s=(0.2, 0.5)),
                          parse_mapping({"buses": buses}), lambda bus, b: got.append(b))
    try:
        client.start_thread()
        wait_for(lambda: client.decoder.frames >= 252, 40, 0.1)
        out, err = proc.communicate(timeout=40)
    finally:
        client.close()
        proc.kill()
    t = np.concatenate([b.t for b in got])
    assert client.counts()["delivered"] == 252 and client.counts()["rejected"] == {}
    np.testing.assert_allclose(np.diff(t), 1 / 50, atol=1e-6)  # re-stamped on the 50 frames/s grid
    assert abs(t[-1] - time.time()) < 30
    assert json.loads(out.strip().splitlines()[-1])["sent"] == 252, err
