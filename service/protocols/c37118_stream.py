"""A C37.118.2 byte stream to per-bus frame batches, with every byte and frame it could not use counted.

:class:`StreamDecoder` takes whatever a socket read returned (several frames, part of one, garbage),
checks each frame's CRC, keeps the current configuration and decodes runs of data frames with it;
:class:`BusResolver` turns decoded data into one :class:`~service.frames.FrameBatch` per mapped bus.

Accounting: ``frames`` counts PMU frames received (one data frame of a PDC carrying 200 PMUs is 200),
and every one of them is either handed on or counted in ``rejected`` under one reason:

``no_config``       data before any configuration (the frame is dropped; a CFG-2 is asked for)
``size_mismatch``   a data frame whose size does not fit the configuration (changed without a CFG-2)
``other_stream``    a data frame of another IDCODE than the configuration's
``off_rate``        time stamp not on the configured DATA_RATE's grid (a PMU sending at another rate)
``unmapped``        PMU blocks no bus uses (counted, not an error)

Whole frames that fail before their PMU count is known are counted in ``bad_frames``: ``bad_crc``,
``truncated`` (a frame cut short: the next frame starts inside it, or the connection ended in it),
``bad_config``, ``cfg3_fragment``; ``skipped_bytes`` counts bytes that were not a frame at all.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from service.frames import FrameBatch
from service.protocols import c37118 as c37
from service.protocols.mapping import BusMap, bus_batch

log = logging.getLogger(__name__)

RATE_TOL = 0.25  # a time stamp further than this fraction of a frame period off the grid is off-rate


@dataclass
class _BusPlan:
    bm: BusMap
    block: int
    voltage: list[int]
    feeders: list[list[int]]


class BusResolver:
    """Per-bus frames from the data of one configuration, as the mapping says.

    Raises
    ------
    KeyError
        At construction, when the configuration lacks a PMU or phasor the mapping names.
    """

    def __init__(self, cfg: c37.Config, buses: tuple[BusMap, ...]) -> None:
        self.cfg = cfg
        self.plans = []
        used = set()
        for bm in buses:
            k = next((i for i, p in enumerate(cfg.pmus) if bm.pmu in (p.idcode, p.station)), None)
            if k is None:
                cfg.pmu(bm.pmu)  # raises KeyError naming what the stream has
            p = cfg.pmus[k]
            used.add(k)
            self.plans.append(_BusPlan(bm, k, [p.phasor_index(n) for n in bm.voltage],
                                       [[p.phasor_index(n) for n in fd.phasors] for fd in bm.feeders]))
        self.unused_blocks = len(cfg.pmus) - len(used)

    def batches(self, t: np.ndarray, blocks: list[c37.DataBlock], keep: np.ndarray | None = None
                ) -> dict[str, FrameBatch]:
        """One batch per bus from decoded data (``keep`` selects frames)."""
        sel = slice(None) if keep is None or keep.all() else keep
        out = {}
        for plan in self.plans:
            b = blocks[plan.block]
            z = b.phasors[sel]
            v = z[:, plan.voltage[0]] if len(plan.voltage) == 1 else z[:, plan.voltage]
            cur = [z[:, ix[0]] if len(ix) == 1 else z[:, ix] for ix in plan.feeders]
            out[plan.bm.bus] = bus_batch(plan.bm, t[sel], v, cur, b.freq[sel], b.stat[sel])
        return out


class StreamDecoder:
    """Frames out of a C37.118.2 byte stream: configurations kept, data decoded, losses counted.

    Parameters
    ----------
    buses : tuple of BusMap
        The mapping's buses.
    on_batches : callable
        Called with ``{bus: FrameBatch}`` for each run of decoded data frames.
    on_config : callable, optional
        Called with each new :class:`~service.protocols.c37118.Config` (after the resolver is built).
    idcode : int, optional
        IDCODE of the stream followed; data of others is rejected as ``other_stream``.
    """

    def __init__(self, buses: tuple[BusMap, ...], on_batches: Callable[[dict[str, FrameBatch]], None],
                 on_config: Callable[[c37.Config], None] | None = None, idcode: int | None = None) -> None:
        self.buses = buses
        self.on_batches = on_batches
        self.on_config = on_config
        self.idcode = idcode
        self.cfg: c37.Config | None = None
        self.resolver: BusResolver | None = None
        self._buf = bytearray()
        self._cfg3 = c37.Cfg3Assembler()
        self.frames = 0  # PMU frames received in data frames (decodable or not)
        self.delivered = 0  # PMU frames handed on (a bus's batch may carry the same frame for several buses)
        self.rejected: Counter[str] = Counter()  # PMU frames, by reason
        self.bad_frames: Counter[str] = Counter()  # whole frames, by reason
        self.flags: Counter[str] = Counter()  # STAT flags and FRACSEC time quality seen, by name
        self.skipped_bytes = 0
        self.configs = 0
        self.config_changes = 0
        self.need_config = False  # set when the stream says its configuration changed: ask for a CFG-2
        self.data_rate_seen: float | None = None

    # --- bytes in ---------------------------------------------------------------------------------

    def feed(self, chunk: bytes) -> None:
        """Add bytes as read from the stream (any split) and decode every whole frame in them."""
        self._buf += chunk
        buf = self._buf
        pos = 0
        run: list[bytes] = []
        while True:
            off, size = c37.split(buf, pos)
            if off > pos:
                self.skipped_bytes += off - pos
            pos = off
            if size == 0 or off + size > len(buf):
                break
            raw = bytes(buf[off: off + size])
            try:
                frame = c37.parse(raw)
            except c37.C37Error as exc:
                pos = self._resync(buf, off, size, exc.reason)
                continue
            pos = off + size
            if frame.ftype == c37.DATA:
                if self.cfg is not None and size == self.cfg.data_size and frame.idcode == self.cfg.idcode:
                    run.append(raw)
                    continue
                self._flush(run)
                run = []
                self._reject_data(frame, size)
            else:
                self._flush(run)
                run = []
                self._control(frame)
        self._flush(run)
        del buf[:pos]

    def end(self) -> None:
        """The stream ended (connection dropped, datagram over): what is left is a truncated frame."""
        if self._buf:
            off, _ = c37.split(self._buf, 0)
            self.skipped_bytes += off
            if off < len(self._buf):
                self.bad_frames["truncated"] += 1
        self._buf.clear()

    def _resync(self, buf: bytearray, off: int, size: int, reason: str) -> int:
        # A frame cut short has the next frame's header (same IDCODE) inside its announced size: resume
        # there.  Matching the IDCODE keeps a 0xAA byte inside a damaged frame's payload from being
        # taken for a frame start and counted a second time.
        idcode = buf[off + 4: off + 6]
        pos = off + 1
        while True:
            nxt, nsize = c37.split(buf, pos)
            if nxt >= off + size or nxt + 6 > len(buf):
                break
            if nsize and buf[nxt + 4: nxt + 6] == idcode:
                self.bad_frames["truncated"] += 1
                self.skipped_bytes += nxt - off
                return nxt
            pos = nxt + 1
        self.bad_frames[reason] += 1
        return off + size

    # --- frames -----------------------------------------------------------------------------------

    def _reject_data(self, frame: c37.Frame, size: int) -> None:
        if self.cfg is None:
            reason = "no_config"
            self.need_config = True
        elif frame.idcode != self.cfg.idcode:
            reason = "other_stream"
        else:
            reason = "size_mismatch"
            self.need_config = True
        n = len(self.cfg.pmus) if self.cfg is not None else 1
        self.frames += n
        self.rejected[reason] += n

    def _control(self, frame: c37.Frame) -> None:
        if frame.ftype in (c37.CFG1, c37.CFG2, c37.CFG3):
            if self.idcode is not None and frame.idcode != self.idcode:
                return
            try:
                if frame.ftype == c37.CFG3:
                    whole = self._cfg3.add(frame)
                    if whole is None:
                        return
                    frame = whole
                cfg = c37.parse_config(frame)
            except c37.C37Error as exc:
                self.bad_frames[exc.reason] += 1
                return
            if frame.ftype == c37.CFG1 and self.cfg is not None:
                return  # CFG-1 says what the PMU can send; CFG-2/3 what it does send
            self.set_config(cfg)
        # header and command frames carry nothing for the buffers

    def set_config(self, cfg: c37.Config) -> None:
        """Follow ``cfg`` from now on (KeyError if the mapping names what it lacks)."""
        changed = self.cfg is not None and (self.cfg.data_size != cfg.data_size or self.cfg.pmus != cfg.pmus
                                            or self.cfg.data_rate != cfg.data_rate)
        self.resolver = BusResolver(cfg, self.buses)
        self.cfg = cfg
        self.configs += 1
        self.config_changes += int(changed)
        self.need_config = False
        if self.on_config is not None:
            self.on_config(cfg)

    def _flush(self, run: list[bytes]) -> None:
        if not run:
            return
        cfg = self.cfg
        t, tq, blocks = cfg.decode_data(b"".join(run))
        n, npmu = len(run), len(cfg.pmus)
        self.frames += n * npmu
        keep = self._on_rate(t)
        n_off = int(n - keep.sum())
        if n_off:
            self.rejected["off_rate"] += n_off * npmu
        self._count_flags(tq, blocks, keep)
        if self.resolver.unused_blocks:
            self.rejected["unmapped"] += int(keep.sum()) * self.resolver.unused_blocks
        self.delivered += int(keep.sum()) * (npmu - self.resolver.unused_blocks)
        if keep.any():
            self.on_batches(self.resolver.batches(t, blocks, keep))

    def _on_rate(self, t: np.ndarray) -> np.ndarray:
        rate = self.cfg.data_rate
        if not rate > 0:
            return np.ones(t.shape, bool)
        ticks = (t - np.floor(t)) * rate
        return np.abs(ticks - np.round(ticks)) <= RATE_TOL

    def _count_flags(self, tq: np.ndarray, blocks: list[c37.DataBlock], keep: np.ndarray) -> None:
        for b in blocks:
            st = b.stat[keep]
            for name, bit in c37.STAT_FLAGS.items():
                k = int(np.count_nonzero(st & bit))
                if k:
                    self.flags[name] += k
                    if bit == c37.STAT_CFG_CHANGE:
                        self.need_config = True
        k = int(np.count_nonzero(tq[keep] == c37.TQ_FAULT))
        if k:
            self.flags["clock_failure"] += k

    def counts(self) -> dict:
        """Counters as plain JSON-able values."""
        return {"frames": self.frames, "delivered": self.delivered, "rejected": dict(self.rejected),
                "bad_frames": dict(self.bad_frames), "skipped_bytes": self.skipped_bytes,
                "flags": dict(self.flags), "configs": self.configs, "config_changes": self.config_changes}
