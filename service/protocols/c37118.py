"""IEEE C37.118.2 frames: configuration (CFG-1/2/3), data, command and header frames, encoded and decoded.

Written from the standard (C37.118.2-2011, clause 6) and checked against independent implementations in
the tests; nothing here does I/O.  Data frames of one configuration have a fixed layout, so a run of them
is decoded by one numpy structured-dtype view (:meth:`Config.decode_data`), which is what lets one core
follow a PDC stream of hundreds of PMUs.

Every frame::

    SYNC(2) FRAMESIZE(2) IDCODE(2) SOC(4) FRACSEC(4) ... CHK(2)

SYNC is 0xAA then (frame type << 4 | version); FRACSEC's top byte is the time-quality flags and its low
24 bits the fraction of a second in units of 1/TIME_BASE; CHK is CRC-CCITT (polynomial 0x1021, initial
0xFFFF, no reflection) over everything before it.
"""

from __future__ import annotations

import binascii
import math
import struct
from dataclasses import dataclass, field

import numpy as np

SYNC_BYTE = 0xAA
DATA, HEADER, CFG1, CFG2, COMMAND, CFG3 = 0, 1, 2, 3, 4, 5
FRAME_NAMES = {DATA: "data", HEADER: "header", CFG1: "cfg1", CFG2: "cfg2", COMMAND: "command", CFG3: "cfg3"}
CMD_DATA_OFF, CMD_DATA_ON, CMD_HEADER, CMD_CFG1, CMD_CFG2, CMD_CFG3 = 1, 2, 3, 4, 5, 6

PREFIX = struct.Struct(">BBHHII")  # sync, type|version, framesize, idcode, soc, fracsec
HEAD_SIZE = PREFIX.size  # 14
MIN_FRAME = HEAD_SIZE + 2
MAX_FRAME = 65535

# STAT bits (C37.118.2-2011 Table 7)
STAT_DATA_ERROR = 0xC000  # 15-14: 01 PMU error, 10 test mode, 11 PMU error (invalid data)
STAT_NOT_SYNC = 0x2000  # 13: PMU not synchronised to UTC
STAT_BY_ARRIVAL = 0x1000  # 12: data sorted by arrival, not by time stamp
STAT_TRIGGER = 0x0800  # 11: PMU trigger detected
STAT_CFG_CHANGE = 0x0400  # 10: configuration will change within a minute
STAT_FLAGS = {"data_error": STAT_DATA_ERROR, "not_sync": STAT_NOT_SYNC, "sorted_by_arrival": STAT_BY_ARRIVAL,
              "trigger": STAT_TRIGGER, "cfg_change": STAT_CFG_CHANGE}
TQ_FAULT = 0xF  # FRACSEC time-quality code: clock failure, time not reliable

VOLTAGE, CURRENT = 0, 1


class C37Error(ValueError):
    """Bytes that are not a valid frame; ``reason`` is the counter label."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(f"{reason}: {message}")
        self.reason = reason


def crc_ccitt(data: bytes | memoryview) -> int:
    """CRC-CCITT of C37.118 (polynomial 0x1021, initial 0xFFFF): ``binascii.crc_hqx`` runs it in C."""
    return binascii.crc_hqx(data, 0xFFFF)


@dataclass(frozen=True)
class Frame:
    """One checked frame: its common header and the bytes between the header and CHK."""

    ftype: int
    version: int
    idcode: int
    soc: int
    fracsec: int
    body: bytes

    @property
    def time_quality(self) -> int:
        """FRACSEC time-quality code (bits 27-24; 0 locked, 0xF clock failure)."""
        return (self.fracsec >> 24) & 0x0F


def split(buf: bytes | bytearray | memoryview, start: int = 0) -> tuple[int, int]:
    """Locate the next frame in ``buf`` from ``start``.

    Returns
    -------
    offset, size : int
        Offset of the SYNC byte and the frame's FRAMESIZE; ``size`` is 0 when no complete header is there
        yet.  Bytes before ``offset`` are not a frame start (the caller counts them as skipped).
    """
    n = len(buf)
    i = start
    while i < n:
        if buf[i] != SYNC_BYTE:
            j = bytes(buf[i:]).find(SYNC_BYTE)
            if j < 0:
                return n, 0
            i += j
        if i + 4 > n:
            return i, 0
        kind = (buf[i + 1] >> 4) & 0x7
        size = (buf[i + 2] << 8) | buf[i + 3]
        if buf[i + 1] & 0x80 or kind not in FRAME_NAMES or size < MIN_FRAME:
            i += 1  # 0xAA inside garbage: resynchronise on the next one
            continue
        return i, size
    return n, 0


def parse(frame: bytes | memoryview) -> Frame:
    """Check and split one whole frame (exactly FRAMESIZE bytes).

    Raises
    ------
    C37Error
        ``bad_sync``, ``bad_size`` or ``bad_crc``.
    """
    if len(frame) < MIN_FRAME:
        raise C37Error("bad_size", f"{len(frame)} bytes")
    sync, tv, size, idcode, soc, fracsec = PREFIX.unpack_from(frame, 0)
    if sync != SYNC_BYTE:
        raise C37Error("bad_sync", f"first byte {sync:#04x}")
    if size != len(frame):
        raise C37Error("bad_size", f"FRAMESIZE {size}, {len(frame)} bytes")
    (chk,) = struct.unpack_from(">H", frame, size - 2)
    if crc_ccitt(frame[: size - 2]) != chk:
        raise C37Error("bad_crc", f"frame type {(tv >> 4) & 7} of {idcode}")
    return Frame((tv >> 4) & 7, tv & 0x0F, idcode, soc, fracsec, bytes(frame[HEAD_SIZE: size - 2]))


def build(ftype: int, idcode: int, soc: int, fracsec: int, body: bytes, version: int = 1) -> bytes:
    """A whole frame around ``body`` with FRAMESIZE and CHK filled in."""
    size = HEAD_SIZE + len(body) + 2
    if size > MAX_FRAME:
        raise C37Error("bad_size", f"{size} bytes is over the 65535 a frame can hold")
    head = PREFIX.pack(SYNC_BYTE, (ftype << 4) | version, size, idcode, soc, fracsec)
    raw = head + body
    return raw + struct.pack(">H", crc_ccitt(raw))


def command(idcode: int, cmd: int, soc: int = 0, fracsec: int = 0) -> bytes:
    """A command frame (``CMD_DATA_ON``, ``CMD_CFG2``, ...)."""
    return build(COMMAND, idcode, soc, fracsec, struct.pack(">H", cmd))


@dataclass
class Phasor:
    """One phasor channel: its name, voltage or current, and how to scale it to volts or amperes."""

    name: str
    kind: int = VOLTAGE
    scale: float = 1.0  # per count of integer data (PHUNIT × 1e-5, or CFG-3's Y) [V or A]
    angle: float = 0.0  # CFG-3 angle adjustment θ [rad]
    component: int | None = None  # CFG-3 phasor component code (1 positive sequence, 4-6 phase A-C)


@dataclass
class PmuConfig:
    """One PMU (or data stream) block of a configuration frame."""

    station: str
    idcode: int
    fmt: int
    phasors: list[Phasor]
    analogs: list[str]
    digitals: int
    fnom: float
    cfgcnt: int
    analog_scale: list[float] = field(default_factory=list)
    digital_names: list[str] = field(default_factory=list)

    @property
    def polar(self) -> bool:
        return bool(self.fmt & 0x1)

    @property
    def phasor_float(self) -> bool:
        return bool(self.fmt & 0x2)

    @property
    def analog_float(self) -> bool:
        return bool(self.fmt & 0x4)

    @property
    def freq_float(self) -> bool:
        return bool(self.fmt & 0x8)

    def block_size(self) -> int:
        """Bytes of this PMU's block in a data frame."""
        ph = 8 if self.phasor_float else 4
        return (2 + ph * len(self.phasors) + (8 if self.freq_float else 4)
                + (4 if self.analog_float else 2) * len(self.analogs) + 2 * self.digitals)

    def phasor_index(self, name: str) -> int:
        """Index of the phasor called ``name`` (KeyError naming the ones there are)."""
        for i, ph in enumerate(self.phasors):
            if ph.name == name:
                return i
        raise KeyError(f"PMU {self.station!r} ({self.idcode}) has no phasor {name!r}; it has "
                       f"{', '.join(p.name for p in self.phasors)}")


@dataclass
class DataBlock:
    """Decoded data frames of one configuration, for one PMU block, as arrays over frames."""

    stat: np.ndarray  # uint16
    phasors: np.ndarray  # complex128 (frames, phasors), primary volts / amperes
    freq: np.ndarray  # Hz
    dfreq: np.ndarray  # Hz/s
    analogs: np.ndarray  # float64 (frames, analogs)


@dataclass
class Config:
    """A configuration frame (CFG-1, CFG-2 or CFG-3): the stream's layout and scaling."""

    idcode: int
    time_base: int
    pmus: list[PmuConfig]
    data_rate: float  # frames/s
    kind: int = CFG2
    _dtype: np.dtype | None = field(default=None, init=False, repr=False)

    @property
    def data_size(self) -> int:
        """FRAMESIZE of this configuration's data frames."""
        return HEAD_SIZE + sum(p.block_size() for p in self.pmus) + 2

    def pmu(self, key: int | str) -> PmuConfig:
        """The PMU block with this IDCODE (int) or station name (str)."""
        for p in self.pmus:
            if p.idcode == key or p.station == key:
                return p
        raise KeyError(f"no PMU {key!r} in the configuration of stream {self.idcode}; it has "
                       f"{', '.join(f'{p.station} ({p.idcode})' for p in self.pmus)}")

    def dtype(self) -> np.dtype:
        """Structured big-endian dtype of a whole data frame of this configuration."""
        if self._dtype is None:
            fields: list[tuple] = [("head", "V14")]
            for k, p in enumerate(self.pmus):
                fields.append((f"stat{k}", ">u2"))
                if p.phasors and (p.phasor_float or not p.polar):
                    fields.append((f"ph{k}", ">f4" if p.phasor_float else ">i2", (len(p.phasors), 2)))
                elif p.phasors:  # integer polar: unsigned magnitude, signed angle in 1e-4 rad
                    fields.append((f"ph{k}", [("mag", ">u2"), ("ang", ">i2")], (len(p.phasors),)))
                ff = ">f4" if p.freq_float else ">i2"
                fields += [(f"freq{k}", ff), (f"dfreq{k}", ff)]
                if p.analogs:
                    fields.append((f"an{k}", ">f4" if p.analog_float else ">i2", (len(p.analogs),)))
                if p.digitals:
                    fields.append((f"dg{k}", ">u2", (p.digitals,)))
            fields.append(("chk", ">u2"))
            self._dtype = np.dtype(fields)
            assert self._dtype.itemsize == self.data_size
        return self._dtype

    def decode_data(self, frames: bytes) -> tuple[np.ndarray, np.ndarray, list[DataBlock]]:
        """Decode back-to-back data frames of this configuration (CRC already checked).

        Returns
        -------
        t : ndarray of float64
            Frame times, UTC since the epoch [s].
        time_quality : ndarray of uint8
            FRACSEC time-quality codes.
        blocks : list of DataBlock
            One per PMU of the configuration, in order.
        """
        rec = np.frombuffer(frames, dtype=self.dtype())
        head = np.frombuffer(frames, dtype=np.dtype([("x", "V6"), ("soc", ">u4"), ("frac", ">u4"),
                                                       ("rest", f"V{self.data_size - 14}")]))
        frac = head["frac"]
        t = head["soc"].astype(np.float64) + (frac & 0xFFFFFF).astype(np.float64) / self.time_base
        blocks = []
        for k, p in enumerate(self.pmus):
            blocks.append(self._block(rec, k, p))
        return t, (frac >> 24).astype(np.uint8) & 0x0F, blocks

    def _block(self, rec: np.ndarray, k: int, p: PmuConfig) -> DataBlock:
        n = rec.shape[0]
        if p.phasors:
            raw = rec[f"ph{k}"]
            if p.phasor_float:
                a, b = raw[..., 0].astype(np.float64), raw[..., 1].astype(np.float64)
            elif p.polar:
                a, b = raw["mag"].astype(np.float64), raw["ang"].astype(np.float64) * 1e-4
            else:
                a, b = raw[..., 0].astype(np.float64), raw[..., 1].astype(np.float64)
            if p.polar:
                z = a * np.exp(1j * b)
            else:
                z = a + 1j * b
            if not p.phasor_float:
                z = z * np.array([ph.scale for ph in p.phasors])
            adj = np.array([ph.angle for ph in p.phasors])
            if adj.any():
                z = z * np.exp(1j * adj)
        else:
            z = np.zeros((n, 0), complex)
        fr, dfr = rec[f"freq{k}"].astype(np.float64), rec[f"dfreq{k}"].astype(np.float64)
        if not p.freq_float:
            # integer FREQ is the deviation from nominal in mHz, DFREQ is ROCOF × 100
            fr, dfr = p.fnom + fr * 1e-3, dfr * 1e-2
        else:
            # Float FREQ is the actual frequency in the standard, but some senders (the synchrophasor
            # package among them) put the deviation in Hz there; no grid runs below 32.767 Hz, so a value
            # in the deviation's range is read as one.
            fr = np.where(np.abs(fr) <= 32.767, p.fnom + fr, fr)
        if p.analogs:
            an = rec[f"an{k}"].astype(np.float64)
            if not p.analog_float and p.analog_scale:
                an = an * np.array(p.analog_scale)
        else:
            an = np.zeros((n, 0))
        return DataBlock(stat=rec[f"stat{k}"].astype(np.uint16), phasors=z, freq=fr, dfreq=dfr, analogs=an)


def _name16(body: bytes, off: int) -> str:
    return body[off: off + 16].decode("latin-1").rstrip("\x00 ").strip()


def parse_config(frame: Frame) -> Config:
    """The configuration in a CFG-1, CFG-2 or (unfragmented or reassembled) CFG-3 frame.

    Raises
    ------
    C37Error
        ``bad_config`` when the body does not hold what its counts announce.
    """
    try:
        if frame.ftype == CFG3:
            return _parse_cfg3(frame)
        return _parse_cfg12(frame)
    except (struct.error, IndexError, UnicodeDecodeError) as exc:
        raise C37Error("bad_config", f"{FRAME_NAMES.get(frame.ftype)} of {frame.idcode}: {exc}") from None


def _parse_cfg12(frame: Frame) -> Config:
    b = frame.body
    time_base, num = struct.unpack_from(">IH", b, 0)
    off = 6
    pmus = []
    for _ in range(num):
        station = _name16(b, off)
        idcode, fmt, phn, ann, dgn = struct.unpack_from(">HHHHH", b, off + 16)
        off += 26
        names = [_name16(b, off + 16 * i) for i in range(phn + ann + 16 * dgn)]
        off += 16 * len(names)
        phunit = struct.unpack_from(f">{phn}I", b, off)
        off += 4 * phn
        anunit = struct.unpack_from(f">{ann}I", b, off)
        off += 4 * ann + 4 * dgn
        fnom, cfgcnt = struct.unpack_from(">HH", b, off)
        off += 4
        phasors = [Phasor(names[i], CURRENT if (u >> 24) == 1 else VOLTAGE, (u & 0xFFFFFF) * 1e-5)
                   for i, u in enumerate(phunit)]
        # ANUNIT: byte 0 the kind, bytes 1-3 a signed 24-bit scale (the user's units per count)
        an_scale = [float(((u & 0xFFFFFF) ^ 0x800000) - 0x800000) or 1.0 for u in anunit]
        pmus.append(PmuConfig(station, idcode, fmt, phasors, names[phn: phn + ann], dgn,
                              50.0 if fnom & 1 else 60.0, cfgcnt, an_scale, names[phn + ann:]))
    (rate,) = struct.unpack_from(">h", b, off)
    if off + 2 != len(b):
        raise C37Error("bad_config", f"{len(b) - off - 2} bytes left after DATA_RATE")
    return Config(frame.idcode, time_base & 0xFFFFFF, pmus, _rate(rate), frame.ftype)


def _rate(code: int) -> float:
    return float(code) if code > 0 else (1.0 / -code if code < 0 else math.nan)


def _name8(b: bytes, off: int) -> tuple[str, int]:
    n = b[off]
    return b[off + 1: off + 1 + n].decode("utf-8", "replace").strip(), off + 1 + n


def _parse_cfg3(frame: Frame) -> Config:
    b = frame.body  # CONT_IDX already consumed by the reassembly: body starts at TIME_BASE
    time_base, num = struct.unpack_from(">IH", b, 0)
    off = 6
    pmus = []
    for _ in range(num):
        station, off = _name8(b, off)
        idcode = struct.unpack_from(">H", b, off)[0]
        off += 2 + 16  # IDCODE, G_PMU_ID
        fmt, phn, ann, dgn = struct.unpack_from(">HHHH", b, off)
        off += 8
        names = []
        for _ in range(phn + ann + 16 * dgn):
            name, off = _name8(b, off)
            names.append(name)
        phasors = []
        for i in range(phn):
            _, ptype, _, y, theta = struct.unpack_from(">HBBff", b, off)
            off += 12
            phasors.append(Phasor(names[i], CURRENT if ptype & 0x8 else VOLTAGE, float(y), float(theta), ptype & 7))
        an_scale = []
        for _ in range(ann):
            m, _b = struct.unpack_from(">ff", b, off)
            an_scale.append(float(m))
            off += 8
        off += 4 * dgn + 12 + 1 + 8  # DIGUNIT, PMU_LAT/LON/ELEV, SVC_CLASS, WINDOW, GRP_DLY
        fnom, cfgcnt = struct.unpack_from(">HH", b, off)
        off += 4
        pmus.append(PmuConfig(station, idcode, fmt, phasors, names[phn: phn + ann], dgn,
                              50.0 if fnom & 1 else 60.0, cfgcnt, an_scale, names[phn + ann:]))
    (rate,) = struct.unpack_from(">h", b, off)
    return Config(frame.idcode, time_base & 0xFFFFFF, pmus, _rate(rate), CFG3)


class Cfg3Assembler:
    """Joins the fragments of a CFG-3 (CONT_IDX 1, 2, ..., 0xFFFF) into one frame's body."""

    def __init__(self) -> None:
        self._parts: list[bytes] = []
        self._next = 1

    def add(self, frame: Frame) -> Frame | None:
        """Feed one CFG-3 frame; the whole configuration frame once complete, else None.

        Raises
        ------
        C37Error
            ``cfg3_fragment`` for a fragment out of sequence.
        """
        (idx,) = struct.unpack_from(">H", frame.body, 0)
        part = frame.body[2:]
        if idx == 0:
            self._parts, self._next = [], 1
            return Frame(frame.ftype, frame.version, frame.idcode, frame.soc, frame.fracsec, part)
        if idx == 0xFFFF and self._parts:
            whole = b"".join([*self._parts, part])
            self._parts, self._next = [], 1
            return Frame(frame.ftype, frame.version, frame.idcode, frame.soc, frame.fracsec, whole)
        if idx != self._next:
            self._parts, self._next = [], 1
            raise C37Error("cfg3_fragment", f"CONT_IDX {idx} out of sequence")
        self._parts.append(part)
        self._next += 1
        return None


# --- encoding (the bridge's test peers, the capture replayer and the benchmark use it) ------------------


def encode_config(cfg: Config, soc: int = 0, fracsec: int = 0) -> bytes:
    """A CFG-2 frame for ``cfg`` (PHUNIT from each phasor's ``scale``)."""
    parts = [struct.pack(">IH", cfg.time_base, len(cfg.pmus))]
    for p in cfg.pmus:
        names = [ph.name for ph in p.phasors] + list(p.analogs) + list(p.digital_names or [""] * 16 * p.digitals)
        parts.append(p.station.encode("latin-1")[:16].ljust(16))
        parts.append(struct.pack(">HHHHH", p.idcode, p.fmt, len(p.phasors), len(p.analogs), p.digitals))
        parts += [n.encode("latin-1")[:16].ljust(16) for n in names]
        parts += [struct.pack(">I", (ph.kind << 24) | round(ph.scale * 1e5)) for ph in p.phasors]
        parts += [struct.pack(">I", round(s) & 0xFFFFFF) for s in (p.analog_scale or [1.0] * len(p.analogs))]
        parts += [struct.pack(">I", 0x0000FFFF)] * p.digitals
        parts.append(struct.pack(">HH", 1 if p.fnom == 50.0 else 0, p.cfgcnt))
    rate = cfg.data_rate
    parts.append(struct.pack(">h", round(rate) if rate >= 1 else -round(1 / rate)))
    return build(CFG2, cfg.idcode, soc, fracsec, b"".join(parts))


def encode_data(cfg: Config, t: float, stat: list[int], phasors: list[np.ndarray], freq: list[float],
                dfreq: list[float]) -> bytes:
    """One data frame of ``cfg`` at time ``t`` [s]; ``phasors[k]`` complex in volts/amperes for PMU k."""
    soc = int(t)
    frac = min(round((t - soc) * cfg.time_base), cfg.time_base - 1)
    parts = []
    for k, p in enumerate(cfg.pmus):
        parts.append(struct.pack(">H", stat[k]))
        z = np.asarray(phasors[k], complex)
        if not p.phasor_float:
            z = z / np.array([ph.scale for ph in p.phasors])
        if p.polar:
            a, b = np.abs(z), np.angle(z)
        else:
            a, b = z.real, z.imag
        if p.phasor_float:
            parts.append(np.stack([a, b], axis=1).astype(">f4").tobytes())
        elif p.polar:
            rows = np.zeros(len(z), dtype=[("m", ">u2"), ("a", ">i2")])
            rows["m"], rows["a"] = np.round(a), np.round(b * 1e4)
            parts.append(rows.tobytes())
        else:
            parts.append(np.round(np.stack([a, b], axis=1)).astype(">i2").tobytes())
        if p.freq_float:
            parts.append(struct.pack(">ff", freq[k], dfreq[k]))
        else:
            parts.append(struct.pack(">hh", round((freq[k] - p.fnom) * 1e3), round(dfreq[k] * 1e2)))
        parts.append(b"\x00" * ((4 if p.analog_float else 2) * len(p.analogs) + 2 * p.digitals))
    return build(DATA, cfg.idcode, soc, frac, b"".join(parts))
