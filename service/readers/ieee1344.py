"""IEEE Std 1344-1995 frames (the predecessor of C37.118) from a capture file, and their re-encoding as
C37.118.2 so that a recording can be replayed through the C37.118 path.

IEEE 1344 frames have no SYNC word; every frame starts with::

    SOC(4)     seconds since 1900-01-01 (not 1970)
    SAMPLE(2)  bits 15-13 frame type (000 data, 010 configuration, 001 header), 12-0 sample count
    STATUS(2)  flags; bits 10-0 the frame length in bytes (data and configuration frames)

and ends with the same CRC-CCITT as C37.118.  A configuration frame then holds the station name (16),
a 64-bit IDCODE, the phasor and digital counts, 16-byte channel names, PHUNIT words (byte 0: 0 voltage,
1 current; bytes 1-3: scale × 1e-5 V or A per count), DIGUNIT, and the reporting PERIOD in hundredths of
a nominal cycle.  A data frame holds 16-bit integer rectangular phasors, FREQ (deviation, mHz), DFREQ
(ROCOF × 100) and the digital words.

Time within the second: the sample count advances by the same step each frame and wraps each second,
so a frame's time is SOC + count / (step × frames per second).  This is read from the recording itself
(the 2007 Shelby capture steps by 40 at 30 frames/s), not from the standard's text.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from service.protocols import c37118 as c37

EPOCH_1900 = 2_208_988_800  # seconds from 1900-01-01 to 1970-01-01
DATA, HEADER, CONFIG = 0, 1, 2


class Ieee1344Error(ValueError):
    """A capture that is not a sequence of IEEE 1344 frames."""


@dataclass
class Capture1344:
    """A decoded IEEE 1344 recording: its configuration and its data as arrays over frames."""

    station: str
    idcode: int
    phasors: list[c37.Phasor]
    digitals: list[str]
    fnom: float
    rate: float  # frames/s
    t: np.ndarray  # UTC since 1970 [s]
    values: np.ndarray  # complex (frames, phasors) [V, A]
    counts: np.ndarray  # int16 (frames, phasors, 2): the raw rectangular counts
    freq: np.ndarray  # Hz
    dfreq: np.ndarray  # Hz/s
    digital: np.ndarray  # uint16 (frames, digitals)
    bad: dict[str, int] = field(default_factory=dict)


def _crc_ok(frame: bytes) -> bool:
    return c37.crc_ccitt(frame[:-2]) == struct.unpack_from(">H", frame, len(frame) - 2)[0]


def _config(frame: bytes) -> tuple:
    station = frame[8:24].decode("latin-1").strip("\x00 ")
    idcode = struct.unpack_from(">Q", frame, 24)[0]
    nph, ndg = struct.unpack_from(">HH", frame, 32)
    off = 36
    names = [frame[off + 16 * i: off + 16 * (i + 1)].decode("latin-1").strip("\x00 ") for i in range(nph + ndg)]
    off += 16 * (nph + ndg)
    units = struct.unpack_from(f">{nph}I", frame, off)
    # DIGUNIT, then FNOM (bit 0: 1 = 50 Hz) and PERIOD: 2 bytes a digital word is what the frame's
    # length leaves for DIGUNIT in the Shelby recording (one digital word, 160-byte frame)
    off += 4 * nph + 2 * ndg
    fnom_word, period = struct.unpack_from(">HH", frame, off)
    fnom = 50.0 if fnom_word & 1 else 60.0
    phasors = [c37.Phasor(names[i], c37.CURRENT if u >> 24 == 1 else c37.VOLTAGE, (u & 0xFFFFFF) * 1e-5)
               for i, u in enumerate(units)]
    return station, idcode, phasors, names[nph:], fnom, fnom * 100.0 / period


def read_1344(path: str | Path) -> Capture1344:
    """Read a capture of IEEE 1344 frames (a configuration frame, then data frames, back to back).

    Frames with a wrong CRC are skipped and counted in ``bad``.

    Raises
    ------
    Ieee1344Error
        No configuration frame before the data, or a frame length that does not fit the file.
    """
    raw = Path(path).read_bytes()
    pos, cfg, bad = 0, None, {"bad_crc": 0, "no_config": 0}
    rows: list[bytes] = []
    while pos + 8 <= len(raw):
        soc, sample, status = struct.unpack_from(">IHH", raw, pos)
        ftype = sample >> 13
        size = status & 0x07FF
        if size < 10 or pos + size > len(raw):
            raise Ieee1344Error(f"{path}: frame at byte {pos} announces {size} bytes; {len(raw) - pos} left")
        frame = raw[pos: pos + size]
        pos += size
        if not _crc_ok(frame):
            bad["bad_crc"] += 1
            continue
        if ftype == CONFIG:
            cfg = _config(frame)
        elif ftype == DATA:
            if cfg is None:
                bad["no_config"] += 1
                continue
            rows.append(frame)
    if cfg is None:
        raise Ieee1344Error(f"{path}: no IEEE 1344 configuration frame")
    station, idcode, phasors, digitals, fnom, rate = cfg
    nph, ndg = len(phasors), len(digitals)
    dt = np.dtype([("soc", ">u4"), ("sample", ">u2"), ("status", ">u2"), ("ph", ">i2", (nph, 2)),
                   ("freq", ">i2"), ("dfreq", ">i2"), ("dg", ">u2", (ndg,)), ("chk", ">u2")])
    sizes = {len(r) for r in rows}
    if sizes and sizes != {dt.itemsize}:
        raise Ieee1344Error(f"{path}: data frames of {sorted(sizes)} bytes; the configuration gives {dt.itemsize}")
    rec = np.frombuffer(b"".join(rows), dtype=dt)
    count = (rec["sample"] & 0x1FFF).astype(np.int64)
    step = _sample_step(count)
    t = rec["soc"].astype(np.float64) - EPOCH_1900 + count / (step * rate)
    scale = np.array([p.scale for p in phasors])
    values = (rec["ph"][..., 0] + 1j * rec["ph"][..., 1].astype(np.float64)) * scale
    return Capture1344(station, int(idcode), phasors, digitals, fnom, rate, t, values, rec["ph"].astype(np.int16),
                       fnom + rec["freq"] * 1e-3, rec["dfreq"] * 1e-2, rec["dg"].astype(np.uint16),
                       {k: v for k, v in bad.items() if v})


def _sample_step(count: np.ndarray) -> int:
    d = np.diff(count)
    d = d[d > 0]
    return int(np.bincount(d).argmax()) if d.size else 1


def to_c37118(cap: Capture1344, idcode: int = 1, t_offset: float = 0.0) -> tuple[c37.Config, list[bytes]]:
    """The recording as a C37.118.2 stream: a CFG-2 and one data frame per recorded frame.

    Phasors stay 16-bit rectangular integers with the recording's PHUNIT scales, so the counts are the
    PMU's own; ``t_offset`` [s] re-stamps the frames (to replay an old recording as live data).
    """
    pmu = c37.PmuConfig(cap.station[:16], idcode, 0x0, list(cap.phasors), [], len(cap.digitals), cap.fnom, 0,
                        digital_names=[*cap.digitals, *[""] * (16 * len(cap.digitals) - len(cap.digitals))])
    cfg = c37.Config(idcode, 1_000_000, [pmu], cap.rate)
    frames = []
    for k in range(cap.t.size):
        t = cap.t[k] + t_offset
        soc = int(math.floor(t))
        frac = min(round((t - soc) * 1e6), 999_999)
        fr = round((cap.freq[k] - cap.fnom) * 1e3)
        body = (struct.pack(">H", 0) + cap.counts[k].astype(">i2").tobytes()
                + struct.pack(">hh", fr, round(cap.dfreq[k] * 1e2)) + cap.digital[k].astype(">u2").tobytes())
        frames.append(c37.build(c37.DATA, idcode, soc, frac, body))
    return cfg, frames
