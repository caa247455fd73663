"""The STTP source without a network: the mapping's names resolved against openPDC-style metadata (sttpapi's
own MetadataCache), and measurements assembled into per-bus frames with everything counted."""

from __future__ import annotations

import numpy as np
import pytest
from sttp_peers import UNIX_TICKS, Device, metadata_xml, ticks

from service.protocols.mapping import MappingError, parse_mapping
from service.sources.sttp import (
    BADDATA,
    BADTIME,
    STAT_NOT_SYNC,
    STAT_PMU_ERROR,
    SUSPECTTIME,
    FrameAssembler,
    SttpSettings,
    filter_expression,
    resolve,
)

DEVICES = [Device("FEEDER7", [("V1", "V"), ("I1", "I")]),
           Device("FEEDER9", [("VA", "V")], freq=False, extra=[("FEEDER9:P", "CALC"), ("FEEDER9:Q", "CALC")])]
BUSES = {"f7": {"pmu": "FEEDER7", "voltage": "V1", "current": "I1", "base_kv": 230.0},
         "f9": {"pmu": "FEEDER9", "voltage": "VA", "power": ["FEEDER9:P", "FEEDER9:Q"], "base_kv": 69.0,
                "base_mva": 50.0}}
VLN = 230e3 / np.sqrt(3)


def cache_and_signals(devices=DEVICES):
    from sttp.data.dataset import DataSet
    from sttp.metadata.cache import MetadataCache

    xml, signals = metadata_xml(devices)
    dataset, err = DataSet.from_xml(xml)
    assert err is None
    return MetadataCache(dataset), signals


def measurement(signals, tag, value, t, flags=0):
    from sttp.transport.measurement import Measurement

    return Measurement(signals[tag].signal_id, np.float64(value), np.uint64(ticks(t)), flags)


def f7_values(k: int) -> dict[str, float]:
    return {"FEEDER7:V1.MAG": VLN * (1 + 0.001 * k), "FEEDER7:V1.ANG": 10.0 + k, "FEEDER7:I1.MAG": 200.0 + k,
            "FEEDER7:I1.ANG": -20.0, "FEEDER7:FREQ": 50.0 + 0.01 * k}


def assembler(buses=BUSES, settings=None, **kw):
    cache, signals = cache_and_signals()
    plans = resolve(cache, parse_mapping({"buses": buses}, power=True).buses, settings or SttpSettings())
    return FrameAssembler(plans, lag_s=kw.pop("lag_s", 1.0), **kw), [], signals


def feed(asm: FrameAssembler, out: list[dict], measurements, now: float | None = None) -> None:
    """Add measurements; what they completed, if anything, is appended to ``out`` as one hand-on."""
    asm.add(measurements, now)
    if taken := asm.take():
        out.append(taken)


def test_power_is_a_mapping_key_of_sttp_only():
    with pytest.raises(MappingError, match="STTP source only"):
        parse_mapping({"buses": {"f9": BUSES["f9"]}})
    bus = parse_mapping({"buses": {"f9": BUSES["f9"]}}, power=True).buses[0]
    assert bus.power == ("FEEDER9:P", "FEEDER9:Q") and bus.feeders == ()
    with pytest.raises(MappingError, match="power"):
        parse_mapping({"buses": {"x": {**BUSES["f9"], "power": ["P"]}}}, power=True)
    with pytest.raises(MappingError, match="missing current"):
        parse_mapping({"buses": {"x": {k: v for k, v in BUSES["f7"].items() if k != "current"}}}, power=True)


def test_the_sttp_table():
    s = SttpSettings.from_table({"host": "pdc", "port": 7175, "backoff_s": [1, 5],
                                 "phasors": {"Vbus": {"mag": "A:VM", "ang": "A:VA"}}})
    assert (s.host, s.port, s.backoff_s, s.phasors) == ("pdc", 7175, (1.0, 5.0), {"Vbus": ("A:VM", "A:VA")})
    with pytest.raises(MappingError, match="unknown key.*idcode"):
        SttpSettings.from_table({"idcode": 1})
    with pytest.raises(MappingError, match="angle_unit"):
        SttpSettings.from_table({"angle_unit": "grad"})
    with pytest.raises(MappingError, match="mag = ..., ang = ..."):
        SttpSettings.from_table({"phasors": {"V": ["a", "b"]}})


def test_names_resolve_against_the_publishers_metadata():
    cache, sig = cache_and_signals()
    plans = resolve(cache, parse_mapping({"buses": BUSES}, power=True).buses, SttpSettings())
    ids = lambda *tags: [sig[t].signal_id for t in tags]  # noqa: E731
    assert plans[0].slots == ids("FEEDER7:V1.MAG", "FEEDER7:V1.ANG", "FEEDER7:I1.MAG", "FEEDER7:I1.ANG",
                                 "FEEDER7:FREQ")
    assert plans[0].has_freq and plans[0].feeder_sizes == [1]
    assert plans[1].slots == ids("FEEDER9:VA.MAG", "FEEDER9:VA.ANG", "FEEDER9:P", "FEEDER9:Q")
    assert not plans[1].has_freq
    # A phasor named outright by point tags (a publisher without PhasorDetail rows), here swapped on purpose.
    explicit = SttpSettings(phasors={"Vx": ("FEEDER7:I1.MAG", "FEEDER7:I1.ANG")})
    bus = parse_mapping({"buses": {"x": {**BUSES["f7"], "voltage": "Vx"}}}).buses
    assert resolve(cache, bus, explicit)[0].slots[:2] == ids("FEEDER7:I1.MAG", "FEEDER7:I1.ANG")
    with pytest.raises(MappingError, match=r"no phasor 'V2' .*it has I1, V1"):
        resolve(cache, parse_mapping({"buses": {"x": {**BUSES["f7"], "voltage": "V2"}}}).buses, SttpSettings())
    with pytest.raises(MappingError, match=r"no device 'PMU3' .*it has FEEDER7, FEEDER9"):
        resolve(cache, parse_mapping({"buses": {"x": {**BUSES["f7"], "pmu": "PMU3"}}}).buses, SttpSettings())
    with pytest.raises(MappingError, match="no measurement 'FEEDER9:S'"):
        resolve(cache, parse_mapping({"buses": {"x": {**BUSES["f9"], "power": ["FEEDER9:P", "FEEDER9:S"]}}},
                                     power=True).buses, SttpSettings())


def test_the_subscription_filter_names_the_devices_and_the_named_measurements():
    mapping = parse_mapping({"buses": BUSES}, power=True)
    sid = "8159f9a0-c025-4c7e-9a49-5bd1e3b3f0a1"
    f = filter_expression(mapping, SttpSettings(phasors={"V": ("O'Brien:VM", sid)}))
    assert f == ("FILTER ActiveMeasurements WHERE Device IN ('FEEDER7', 'FEEDER9') OR "
                 "PointTag IN ('FEEDER9:P', 'FEEDER9:Q', 'O''Brien:VM') OR "
                 "SignalReference IN ('FEEDER9:P', 'FEEDER9:Q', 'O''Brien:VM') OR SignalID IN ({" + sid + "})")
    assert ";" not in f


def test_measurements_in_any_order_make_frames_with_the_published_values():
    asm, out, sig = assembler()
    t0 = 1.7e9
    ms = [measurement(sig, tag, v, t0 + k / 50) for k in range(4) for tag, v in f7_values(k).items()]
    ms = ms[::-1]  # the newest timestamp first, and each frame's measurements reversed
    feed(asm, out, ms[:7])  # frame 3 whole, two measurements of frame 2
    assert len(out) == 1 and len(out[0]["f7"]) == 1
    feed(asm, out, ms[7:])
    assert len(out) == 2 and set(out[1]) == {"f7"}
    b = out[1]["f7"]  # frames 0, 1, 2 in time order
    np.testing.assert_array_equal(b.t, (np.array([ticks(t0 + k / 50) for k in range(3)]) - UNIX_TICKS) / 1e7)
    v = [f7_values(k) for k in range(3)]
    V = np.array([x["FEEDER7:V1.MAG"] * np.exp(1j * np.radians(x["FEEDER7:V1.ANG"])) for x in v])
    i = np.array([x["FEEDER7:I1.MAG"] * np.exp(1j * np.radians(x["FEEDER7:I1.ANG"])) for x in v])
    s = 3 * V * np.conj(i) / 100e6
    np.testing.assert_allclose(b.V, np.abs(V) / VLN, rtol=1e-15)
    np.testing.assert_allclose(b.theta, np.angle(V), rtol=1e-15)
    np.testing.assert_allclose(np.stack([b.P, b.Q]), np.stack([s.real, s.imag]), rtol=1e-14)
    np.testing.assert_allclose(b.f, [x["FEEDER7:FREQ"] for x in v], rtol=1e-15)
    c = asm.counts()
    assert (c["measurements"], c["frames"], c["delivered"], c["pending"], c["bad_measurements"]) == (20, 4, 4, 0, {})


def test_power_buses_take_p_and_q_in_mw_and_mvar():
    asm, out, sig = assembler()
    vals = {"FEEDER9:VA.MAG": 69e3 / np.sqrt(3) * 1.02, "FEEDER9:VA.ANG": 0.0, "FEEDER9:P": 40.0, "FEEDER9:Q": -5.0}
    feed(asm, out, [measurement(sig, tag, v, 1.7e9) for tag, v in vals.items()])
    b = out[0]["f9"]
    np.testing.assert_allclose([b.V[0], b.P[0], b.Q[0]], [1.02, 40.0 / 50.0, -5.0 / 50.0], rtol=1e-14)
    assert b.f is None


def test_what_cannot_make_a_frame_is_counted():
    asm, out, sig = assembler(lag_s=1.0)
    t0 = 1.7e9
    full = [measurement(sig, tag, v, t0) for tag, v in f7_values(0).items()]
    feed(asm, out, full, now=0.0)
    feed(asm, out, [full[0]], now=0.1)  # of a frame already handed on
    feed(asm, out, [measurement(sig, "FEEDER9:P", 1.0, t0)], now=0.1)  # f9's frame stays incomplete
    feed(asm, out, [measurement(sig, "FEEDER7:I1.MAG", 1.0, t0 + 0.02)] * 2, now=0.2)  # twice the same slot
    asm.expire(now=1.15)
    assert asm.counts()["pending"] == 1  # the frame at t0 + 0.02 is younger than lag_s
    asm.expire(now=1.25)
    c = asm.counts()
    assert c["bad_measurements"] == {"late": 1, "duplicate": 1}
    assert (c["measurements"], c["frames"], c["delivered"], c["rejected"], c["pending"]) == (
        9, 3, 1, {"incomplete": 2}, 0)
    # Measurements of an expired frame are late too, not the start of a new one.
    feed(asm, out, [measurement(sig, "FEEDER9:Q", 1.0, t0)], now=1.3)
    assert asm.counts()["bad_measurements"]["late"] == 2 and asm.counts()["frames"] == 3


def test_unmapped_signals_are_counted_and_flags_become_stat_bits():
    cache, sig = cache_and_signals()
    plans = resolve(cache, parse_mapping({"buses": {"f7": BUSES["f7"]}}).buses, SttpSettings())
    out: list[dict] = []
    asm = FrameAssembler(plans, lag_s=1.0)
    t0 = 1.7e9
    flags = [0, BADDATA, BADTIME, SUSPECTTIME]
    ms = [measurement(sig, tag, v, t0 + k / 50, flags[k] if tag == "FEEDER7:I1.ANG" else 0)
          for k in range(4) for tag, v in f7_values(k).items()]
    ms.append(measurement(sig, "FEEDER9:P", 3.0, t0))  # a signal no bus of this mapping uses
    feed(asm, out, ms)
    b = out[0]["f7"]
    assert b.stat.tolist() == [0, STAT_PMU_ERROR, STAT_NOT_SYNC, 0]
    c = asm.counts()
    assert c["bad_measurements"] == {"unmapped": 1} and c["delivered"] == 4
    assert c["flags"] == {"bad_data": 1, "bad_time": 1, "suspect_time": 1}


def test_nan_values_complete_a_frame_and_adjustments_apply():
    asm, out, sig = assembler(adjust=None)
    vals = f7_values(0)
    vals["FEEDER7:FREQ"] = float("nan")
    feed(asm, out, [measurement(sig, tag, v, 1.7e9) for tag, v in vals.items()])
    assert np.isnan(out[0]["f7"].f[0])  # handed on: the service's validation rejects it (non_finite)
    cache, sig2 = cache_and_signals()
    plans = resolve(cache, parse_mapping({"buses": {"f7": BUSES["f7"]}}).buses, SttpSettings(angle_unit="rad"))
    out = []
    asm = FrameAssembler(plans, lag_s=1.0, angle_unit="rad",
                         adjust={sig2["FEEDER7:V1.MAG"].signal_id: (1e3, 0.0)})  # a PMU sending kV
    vals = {**f7_values(0), "FEEDER7:V1.MAG": VLN / 1e3, "FEEDER7:V1.ANG": 0.5}
    feed(asm, out, [measurement(sig2, tag, v, 1.7e9) for tag, v in vals.items()])
    b = out[0]["f7"]
    np.testing.assert_allclose([b.V[0], b.theta[0]], [1.0, 0.5], rtol=1e-14)


def test_the_sttp_source_is_built_from_the_settings_mapping_file(tmp_path):
    from types import SimpleNamespace

    from service.registry import load
    from service.settings import SettingsError, load_settings
    from service.sources import SOURCES
    from service.sources.sttp import SttpSource

    with pytest.raises(SettingsError, match="pmu_mapping"):
        load_settings(sources=["sttp"], storage_url=str(tmp_path / "x.sqlite"))
    path = tmp_path / "openpdc.toml"
    path.write_text('[sttp]\nhost = "pdc"\nport = 7175\n[buses.f9]\npmu = "FEEDER9"\nvoltage = "VA"\n'
                    'power = ["FEEDER9:P", "FEEDER9:Q"]\nbase_kv = 69\n')
    settings = load_settings(sources=["sttp"], pmu_mapping=str(path), storage_url=str(tmp_path / "x.sqlite"))
    source = load(SOURCES, "sttp")(SimpleNamespace(settings=settings))  # build(ctx) reads ctx.settings only
    assert isinstance(source, SttpSource) and (source.settings.host, source.settings.port) == ("pdc", 7175)
    assert source.mapping.buses[0].power == ("FEEDER9:P", "FEEDER9:Q")
    path.write_text('[c37118]\nport = 1\n[buses.f9]\npmu = "FEEDER9"\nvoltage = "VA"\ncurrent = "I"\nbase_kv = 1\n')
    with pytest.raises(MappingError, match=r"no \[sttp\] table"):
        load(SOURCES, "sttp")(SimpleNamespace(settings=settings))
