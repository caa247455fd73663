"""Per-bus ring buffers of PMU frames, ordered by PMU timestamp, with accounting of every drop.

Invariant (checked by tests and the ingest benchmark): for every bus,
``frames offered = frames buffered + sum(frames rejected by reason)``.  Frames that age out of a full
ring were buffered and are not counted again.

Reasons a frame is rejected here: ``late`` (older than the newest buffered frame of the bus minus the
late-data allowance), ``duplicate`` (within a quarter frame period of a frame already held or earlier in
the same batch).  Frames within the allowance but out of order are merged in time order.
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from dataclasses import dataclass

import numpy as np

from aslm_core.window import CHANNELS, Window
from service.frames import FrameBatch

ROWS = CHANNELS  # one row per channel, f last (NaN for frames without it)
_NROWS = len(ROWS)
_EMPTY = np.empty((_NROWS, 0))


class BusBuffer:
    """Time-ordered frames of one bus in a linear array that is compacted when its end is reached.

    The live region ``data[:, start:end]`` is always contiguous and sorted by t, which keeps
    appends to a slice copy and window cuts to two ``searchsorted`` calls.

    Parameters
    ----------
    capacity : int
        Frames kept; older ones are overwritten.
    tol : float
        Two frames closer than this are duplicates [s].
    late_s : float
        Late-data allowance [s].
    """

    __slots__ = ("capacity", "tol", "late_s", "data", "start", "end", "lock", "buffered", "rejected",
                 "has_f", "last_arrival", "messages", "messages_rejected")

    def __init__(self, capacity: int, tol: float, late_s: float) -> None:
        self.capacity = int(capacity)
        self.tol = float(tol)
        self.late_s = float(late_s)
        self.data = _EMPTY  # allocated on the first frame: a key that only sends garbage costs nothing
        self.start = 0
        self.end = 0
        self.lock = threading.Lock()
        self.buffered = 0
        self.rejected: Counter[str] = Counter()
        self.has_f = False
        self.last_arrival = 0.0
        self.messages = 0
        self.messages_rejected: Counter[str] = Counter()

    def count(self, rejected: dict[str, int], message_reason: str | None = None) -> None:
        """Record frames rejected before buffering (validation, undecodable message)."""
        with self.lock:
            self.messages += 1
            if message_reason:
                self.messages_rejected[message_reason] += 1
            for reason, k in rejected.items():
                self.rejected[reason] += k

    @property
    def size(self) -> int:
        """Frames held."""
        return self.end - self.start

    @property
    def newest(self) -> float:
        """PMU time of the newest frame held [s] (-inf when empty)."""
        return float(self.data[0, self.end - 1]) if self.end > self.start else -math.inf

    def insert(self, batch: FrameBatch, arrival: float = 0.0, rejected: dict[str, int] | None = None
               ) -> dict[str, int]:
        """Add one message's validated frames; ``rejected`` are its frames that failed validation.

        Returns the frames rejected here (late, duplicate) by reason; empty when all were taken.
        """
        n = len(batch)
        with self.lock:
            self.messages += 1
            if rejected:
                for reason, k in rejected.items():
                    self.rejected[reason] += k
            if n == 0:
                return {}
            if self.data is _EMPTY:
                # Slack of a quarter capacity: compaction (one copy of the live region) every ~cap/4 frames.
                self.data = np.empty((_NROWS, self.capacity + self.capacity // 4 + 64))
            self.last_arrival = arrival
            cols = batch.block()
            t = cols[0]
            newest = self.newest
            if batch.f is not None:
                self.has_f = True
            # Fast path: the batch is strictly increasing and starts after the newest frame held.
            if float(t[0]) > newest + self.tol and (n == 1 or float((t[1:] - t[:-1]).min()) > self.tol):
                self._append(cols, batch.f is not None)
                self.buffered += n
                return {}
            return self._insert_slow(batch, newest)

    def _columns(self, batch: FrameBatch) -> np.ndarray:
        cols = np.empty((_NROWS, len(batch)))
        cols[:5] = batch.block()[:5]
        cols[5] = batch.f if batch.f is not None else np.nan
        return cols

    def _reserve(self, n: int) -> None:
        """Make room for n frames after ``end``, keeping at most ``capacity`` frames in all."""
        if self.end + n <= self.data.shape[1]:
            return
        keep = max(0, min(self.size, self.capacity - n))
        self.data[:, :keep] = self.data[:, self.end - keep:self.end]
        self.start, self.end = 0, keep

    def _append(self, cols: np.ndarray, has_f: bool) -> None:
        n = cols.shape[1]
        if n > self.capacity:  # a batch longer than the ring: only its tail can be held
            cols = cols[:, -self.capacity:]
            n = self.capacity
        self._reserve(n)
        e = self.end
        self.data[:cols.shape[0], e:e + n] = cols
        if not has_f and self.has_f:
            self.data[5, e:e + n] = np.nan  # this bus sent f before: mark the frames without it
        self.end = e + n
        if self.size > self.capacity:
            self.start = self.end - self.capacity

    def _insert_slow(self, batch: FrameBatch, newest: float) -> dict[str, int]:
        cols = self._columns(batch)
        cols = cols[:, np.argsort(cols[0], kind="stable")]
        t = cols[0]
        rejected: dict[str, int] = {}
        late = t < newest - self.late_s
        if self.size >= self.capacity:
            # A full ring cannot place frames older than its oldest one: late as well.
            late |= t < self.data[0, self.start] - self.tol
        n_late = int(late.sum())
        if n_late:
            rejected["late"] = n_late
            cols = cols[:, ~late]
            t = cols[0]
        if t.size:
            dup = np.zeros(t.size, bool)
            dup[1:] = np.diff(t) <= self.tol
            held = self.data[0, self.start:self.end]
            i0 = int(np.searchsorted(held, t[0] - self.tol))
            region = held[i0:]
            if region.size:
                j = np.searchsorted(region, t)
                lo = np.abs(t - region[np.clip(j - 1, 0, region.size - 1)])
                hi = np.abs(region[np.clip(j, 0, region.size - 1)] - t)
                dup |= np.minimum(lo, hi) <= self.tol
            n_dup = int(dup.sum())
            if n_dup:
                rejected["duplicate"] = n_dup
                cols = cols[:, ~dup]
                t = cols[0]
            if t.size:
                tail = self.data[:, self.start + i0:self.end].copy()
                merged = np.concatenate([tail, cols], axis=1)
                merged = merged[:, np.argsort(merged[0], kind="stable")]
                self.end = self.start + i0
                self._write(merged)
                self.buffered += int(t.size)
        for reason, k in rejected.items():
            self.rejected[reason] += k
        return rejected

    def _write(self, cols: np.ndarray) -> None:
        n = cols.shape[1]
        if n > self.capacity:
            cols = cols[:, -self.capacity:]
            n = self.capacity
        self._reserve(n)
        self.data[:, self.end:self.end + n] = cols
        self.end += n
        if self.size > self.capacity:
            self.start = self.end - self.capacity

    def cut(self, t_from: float, t_to: float, *, f0: float = 50.0, bus: str = "") -> Window:
        """Copy of the frames with ``t_from < t <= t_to`` [s], as a window of nominal frequency ``f0`` [Hz].

        The channels are rows of one fresh array (safe to hand to another process); f is None unless
        every frame of the cut has it.
        """
        with self.lock:
            held = self.data[0, self.start:self.end]
            i = self.start + int(np.searchsorted(held, t_from, side="right"))
            j = self.start + int(np.searchsorted(held, t_to, side="right"))
            block = self.data[:, i:j].copy()
            has_f = self.has_f
        return Window.from_rows(block, with_f=has_f and bool(np.isfinite(block[5]).all()), f0=f0, bus=bus)


@dataclass
class BusCounts:
    """Accounting of one bus: ``buffered + sum(rejected.values())`` frames were offered."""

    bus: str
    messages: int
    buffered: int
    held: int
    newest_t: float | None
    rejected: dict[str, int]
    messages_rejected: dict[str, int]


@dataclass
class Totals:
    """Service-wide accounting (sums over buses, computed on demand)."""

    buses: int
    messages: int
    frames_buffered: int
    frames_rejected: dict[str, int]
    messages_rejected: dict[str, int]

    @property
    def frames_received(self) -> int:
        """Frames offered: buffered plus rejected."""
        return self.frames_buffered + sum(self.frames_rejected.values())


class BufferStore:
    """All buses' buffers and their accounting.

    Counters live in each bus's buffer and change under its lock, so the accounting stays exact
    whichever Zenoh thread delivers a message; service-wide totals are sums taken on demand.

    Parameters
    ----------
    window_s, frame_rate, late_s : float
        Size the rings: ``(window_s + late_s + 3 s) * frame_rate`` frames, the 3 s covering the time
        between a period's cut and the frames that keep arriving meanwhile.
    max_buses : int
        New buses beyond this are refused (``too_many_buses``), so stray keys cannot exhaust memory.
    """

    def __init__(self, window_s: float, frame_rate: float, late_s: float, max_buses: int = 100_000) -> None:
        self.capacity = int(math.ceil((window_s + late_s + 3.0) * frame_rate))
        self.tol = 0.25 / frame_rate
        self.late_s = late_s
        self.max_buses = max_buses
        self._buses: dict[str, BusBuffer] = {}
        self._lock = threading.Lock()
        self._refused: Counter[str] = Counter()  # frames of buses beyond max_buses
        self._refused_messages = 0

    def buffer(self, bus: str, create: bool = True) -> BusBuffer | None:
        """The buffer of ``bus``, created on first use (None beyond ``max_buses``)."""
        buf = self._buses.get(bus)
        if buf is None and create:
            with self._lock:
                buf = self._buses.get(bus)
                if buf is None:
                    if len(self._buses) >= self.max_buses:
                        return None
                    buf = self._buses[bus] = BusBuffer(self.capacity, self.tol, self.late_s)
        return buf

    def buses(self) -> list[str]:
        """Buses that have sent anything, sorted."""
        return sorted(self._buses)

    def discard(self, bus: str) -> None:
        """Forget ``bus`` and its frames (another instance of a sharded fleet owns it now)."""
        with self._lock:
            self._buses.pop(bus, None)

    def reject_message(self, bus: str, reason: str, n_frames: int = 0) -> None:
        """Record an undecodable message and the frames it announced, if known."""
        buf = self.buffer(bus)
        if buf is None:
            self._refuse(n_frames)
            return
        buf.count({reason: n_frames} if n_frames else {}, message_reason=reason)

    def add(self, bus: str, batch: FrameBatch, rejected: dict[str, int] | None = None,
            arrival: float = 0.0) -> dict[str, int]:
        """Buffer a validated batch of ``bus``; ``rejected`` are its frames that failed validation.

        Returns the frames rejected by the buffer (late, duplicate) by reason.
        """
        buf = self.buffer(bus)
        if buf is None:
            self._refuse(len(batch) + sum((rejected or {}).values()))
            return {"too_many_buses": len(batch)}
        return buf.insert(batch, arrival, rejected)

    def _refuse(self, n_frames: int) -> None:
        with self._lock:
            self._refused["too_many_buses"] += n_frames
            self._refused_messages += 1

    def counts(self, bus: str) -> BusCounts | None:
        """Accounting of one bus (None if unknown)."""
        buf = self._buses.get(bus)
        if buf is None:
            return None
        with buf.lock:
            return BusCounts(bus=bus, messages=buf.messages, buffered=buf.buffered, held=buf.size,
                             newest_t=buf.newest if buf.size else None, rejected=dict(buf.rejected),
                             messages_rejected=dict(buf.messages_rejected))

    def totals(self) -> Totals:
        """Service-wide sums."""
        rejected: Counter[str] = Counter(self._refused)
        mrej: Counter[str] = Counter({"too_many_buses": self._refused_messages} if self._refused_messages else {})
        messages = buffered = 0
        for buf in list(self._buses.values()):
            messages += buf.messages
            buffered += buf.buffered
            rejected.update(buf.rejected)
            mrej.update(buf.messages_rejected)
        return Totals(buses=len(self._buses), messages=messages + self._refused_messages,
                      frames_buffered=buffered, frames_rejected=dict(rejected), messages_rejected=dict(mrej))
