"""Per-bus ring buffers of PMU frames, ordered by PMU timestamp, with accounting of every drop.

Invariant (checked by tests and the ingest benchmark): for every bus,
``frames offered = frames buffered + sum(frames rejected by reason)``.  Frames that age out of a full
ring were buffered and are not counted again.

Reasons a frame is rejected here: ``late`` (older than the bus's watermark minus the late-data
allowance), ``duplicate`` (within a quarter frame period of a frame already held or earlier in the same
batch), ``bad_bus`` (the bus name breaks the grammar of :mod:`service.busnames`: no buffer is made).
Frames within the allowance but out of order are merged in time order.

The watermark is the newest frame held, but never later than the arrival clock: a single frame stamped
up to ``max_future_s`` ahead (accepted, a PMU's clock may run a little fast) would otherwise make every
real frame of the next seconds ``late`` (with max_future_s 5 > late_s 1, about 1,000 frames at 50/s).

Buses are forgotten in two ways, their counts moving to the store's totals so the invariant holds:
:meth:`BufferStore.evict_idle` (the scheduler's sweep of buses not heard from for ``bus_idle_s``) and,
when a new bus arrives with ``max_buses`` buffers in use, the eviction of the buses that went longest
without a valid frame (those that never sent one first), so stray keys can fill the store but never
keep a real bus out.
"""

from __future__ import annotations

import heapq
import math
import threading
from collections import Counter
from dataclasses import dataclass

import numpy as np

from aslm_core.window import CHANNELS, Window
from service.busnames import bus_name_problem
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
                 "has_f", "last_arrival", "last_seen", "messages", "messages_rejected", "retired")

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
        self.last_arrival = 0.0  # clock time of the last message with valid frames [s]
        self.last_seen = 0.0  # clock time of the last message of any kind [s]
        self.messages = 0
        self.messages_rejected: Counter[str] = Counter()
        self.retired = False  # evicted: its counts are in the store's totals, nothing more goes here

    def count(self, rejected: dict[str, int], message_reason: str | None = None,
              arrival: float | None = None) -> bool:
        """Record frames rejected before buffering (validation, undecodable message).

        Returns False if the buffer was evicted meanwhile (nothing recorded: count on the new one).
        """
        with self.lock:
            if self.retired:
                return False
            if arrival is not None:
                self.last_seen = arrival
            self.messages += 1
            if message_reason:
                self.messages_rejected[message_reason] += 1
            for reason, k in rejected.items():
                self.rejected[reason] += k
        return True

    @property
    def size(self) -> int:
        """Frames held."""
        return self.end - self.start

    @property
    def newest(self) -> float:
        """PMU time of the newest frame held [s] (-inf when empty)."""
        return float(self.data[0, self.end - 1]) if self.end > self.start else -math.inf

    def insert(self, batch: FrameBatch, arrival: float | None = None, rejected: dict[str, int] | None = None
               ) -> dict[str, int] | None:
        """Add one message's validated frames; ``rejected`` are its frames that failed validation.

        ``arrival`` is the clock time of the message [s] (None: no clock, the watermark is the newest
        frame).  Returns the frames rejected here (late, duplicate) by reason, empty when all were
        taken, or None if the buffer was evicted meanwhile (nothing recorded: insert into the new one).
        """
        n = len(batch)
        with self.lock:
            if self.retired:
                return None
            if arrival is not None:
                self.last_seen = arrival
            self.messages += 1
            if rejected:
                for reason, k in rejected.items():
                    self.rejected[reason] += k
            if n == 0:
                return {}
            if self.data is _EMPTY:
                # Slack of a quarter capacity: compaction (one copy of the live region) every ~cap/4 frames.
                self.data = np.empty((_NROWS, self.capacity + self.capacity // 4 + 64))
            if arrival is not None:
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
            return self._insert_slow(batch, newest if arrival is None or arrival >= newest else arrival)

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

    def _insert_slow(self, batch: FrameBatch, watermark: float) -> dict[str, int]:
        cols = self._columns(batch)
        cols = cols[:, np.argsort(cols[0], kind="stable")]
        t = cols[0]
        rejected: dict[str, int] = {}
        late = t < watermark - self.late_s
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
    """Service-wide accounting (sums over buses, computed on demand; evicted buses included)."""

    buses: int
    messages: int
    frames_buffered: int
    frames_rejected: dict[str, int]
    messages_rejected: dict[str, int]
    buses_evicted: int = 0

    @property
    def frames_received(self) -> int:
        """Frames offered: buffered plus rejected."""
        return self.frames_buffered + sum(self.frames_rejected.values())


class BufferStore:
    """All buses' buffers and their accounting.

    Counters live in each bus's buffer and change under its lock, so the accounting stays exact
    whichever Zenoh thread delivers a message; service-wide totals are sums taken on demand, plus what
    evicted buses and refused names had counted.

    Parameters
    ----------
    window_s, frame_rate, late_s : float
        Size the rings: ``(window_s + history_s + late_s + 3 s) * frame_rate`` frames, the 3 s covering the
        time between a period's cut and the frames that keep arriving meanwhile.
    history_s : float
        Held besides the window: the windows before it that the identifier's input history pools [s].
    max_buses : int
        Buffers kept at most.  A new bus beyond it evicts the buses that went longest without a valid
        frame (a 64th of the cap at a time, so a flood of new names costs O(1) each on average), so
        stray keys cannot exhaust memory and cannot keep a real bus out either.
    """

    def __init__(self, window_s: float, frame_rate: float, late_s: float, max_buses: int = 100_000,
                 history_s: float = 0.0) -> None:
        self.capacity = int(math.ceil((window_s + history_s + late_s + 3.0) * frame_rate))
        self.tol = 0.25 / frame_rate
        self.late_s = late_s
        self.max_buses = max_buses
        self._buses: dict[str, BusBuffer] = {}
        self._lock = threading.Lock()
        # What no live buffer holds: frames and messages of refused names and of evicted buses.
        self._gone_rejected: Counter[str] = Counter()
        self._gone_messages_rejected: Counter[str] = Counter()
        self._gone_messages = 0
        self._gone_buffered = 0
        self.evicted = 0

    def buffer(self, bus: str, create: bool = True) -> BusBuffer | None:
        """The buffer of ``bus``, created on first use; None if unknown (``create`` False) or invalid."""
        buf = self._buses.get(bus)
        if buf is None and create:
            if bus_name_problem(bus) is not None:  # checked once per new name, never per message
                return None
            with self._lock:
                buf = self._buses.get(bus)
                if buf is None:
                    if len(self._buses) >= self.max_buses:
                        self._make_room()
                    buf = self._buses[bus] = BusBuffer(self.capacity, self.tol, self.late_s)
        return buf

    def buses(self) -> list[str]:
        """Buses that have sent anything and are not evicted, sorted."""
        return sorted(self._buses)

    def discard(self, bus: str) -> None:
        """Forget ``bus`` and its frames (another instance of a sharded fleet owns it now); its counts stay
        in :meth:`totals`."""
        self.evict([bus])

    def reject_message(self, bus: str, reason: str, n_frames: int = 0, arrival: float | None = None) -> None:
        """Record an undecodable message and the frames it held, if known."""
        while True:
            buf = self.buffer(bus)
            if buf is None:
                self._refuse("bad_bus", n_frames)
                return
            if buf.count({reason: n_frames} if n_frames else {}, message_reason=reason, arrival=arrival):
                return

    def add(self, bus: str, batch: FrameBatch, rejected: dict[str, int] | None = None,
            arrival: float | None = None) -> dict[str, int]:
        """Buffer a validated batch of ``bus``; ``rejected`` are its frames that failed validation.

        ``arrival`` is the clock time of the message [s].  Returns the frames rejected by the buffer
        (late, duplicate, bad_bus) by reason.
        """
        while True:
            buf = self.buffer(bus)
            if buf is None:
                self._refuse("bad_bus", len(batch) + sum((rejected or {}).values()))
                return {"bad_bus": len(batch)}
            out = buf.insert(batch, arrival, rejected)
            if out is not None:  # None: evicted between the lookup and the insert, try the new buffer
                return out

    def _refuse(self, reason: str, n_frames: int) -> None:
        with self._lock:
            if n_frames:
                self._gone_rejected[reason] += n_frames
            self._gone_messages_rejected[reason] += 1
            self._gone_messages += 1

    def evict(self, buses: list[str]) -> list[str]:
        """Forget ``buses`` (their counts stay in :meth:`totals`); returns those that were known."""
        with self._lock:
            return [bus for bus in buses if self._retire(bus)]

    def evict_idle(self, before: float) -> list[str]:
        """Forget the buses whose last message arrived before ``before`` (clock time [s]), sorted."""
        idle = [bus for bus, buf in list(self._buses.items()) if buf.last_seen < before]
        return sorted(self.evict(idle))

    def _make_room(self) -> None:
        """Evict the buses longest without a valid frame (caller holds ``_lock``)."""
        k = max(1, self.max_buses // 64)
        for bus, _ in heapq.nsmallest(k, self._buses.items(), key=lambda kv: (kv[1].last_arrival, kv[1].last_seen)):
            self._retire(bus)

    def _retire(self, bus: str) -> bool:
        buf = self._buses.pop(bus, None)
        if buf is None:
            return False
        with buf.lock:
            buf.retired = True
            self._gone_rejected.update(buf.rejected)
            self._gone_messages_rejected.update(buf.messages_rejected)
            self._gone_messages += buf.messages
            self._gone_buffered += buf.buffered
        self.evicted += 1
        return True

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
        with self._lock:  # a consistent view of the evicted part (an eviction moves counts under it)
            rejected: Counter[str] = Counter(self._gone_rejected)
            mrej: Counter[str] = Counter(self._gone_messages_rejected)
            messages, buffered = self._gone_messages, self._gone_buffered
            live = list(self._buses.values())
            evicted = self.evicted
        for buf in live:
            messages += buf.messages
            buffered += buf.buffered
            rejected.update(buf.rejected)
            mrej.update(buf.messages_rejected)
        return Totals(buses=len(live), messages=messages, frames_buffered=buffered, frames_rejected=dict(rejected),
                      messages_rejected=dict(mrej), buses_evicted=evicted)
