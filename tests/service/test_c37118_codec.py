"""The C37.118.2 codec and stream decoder against frames encoded by an independent implementation.

Frames come from the ``synchrophasor`` package (tests/c37118_peers.py); the stream tests cut them and
damage them the ways a network and a PMU do, and check that every PMU frame is either delivered or
counted with its reason.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from c37118_peers import STAT_OK, config2, data_frame

from service.protocols import c37118 as c37
from service.protocols.c37118_stream import StreamDecoder
from service.protocols.mapping import MappingError, parse_mapping, positive_sequence

T0 = 1_700_000_000.0
A = np.exp(2j * np.pi / 3)
VLN = 230e3 / np.sqrt(3)
MAPPING = {"buses": {"b1": {"pmu": "Station A", "voltage": ["VA", "VB", "VC"], "current": "I1", "base_kv": 230.0}}}


def balanced(k: int, v: float = 1.02, i: float = 400.0, phi: float = 0.3) -> list[complex]:
    """Phasors of frame k: balanced three-phase voltages and the current of phase A's positive sequence."""
    th = 0.05 + 0.001 * k
    va = v * VLN * np.exp(1j * th)
    return [va, va * A * A, va * A, i * np.exp(1j * (th - phi))]


def test_crc_is_crc_ccitt_false():
    # The check value of CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over "123456789".
    assert c37.crc_ccitt(b"123456789") == 0x29B1


@pytest.mark.parametrize("polar", [False, True])
@pytest.mark.parametrize("floating", [False, True])
def test_frames_of_the_synchrophasor_package_decode_to_the_phasors_they_carry(polar, floating):
    cfg2 = config2(7734, polar=polar, floating=floating, rate=50)
    cfg = c37.parse_config(c37.parse(cfg2.convert2bytes()))
    assert (cfg.idcode, cfg.time_base, cfg.data_rate) == (7734, 1_000_000, 50.0)
    p = cfg.pmus[0]
    assert (p.station, p.polar, p.phasor_float, p.freq_float, p.fnom) == ("Station A", polar, floating, floating, 50.0)
    assert [(ph.name, ph.kind) for ph in p.phasors] == [("VA", 0), ("VB", 0), ("VC", 0), ("I1", 1)]
    frames, carried = zip(*(data_frame(cfg2, T0 + k / 50, balanced(k), freq_dev=0.012 * k) for k in range(5)),
                          strict=True)
    raw = b"".join(f.convert2bytes() for f in frames)
    t, tq, (block,) = cfg.decode_data(raw)
    np.testing.assert_allclose(t, T0 + np.arange(5) / 50, atol=1e-6)
    np.testing.assert_allclose(block.phasors, np.array(carried), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(block.freq, 50.0 + 0.012 * np.arange(5), atol=1e-6)
    assert (block.stat == 0).all() and (tq == 0).all()


def _stream(n: int, *, start: int = 0, rate: int = 50, polar: bool = False):
    cfg2 = config2(7734, polar=polar, rate=rate)
    frames = [data_frame(cfg2, T0 + (start + k) / rate, balanced(start + k))[0].convert2bytes() for k in range(n)]
    return cfg2.convert2bytes(), frames


def _decoder():
    out: list = []
    dec = StreamDecoder(parse_mapping(MAPPING).buses, lambda b: out.append(b["b1"]), idcode=7734)
    return dec, out


def _t(out) -> np.ndarray:
    return np.concatenate([b.t for b in out]) if out else np.array([])


def _balanced_books(dec: StreamDecoder) -> None:
    assert dec.frames == dec.delivered + sum(dec.rejected.values())


def test_several_frames_per_read_and_frames_split_across_reads_give_the_same_frames():
    cfg, frames = _stream(40)
    whole = cfg + b"".join(frames)
    dec_a, out_a = _decoder()
    dec_a.feed(whole)
    dec_b, out_b = _decoder()
    for i in range(0, len(whole), 7):  # 7-byte reads: every frame is split, headers too
        dec_b.feed(whole[i: i + 7])
    assert len(_t(out_a)) == len(_t(out_b)) == 40
    np.testing.assert_array_equal(_t(out_a), _t(out_b))
    a, b = (np.concatenate([x.P for x in o]) for o in (out_a, out_b))
    np.testing.assert_array_equal(a, b)
    assert dec_a.counts()["bad_frames"] == dec_b.counts()["bad_frames"] == {}
    _balanced_books(dec_b)


def test_bus_quantities_follow_the_mapping_formula():
    cfg2 = config2(7734)
    frame, carried = data_frame(cfg2, T0, balanced(0))
    dec, out = _decoder()
    dec.feed(cfg2.convert2bytes() + frame.convert2bytes())
    b = out[0]
    va, vb, vc, i1 = carried
    v1 = (va + A * vb + A * A * vc) / 3
    s = 3 * v1 * np.conj(i1) / 100e6  # three-phase, 100 MVA base
    np.testing.assert_allclose([b.V[0], b.theta[0], b.P[0], b.Q[0]],
                               [abs(v1) / VLN, np.angle(v1), s.real, s.imag], rtol=1e-12)
    assert abs(b.V[0] - 1.02) < 1e-4 and abs(b.P[0] - 3 * 1.02 * VLN * 400 * np.cos(0.3) / 100e6) < 1e-3


def test_truncated_frame_bad_crc_and_garbage_are_counted_and_the_rest_delivered():
    cfg, frames = _stream(10)
    bad_crc = bytearray(frames[3])
    bad_crc[20] ^= 0xFF
    stream = cfg + b"".join(frames[:2]) + frames[2][:17] + bytes(bad_crc) + b"\x00garbage" + b"".join(frames[4:])
    dec, out = _decoder()
    for i in range(0, len(stream), 50):
        dec.feed(stream[i: i + 50])
    assert dec.bad_frames == {"truncated": 1, "bad_crc": 1}
    assert dec.skipped_bytes >= 8
    assert len(_t(out)) == 8  # frames 2 and 3 lost, each counted once as a bad frame
    _balanced_books(dec)


def test_data_before_configuration_is_counted_and_asks_for_one():
    cfg, frames = _stream(6)
    dec, out = _decoder()
    dec.feed(b"".join(frames[:3]))
    assert dec.rejected == {"no_config": 3} and dec.need_config and not out
    dec.feed(cfg + b"".join(frames[3:]))
    assert len(_t(out)) == 3 and not dec.need_config
    _balanced_books(dec)


def test_a_configuration_change_mid_stream_is_followed():
    cfg_a, frames_a = _stream(5)
    cfg_b, frames_b = _stream(5, start=5, polar=True)
    dec, out = _decoder()
    dec.feed(cfg_a + b"".join(frames_a) + cfg_b + b"".join(frames_b))
    assert dec.config_changes == 1 and dec.configs == 2
    assert len(_t(out)) == 10
    np.testing.assert_allclose(np.concatenate([b.V for b in out]), 1.02, rtol=2e-4)
    _balanced_books(dec)


def test_data_that_no_longer_fits_its_configuration_is_counted_as_such():
    cfg_a, frames_a = _stream(3)
    cfg_b, frames_b = _stream(3, start=3, polar=True)
    float_cfg = config2(7734, floating=True)
    float_frame = data_frame(float_cfg, T0 + 1, balanced(0))[0].convert2bytes()
    dec, out = _decoder()
    dec.feed(cfg_a + b"".join(frames_a) + float_frame)
    assert dec.rejected == {"size_mismatch": 1} and dec.need_config
    _balanced_books(dec)


def test_frames_off_the_configured_rate_are_counted():
    cfg2 = config2(7734, rate=25)
    cfg = cfg2.convert2bytes()
    frames = [data_frame(cfg2, T0 + k / 50, balanced(k))[0].convert2bytes() for k in range(20)]  # sent at 50/s
    dec, out = _decoder()
    dec.feed(cfg + b"".join(frames))
    assert dec.rejected == {"off_rate": 10}
    assert len(_t(out)) == 10
    _balanced_books(dec)


def test_stat_flags_and_time_quality_are_counted_and_data_errors_reach_validation():
    cfg2 = config2(7734)
    bad = ("error", False, "timestamp", True, False, False, 0, "<10", 0)
    frames = [data_frame(cfg2, T0 + k / 50, balanced(k), stat=bad if k % 2 else STAT_OK)[0] for k in range(4)]
    frames[0].set_frasec(0, time_quality=15)
    dec, out = _decoder()
    dec.feed(cfg2.convert2bytes() + b"".join(f.convert2bytes() for f in frames))
    assert dec.flags == {"data_error": 2, "not_sync": 2, "trigger": 2, "clock_failure": 1}
    stat = np.concatenate([b.stat for b in out])
    assert list((stat & c37.STAT_DATA_ERROR) != 0) == [False, True, False, True]  # validation rejects these


def test_a_connection_ending_inside_a_frame_counts_it_truncated():
    cfg, frames = _stream(2)
    dec, out = _decoder()
    dec.feed(cfg + frames[0] + frames[1][:20])
    dec.end()
    assert dec.bad_frames == {"truncated": 1} and len(_t(out)) == 1


def _cfg3_body() -> bytes:
    """A one-PMU CFG-3 body written by hand from C37.118.2-2011 Table 10 (after CONT_IDX)."""
    def name(s: str) -> bytes:
        return bytes([len(s)]) + s.encode()

    parts = [struct.pack(">IH", 1_000_000, 1), name("Sub 7"), struct.pack(">H", 42), b"\x00" * 16,
             struct.pack(">HHHH", 0x0000, 2, 0, 0), name("V1"), name("I1"),
             struct.pack(">HBBff", 0, 0x01, 0, 10.0, 0.0),  # voltage, positive sequence, 10 V per count
             struct.pack(">HBBff", 0, 0x09, 0, 0.5, 0.1),  # current, positive sequence, 0.5 A, +0.1 rad
             struct.pack(">fffB", 35.0, -85.0, 100.0, ord("M")), struct.pack(">ii", 40000, 20000),
             struct.pack(">HH", 0, 3), struct.pack(">h", 60)]
    return b"".join(parts)


def test_cfg3_whole_and_in_fragments():
    body = _cfg3_body()
    whole = c37.build(c37.CFG3, 42, 0, 0, struct.pack(">H", 0) + body, version=2)
    asm = c37.Cfg3Assembler()
    cfg = c37.parse_config(asm.add(c37.parse(whole)))
    p = cfg.pmus[0]
    assert (p.station, p.idcode, p.fnom, p.cfgcnt, cfg.data_rate) == ("Sub 7", 42, 60.0, 3, 60.0)
    assert [(ph.name, ph.kind, ph.scale, ph.component) for ph in p.phasors] == [("V1", 0, 10.0, 1), ("I1", 1, 0.5, 1)]
    assert p.phasors[1].angle == pytest.approx(0.1)
    half = len(body) // 2
    first = c37.parse(c37.build(c37.CFG3, 42, 0, 0, struct.pack(">H", 1) + body[:half], version=2))
    last = c37.parse(c37.build(c37.CFG3, 42, 0, 0, struct.pack(">H", 0xFFFF) + body[half:], version=2))
    assert asm.add(first) is None
    assert c37.parse_config(asm.add(last)).pmus == cfg.pmus
    # integer rectangular data of that configuration: scale Y, then the angle adjustment
    data = c37.build(c37.DATA, 42, 1, 0, struct.pack(">H4hhh", 0, 100, 0, 20, 0, 0, 0))
    _, _, (block,) = cfg.decode_data(data)
    np.testing.assert_allclose(block.phasors[0], [1000.0, 10.0 * np.exp(0.1j)])
    assert block.freq[0] == 60.0


def test_own_encoder_round_trips_several_pmus():
    pmus = [c37.PmuConfig(f"P{k}", 100 + k, fmt, [c37.Phasor("V", 0, 2.0), c37.Phasor("I", 1, 0.05)], [], 0,
                          60.0, 0) for k, fmt in enumerate((0x0, 0x1, 0xF))]
    cfg = c37.Config(9, 1_000_000, pmus, 60.0)
    back = c37.parse_config(c37.parse(c37.encode_config(cfg)))
    assert back.pmus == cfg.pmus and back.data_rate == 60.0
    z = [np.array([60000 + 100j, 300 - 20j])] * 3
    frame = c37.encode_data(cfg, T0 + 0.5, [0, 0, 0], z, [60.01] * 3, [0.0] * 3)
    t, _, blocks = back.decode_data(frame)
    assert t[0] == pytest.approx(T0 + 0.5)
    for b in blocks:
        np.testing.assert_allclose(b.phasors[0], z[0], rtol=2e-4, atol=2.0)
        assert b.freq[0] == pytest.approx(60.01, abs=1e-4)


def test_positive_sequence_of_balanced_phases_is_phase_a():
    va = 1000 * np.exp(0.2j)
    np.testing.assert_allclose(positive_sequence(np.array([[va, va * A * A, va * A]])), [va])


@pytest.mark.parametrize("bad, message", [
    ({}, "no \\[buses"),
    ({"buses": {"x": {"pmu": 1, "voltage": "V"}}}, "missing current, base_kv"),
    ({"buses": {"x": {"pmu": 1, "voltage": ["V", "W"], "current": "I", "base_kv": 1}}}, "list of three"),
    ({"buses": {"x": {"pmu": 1, "voltage": "V", "current": "I", "base_kv": 1, "kv": 2}}}, "unknown key"),
])
def test_mapping_errors_name_the_bus_and_key(bad, message):
    with pytest.raises(MappingError, match=message):
        parse_mapping(bad)


def test_the_c37118_source_needs_a_mapping_file_in_the_settings(tmp_path):
    from service.settings import SettingsError, load_settings

    with pytest.raises(SettingsError, match="pmu_mapping"):
        load_settings(sources=["c37118"], storage_url=str(tmp_path / "x.sqlite"))
    path = tmp_path / "pdc.toml"
    path.write_text('[c37118]\nport = 4712\nidcode = 7\n[buses.b]\npmu = 7\nvoltage = "V"\ncurrent = "I"\nbase_kv = 1\n')
    settings = load_settings(sources=["c37118"], pmu_mapping=str(path), storage_url=str(tmp_path / "x.sqlite"))
    from service.sources.c37118 import load

    stream, mapping = load(settings.pmu_mapping)
    assert (stream.port, stream.idcode, stream.transport, [b.bus for b in mapping.buses]) == (4712, 7, "tcp", ["b"])
