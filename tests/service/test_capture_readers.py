"""The capture readers on the two real recordings in ../shared/data/real/.

The IEEE 1344 recording is checked against what its README states; the C37.118 pcap against the Zeek
analyser's independent decoding of every data frame (its test baselines, rows sorted, times masked).
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest

from service.protocols import c37118 as c37
from service.protocols.c37118_stream import StreamDecoder
from service.protocols.mapping import parse_mapping
from service.protocols.pmu_server import restamp
from service.readers.ieee1344 import read_1344, to_c37118
from service.readers.pcap import PcapError, pmu_payload, streams

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"
SHELBY = REAL / "tva-shelby-2007-ieee1344.PmuCapture"
PCAP = REAL / "c37118-1pmu-tcp.pcap"

pytestmark = pytest.mark.skipif(not SHELBY.is_file() or not PCAP.is_file(), reason="real recordings not present")


def test_the_1344_recording_reads_as_its_readme_says():
    cap = read_1344(SHELBY)
    assert (cap.station, cap.idcode, cap.fnom, cap.rate, cap.bad) == ("Shelby", 2, 60.0, 30.0, {})
    assert [p.name for p in cap.phasors] == ["Bus 1", "Bus 2", "Cordova", "Dell", "Lagoon Creek"]
    assert [round(p.scale, 5) for p in cap.phasors] == [24.66979, 24.66979, 0.36621, 0.54931, 0.54931]
    assert cap.t.size == 973
    assert dt.datetime.fromtimestamp(cap.t[0], dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S") == "2007-04-26 19:15:12"
    np.testing.assert_allclose(np.diff(cap.t), 1 / 30, atol=1e-6)  # no gap, no repeat
    assert abs(np.abs(cap.values[:, 0]).mean() - 299.6e3) < 1e3
    flows = [3 * cap.values[:, 0] * np.conj(cap.values[:, j]) / 1e6 for j in (2, 3, 4)]
    means = [complex(np.round(f.mean())) for f in flows]
    assert means == [-210 - 33j, 462 - 4j, 125 + 146j]  # MW, Mvar as the README states


def test_the_1344_recording_as_c37118_carries_the_same_counts_and_times():
    cap = read_1344(SHELBY)
    cfg, frames = to_c37118(cap, idcode=2, t_offset=0.0)
    back = c37.parse_config(c37.parse(c37.encode_config(cfg)))
    t, _, (block,) = back.decode_data(b"".join(frames))
    np.testing.assert_array_equal(block.phasors, cap.values)
    np.testing.assert_allclose(t, cap.t, atol=1e-6)
    np.testing.assert_allclose(block.freq, cap.freq, atol=1e-9)
    moved = c37.parse(restamp(frames[0], 2e9 + 0.5, cfg.time_base))  # CRC redone
    assert (moved.soc, moved.fracsec & 0xFFFFFF) == (2_000_000_000, 500_000)


def _zeek_rows(path: Path) -> list[dict[str, str]]:
    lines = path.read_text().splitlines()
    fields = next(line for line in lines if line.startswith("#fields")).split("\t")[1:]
    return [dict(zip(fields, line.split("\t"), strict=True)) for line in lines if not line.startswith("#")]


def test_the_c37118_pcap_decodes_to_the_zeek_analysers_values():
    payload = pmu_payload(PCAP, 4712)
    mapping = parse_mapping({"buses": {"blue": {"pmu": 241, "voltage": "V1LPM", "current": "VALPM", "base_kv": 1}}})
    dec = StreamDecoder(mapping.buses, lambda batches: None, idcode=241)
    dec.feed(payload)
    assert dec.counts()["bad_frames"] == {} and dec.skipped_bytes == 0 and dec.frames == dec.delivered == 252
    assert dec.flags == {"trigger": 252}  # the analyser too reads the trigger bit set in every frame
    cfg = dec.cfg.pmus[0]
    zcfg = _zeek_rows(REAL / "c37118-1pmu-tcp.zeek-cfg.log")[0]
    assert cfg.station == zcfg["station_name"] and str(cfg.idcode) == zcfg["data_source_id"]
    assert ",".join(p.name for p in cfg.phasors) == zcfg["phnam"] and str(cfg.cfgcnt) == zcfg["cfgcnt"]
    data, pos = [], 0
    while True:
        off, size = c37.split(payload, pos)
        if not size or off + size > len(payload):
            break
        if c37.parse(payload[off: off + size]).ftype == c37.DATA:
            data.append(payload[off: off + size])
        pos = off + size
    _, _, (block,) = dec.cfg.decode_data(b"".join(data))
    ours = sorted(tuple(np.round(np.concatenate([row.real, row.imag]), 3)) for row in block.phasors)
    zeek = sorted(tuple(np.round([float(x) for x in (r["est_rectangular_real"] + "," + r["est_rectangular_imaginary"])
                                  .split(",")], 3)) for r in _zeek_rows(REAL / "c37118-1pmu-tcp.zeek-data.log"))
    assert len(ours) == len(zeek) == 252
    np.testing.assert_allclose(np.array(ours), np.array(zeek), atol=2e-3)


def test_pcap_reader_sees_both_directions_and_refuses_other_files(tmp_path):
    flows = streams(PCAP)
    assert {(k[1], k[3]) for k in flows} == {(36835, 4712), (4712, 36835)}
    commands = c37.parse(flows[("192.168.0.20", 36835, "192.168.0.241", 4712)].payload()[:18])
    assert commands.ftype == c37.COMMAND
    bad = tmp_path / "x.pcap"
    bad.write_bytes(b"\x0a\x0d\x0d\x0a" + bytes(60))
    with pytest.raises(PcapError, match="pcapng"):
        streams(bad)
