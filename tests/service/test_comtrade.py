"""COMTRADE files written by hand per IEEE C37.111 (1999 .cfg/.dat ASCII and binary, 2013 .cff) read back
through the bus mapping: waveforms to phasors, phasor channels, and ``aslm identify`` on a recording."""

from __future__ import annotations

import datetime as dt
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from conftest import D_TRUE

from service.protocols.mapping import parse_mapping
from service.readers.comtrade import ComtradeReadError, comtrade_window

pytest.importorskip("comtrade")

START = dt.datetime(2026, 3, 1, 12, 0, 0, tzinfo=dt.timezone.utc)
VLN = 230e3 / np.sqrt(3)
A = np.exp(2j * np.pi / 3)
WAVE_BUS = {"pmu": 1, "voltage": ["VA", "VB", "VC"], "current": [["IA", "IB", "IC"]], "base_kv": 230.0}


def write_comtrade(stem: Path, names: list[str], units: list[str], data: np.ndarray, fs: float, *,
                   fmt: str = "ASCII", rev: str = "1999", f0: float = 50.0) -> Path:
    """Write ``data`` (channels × samples) per C37.111: .cfg + .dat, or one .cff for rev 2013 with fmt."""
    n_ch, n = data.shape
    if fmt == "BINARY":
        a = np.abs(data).max(axis=1) / 30000.0
        a[a == 0] = 1.0
    else:
        a = np.ones(n_ch)
    lines = [f"test station,aslm,{rev}", f"{n_ch},{n_ch}A,0D"]
    for k, (name, unit) in enumerate(zip(names, units, strict=True)):
        lines.append(f"{k + 1},{name},,,{unit},{float(a[k])!r},0.0,0.0,-32767,32767,1.0,1.0,P")
    stamp = START.strftime("%d/%m/%Y,%H:%M:%S.%f")
    lines += [f"{f0:g}", "1", f"{fs:g},{n}", stamp, stamp, fmt, "1"]
    if rev == "2013":
        lines += ["0,0", "0,0"]
    cfg = "\r\n".join(lines) + "\r\n"
    us = np.round(np.arange(n) / fs * 1e6).astype(np.int64)
    if fmt == "ASCII":
        dat = "".join(f"{i + 1},{us[i]}," + ",".join(repr(float(v)) for v in data[:, i]) + "\r\n"
                      for i in range(n)).encode()
    else:
        counts = np.round(data / a[:, None]).astype("<i2")
        dat = b"".join(struct.pack("<II", i + 1, int(us[i])) + counts[:, i].tobytes() for i in range(n))
    if rev == "2013":
        kind = "ASCII" if fmt == "ASCII" else "BINARY"
        body = (f"--- file type: CFG ---\r\n{cfg}--- file type: INF ---\r\n--- file type: HDR ---\r\n"
                f"--- file type: DAT {kind}: {len(dat)} ---\r\n").encode() + dat
        path = stem.with_suffix(".cff")
        path.write_bytes(body)
        return path
    stem.with_suffix(".cfg").write_text(cfg, newline="")
    stem.with_suffix(".dat").write_bytes(dat)
    return stem.with_suffix(".cfg")


def waveforms(v_rms: float, theta: float, i_rms: float, phi: float, fs: float, seconds: float, f0: float = 50.0):
    t = np.arange(int(round(seconds * fs))) / fs
    out = []
    for mag, ang in ((v_rms, theta), (i_rms, phi)):
        for shift in (0.0, -2 * np.pi / 3, 2 * np.pi / 3):
            out.append(np.sqrt(2) * mag * np.cos(2 * np.pi * f0 * t + ang + shift))  # START: a whole second
    return np.array(out)


@pytest.mark.parametrize("fmt, rev", [("ASCII", "1999"), ("BINARY", "1999"), ("ASCII", "2013"), ("BINARY", "2013")])
def test_waveforms_give_the_phasors_and_power_they_carry(tmp_path, fmt, rev):
    v, th, i, phi = 1.01 * VLN, 0.2, 500.0, 0.2 - 0.35
    data = waveforms(v, th, i, phi, fs=1000.0, seconds=1.0)
    path = write_comtrade(tmp_path / "rec", ["VA", "VB", "VC", "IA", "IB", "IC"], ["V"] * 3 + ["A"] * 3, data,
                          1000.0, fmt=fmt, rev=rev)
    bus = parse_mapping({"buses": {"feeder": WAVE_BUS}}).buses[0]
    w = comtrade_window(path, bus)
    s = 3 * v * i * np.exp(1j * (th - phi)) / 100e6
    tol = 2e-5 if fmt == "ASCII" else 2e-4  # ASCII: the package's sample times; binary: 16-bit counts
    assert w.t.size == 50 - 1 + 1 and w.bus == "feeder" and w.f0 == 50.0
    np.testing.assert_allclose(w.V, 1.01, rtol=tol)
    np.testing.assert_allclose(w.theta, th, atol=tol)
    np.testing.assert_allclose(w.P, s.real, rtol=tol)
    np.testing.assert_allclose(w.Q, s.imag, rtol=tol)
    assert w.t[0] == pytest.approx(START.timestamp() + 0.019, abs=1e-9)  # end of the first whole cycle


def test_kilovolts_and_missing_channels(tmp_path):
    data = waveforms(VLN, 0.0, 100.0, 0.0, fs=1000.0, seconds=0.2)
    data[:3] /= 1e3
    path = write_comtrade(tmp_path / "kv", ["VA", "VB", "VC", "IA", "IB", "IC"], ["kV"] * 3 + ["A"] * 3, data, 1000.0)
    bus = parse_mapping({"buses": {"feeder": WAVE_BUS}}).buses[0]
    np.testing.assert_allclose(comtrade_window(path, bus).V, 1.0, rtol=1e-7)
    other = parse_mapping({"buses": {"x": {**WAVE_BUS, "voltage": "V1"}}}).buses[0]
    with pytest.raises(ComtradeReadError, match="no channel 'V1'.*VA, VB"):
        comtrade_window(path, other)


def test_aslm_identify_reads_a_phasor_recording_through_the_mapping(tmp_path, eq_window, capsys):
    from service.cli import main

    w = eq_window
    v = w.V * VLN * np.exp(1j * w.theta)
    i = np.conj((w.P + 1j * w.Q) * 100e6 / (3 * v))
    data = np.array([np.abs(v), np.rad2deg(np.angle(v)), np.abs(i), np.rad2deg(np.angle(i))])
    path = write_comtrade(tmp_path / "pmu", ["V1_mag", "V1_ang", "I1_mag", "I1_ang"], ["V", "deg", "A", "deg"],
                          data, 100.0, rev="2013")
    mapping = tmp_path / "map.toml"
    mapping.write_text('[buses.eq]\npmu = 1\nvoltage = "V1"\ncurrent = "I1"\nbase_kv = 230.0\n')
    assert main(["identify", str(path), "--mapping", str(mapping), "--json", "--lowpass", "2"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    d = np.array([out["dynamic"][k] for k in ("a", "b", "H2", "Tm")])
    assert np.all(np.abs(d / D_TRUE - 1) < 0.05), d
