"""STTP (IEEE 2664) source: a subscriber of openPDC/openHistorian through ``sttpapi``, its buses' frames handed
on per batch.

STTP carries measurements, not frames: each value comes alone with its signal ID, a timestamp (ticks,
100 ns) and state flags.  The subscriber asks for the publisher's metadata, resolves the mapping's names
against it (a PMU is a device acronym; a phasor is a ``PhasorDetail`` label of that device, whose magnitude
and angle measurements openPDC names ``{DEVICE}-PM{i}`` / ``{DEVICE}-PA{i}``, or an explicit pair in
``[sttp.phasors]``; the frequency is the device's ``FREQ`` measurement), subscribes to the measurements of
the mapping's devices and assembles, per bus, the measurements of one timestamp into one frame.  A frame is handed on when all
its measurements have arrived; one still missing some ``lag_s`` after its first arrived is counted as
``incomplete``.  Reconnection with exponential backoff is ``sttpapi``'s own (its connector), bounded by
``backoff_s``; each new connection asks for metadata again and re-subscribes.  A connection that stays
open but brings no measurement for ``timeout_s`` is dropped for a new one (``disconnects["silent"]``).

Frames go to the service's ``Inlet`` (``sources = ["sttp"]`` with ``pmu_mapping`` naming the mapping file)
or to Zenoh by ``aslm bridge sttp``, every ``batch_s`` seconds, like the C37.118 source.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service.context import Context
from service.frames import FrameBatch
from service.protocols.mapping import BusMap, Mapping, MappingError, bus_batch, load_mapping, power_batch
from service.sources.base import Inlet
from service.sources.c37118 import Gatherer

log = logging.getLogger(__name__)

UNIX_TICKS = 621355968000000000
"""STTP ticks (100 ns since 0001-01-01 UTC) at the Unix epoch."""
TICKS_VALUE_MASK = 0x3FFFFFFFFFFFFFFF
"""The time bits of a timestamp; the top two flag a leap second."""

# STTP state flags (sttp.transport.constants.StateFlags) and the C37.118 STAT bits they become.
BADDATA, SUSPECTDATA, BADTIME, SUSPECTTIME = 0x1, 0x2, 0x10000, 0x20000
STAT_PMU_ERROR = 0x4000  # bits 15-14 = 01: "PMU error, no information about data" (validation rejects it)
STAT_NOT_SYNC = 0x2000  # bit 13: time not synchronised
CLOSED_KEEP = 4096
#: :meth:`SttpClient.close` waits this long for sttpapi's subscriber to dispose [s].  Its disconnect and auto-reconnect
#: threads can join each other for ever when a close meets a reconnect (seen in CI, stop 57); the close goes on
#: without it then, counted as ``disconnects["dispose_stuck"]``.
DISPOSE_WAIT_S = 10.0
"""Timestamps remembered per bus as handed on or dropped (80 s at 50 frames/s): a measurement of one of
them is ``late``."""


@dataclass
class SttpSettings:
    """Where the STTP publisher is and how to read it (the ``[sttp]`` table of the mapping file)."""

    host: str = "127.0.0.1"
    port: int = 7165  # openPDC's default STTP data publisher port
    batch_s: float = 0.2  # frames gathered per bus before they are handed on [s]
    lag_s: float = 2.0  # a frame still missing measurements this long after its first one is incomplete [s]
    timeout_s: float = 10.0  # connected but no measurement for this long: the connection is renewed [s]
    backoff_s: tuple[float, float] = (0.5, 30.0)  # first and longest wait before reconnecting [s]
    angle_unit: str = "deg"  # of phasor angles: openPDC sends degrees; "rad" for publishers that do not
    compress: bool = True  # TSSC-compressed data (openPDC's default); false asks for compact measurements
    filter: str | None = None  # subscription filter expression; default: the mapping's devices (filter_expression)
    phasors: dict[str, tuple[str, str]] = field(default_factory=dict)  # name → (magnitude, angle) tags or IDs

    @classmethod
    def from_table(cls, table: dict) -> SttpSettings:
        """From the ``[sttp]`` table; unknown keys are an error naming them."""
        known = {"host", "port", "batch_s", "lag_s", "timeout_s", "backoff_s", "angle_unit", "compress", "filter", "phasors"}
        unknown = set(table) - known
        if unknown:
            raise MappingError(f"[sttp]: unknown key(s) {', '.join(sorted(unknown))}")
        s = cls(**{k: v for k, v in table.items() if k not in ("backoff_s", "phasors")})
        if "backoff_s" in table:
            s.backoff_s = tuple(float(x) for x in table["backoff_s"])
        for name, pair in table.get("phasors", {}).items():
            if not (isinstance(pair, dict) and set(pair) == {"mag", "ang"}):
                raise MappingError(f"[sttp.phasors].{name}: a table {{ mag = ..., ang = ... }}, got {pair!r}")
            s.phasors[name] = (str(pair["mag"]), str(pair["ang"]))
        if s.angle_unit not in ("deg", "rad"):
            raise MappingError(f"[sttp]: angle_unit must be 'deg' or 'rad', got {s.angle_unit!r}")
        return s


# --- names → signal IDs ---------------------------------------------------------------------------------


@dataclass
class BusSignals:
    """The signals one bus's frame is made of, in slot order: voltage (mag, ang) pairs, then the feeders'
    pairs or P and Q, then the frequency if the device has one."""

    bm: BusMap
    slots: list[uuid.UUID]
    n_voltage: int  # phasors in the voltage (1 or 3)
    feeder_sizes: list[int]  # phasors per feeder
    has_freq: bool


def _measurement(cache: Any, name: str, where: str):
    """The metadata record of a point tag, signal reference or signal ID."""
    rec = cache.find_measurement_pointtag(name) or cache.find_measurement_signalreference(name)
    if rec is None:
        try:
            rec = cache.find_measurement_signalid(uuid.UUID(name))
        except ValueError:
            rec = None
    if rec is None:
        raise MappingError(f"{where}: no measurement {name!r} (a point tag, signal reference or signal ID) "
                           f"in the publisher's metadata")
    return rec


def _phasor(cache: Any, device: Any, name: str, settings: SttpSettings, where: str) -> list[uuid.UUID]:
    if name in settings.phasors:
        mag, ang = settings.phasors[name]
        return [_measurement(cache, mag, where).signalid, _measurement(cache, ang, where).signalid]
    for p in device.phasors:
        if p.label == name and p.magnitude_measurement is not None and p.angle_measurement is not None:
            return [p.magnitude_measurement.signalid, p.angle_measurement.signalid]
    have = sorted(p.label for p in device.phasors)
    raise MappingError(f"{where}: device {device.acronym} has no phasor {name!r} with magnitude and angle "
                       f"measurements (it has {', '.join(have) or 'none'}; or name it in [sttp.phasors])")


def resolve(cache: Any, buses: Iterable[BusMap], settings: SttpSettings) -> list[BusSignals]:
    """Each bus's signals from the publisher's metadata (an ``sttp`` ``MetadataCache``).

    Raises
    ------
    MappingError
        Naming the bus, and what the publisher has, when a device, phasor or measurement is not there.
    """
    out = []
    for bm in buses:
        where = f"buses.{bm.bus}"
        device = cache.find_device_acronym(str(bm.pmu))
        if device is None:
            have = sorted(d.acronym for d in cache.device_records)
            raise MappingError(f"{where}: no device {bm.pmu!r} in the publisher's metadata "
                               f"(it has {', '.join(have) or 'none'})")
        slots = [s for n in bm.voltage for s in _phasor(cache, device, n, settings, where)]
        sizes = []
        if bm.power is not None:
            slots += [_measurement(cache, n, f"{where}.power").signalid for n in bm.power]
        for fd in bm.feeders:
            slots += [s for n in fd.phasors for s in _phasor(cache, device, n, settings, f"{where}.current")]
            sizes.append(len(fd.phasors))
        freq = sorted((m for m in device.measurements if m.signalacronym == "FREQ"), key=lambda m: m.pointtag)
        if freq:
            slots.append(freq[0].signalid)
        out.append(BusSignals(bm, slots, len(bm.voltage), sizes, bool(freq)))
    return out


def filter_expression(mapping: Mapping, settings: SttpSettings) -> str:
    """The subscription filter of a mapping: every measurement of its devices, and the measurements it names
    outright (``[sttp.phasors]``, ``power``) wherever they are.

    Known before any metadata arrives, so the subscription goes with the connection; measurements of
    those devices that no bus uses arrive too and are counted as ``unmapped``.  It holds no ``;``, which
    some publishers (``sttpapi``'s own) split the connection string on.
    """
    def quoted(names: Iterable[str]) -> str:
        return ", ".join("'" + n.replace("'", "''") + "'" for n in sorted(set(names)))

    named = [n for pair in settings.phasors.values() for n in pair]
    named += [n for bm in mapping.buses if bm.power is not None for n in bm.power]
    ids, tags = [], []
    for n in named:
        try:
            ids.append("{" + str(uuid.UUID(n)) + "}")
        except ValueError:
            tags.append(n)
    terms = [f"Device IN ({quoted(str(bm.pmu) for bm in mapping.buses)})"]
    if tags:
        terms += [f"PointTag IN ({quoted(tags)})", f"SignalReference IN ({quoted(tags)})"]
    if ids:
        terms.append(f"SignalID IN ({', '.join(sorted(set(ids)))})")
    return "FILTER ActiveMeasurements WHERE " + " OR ".join(terms)


# --- measurements → frames ------------------------------------------------------------------------------


class _Frame:
    """One bus's measurements of one timestamp, as they arrive."""

    __slots__ = ("values", "have", "n", "flags", "first")

    def __init__(self, size: int, first: float) -> None:
        # Lists, not arrays: they are written one scalar at a time, which numpy does several times slower.
        self.values = [math.nan] * size
        self.have = [False] * size  # a NaN value has arrived all the same
        self.n = 0
        self.flags = 0
        self.first = first  # arrival of its first measurement [s, monotonic]


class FrameAssembler:
    """Measurements of one timestamp gathered into one frame per bus, every measurement accounted for.

    Parameters
    ----------
    plans : list of BusSignals
    lag_s : float
        A frame still missing measurements this long after its first one arrived is dropped [s].
    angle_unit : str
        ``"deg"`` or ``"rad"``.
    adjust : dict
        Signal ID → (multiplier, adder) from the metadata, applied as ``value · multiplier + adder``.

    Notes
    -----
    Counters: ``measurements`` received = used + Σ ``bad_measurements`` (``unmapped``: a signal no bus
    uses; ``late``: its frame was already handed on or dropped; ``duplicate``: a second value for a
    filled slot); ``frames`` started = ``delivered`` + Σ ``rejected`` (``incomplete``) + pending.
    """

    def __init__(self, plans: list[BusSignals], *, lag_s: float, angle_unit: str = "deg",
                 adjust: dict[uuid.UUID, tuple[float, float]] | None = None) -> None:
        self.plans = plans
        self.lag_s = lag_s
        self.angle_scale = math.pi / 180.0 if angle_unit == "deg" else 1.0
        self.adjust = adjust or {}
        self.targets: dict[uuid.UUID, list[tuple[int, int]]] = {}
        for b, plan in enumerate(plans):
            for k, sid in enumerate(plan.slots):
                self.targets.setdefault(sid, []).append((b, k))
        self.pending: list[dict[int, _Frame]] = [{} for _ in plans]  # per bus: ticks → frame
        # Completed frames wait here for take(): one batch per bus and hand-on costs less than one per frame.
        self.ready: list[list[tuple[int, _Frame]]] = [[] for _ in plans]
        # Per bus, the timestamps lately handed on or dropped: publishers do not keep measurements of
        # successive timestamps in order, so "older than the newest handed on" does not mean late.
        self.closed: list[dict[int, None]] = [{} for _ in plans]
        self.measurements = self.frames = self.delivered = 0
        self.rejected: Counter[str] = Counter()
        self.bad_measurements: Counter[str] = Counter()
        self.flags: Counter[str] = Counter()

    def add(self, measurements: Iterable[Any], now: float | None = None) -> None:
        """Place measurements (``signalid``, ``value``, ``timestamp`` [ticks], ``flags``); completed frames wait
        for :meth:`take`."""
        now = time.monotonic() if now is None else now
        done = self.ready
        for m in measurements:
            self.measurements += 1
            targets = self.targets.get(m.signalid)
            if targets is None:
                self.bad_measurements["unmapped"] += 1
                continue
            ticks = int(m.timestamp) & TICKS_VALUE_MASK
            mult, add = self.adjust.get(m.signalid, (1.0, 0.0))
            value = float(m.value) * mult + add
            outcome = None
            for b, k in targets:
                frames = self.pending[b]
                frame = frames.get(ticks)
                if frame is None:
                    if ticks in self.closed[b]:
                        outcome = outcome or "late"
                        continue
                    frame = frames[ticks] = _Frame(len(self.plans[b].slots), now)
                    self.frames += 1
                if frame.have[k]:
                    outcome = outcome or "duplicate"
                    continue
                frame.values[k], frame.have[k] = value, True
                frame.n += 1
                frame.flags |= int(m.flags)
                outcome = "used"
                if frame.n == len(frame.values):
                    done[b].append((ticks, frames.pop(ticks)))
                    self._close(b, ticks)
                    self.delivered += 1
            if outcome != "used":
                self.bad_measurements[outcome or "late"] += 1

    def expire(self, now: float | None = None, *, everything: bool = False) -> None:
        """Drop frames whose first measurement is older than ``lag_s`` (all pending, with ``everything``)."""
        now = time.monotonic() if now is None else now
        for b, frames in enumerate(self.pending):
            old = [t for t, frame in frames.items() if everything or now - frame.first > self.lag_s]
            for t in old:
                del frames[t]
                self._close(b, t)
            if old:
                self.rejected["incomplete"] += len(old)

    def _close(self, b: int, ticks: int) -> None:
        closed = self.closed[b]
        closed[ticks] = None
        if len(closed) > CLOSED_KEEP:
            del closed[next(iter(closed))]

    def take(self) -> dict[str, FrameBatch]:
        """The frames completed since the last call, one batch per bus in time order."""
        out = {}
        for b, rows in enumerate(self.ready):
            if rows:
                rows.sort(key=lambda r: r[0])
                out[self.plans[b].bm.bus] = self._batch(self.plans[b], rows)
        self.ready = [[] for _ in self.plans]
        return out

    def _batch(self, plan: BusSignals, rows: list[tuple[int, _Frame]]) -> FrameBatch:
        t = (np.array([r[0] for r in rows], dtype=np.int64) - UNIX_TICKS) / 1e7
        vals = np.array([r[1].values for r in rows], dtype=np.float64)
        flags = np.array([r[1].flags for r in rows], dtype=np.int64)
        stat = (np.where(flags & BADDATA, STAT_PMU_ERROR, 0) | np.where(flags & BADTIME, STAT_NOT_SYNC, 0))
        for name, bit in (("bad_data", BADDATA), ("suspect_data", SUSPECTDATA), ("bad_time", BADTIME),
                          ("suspect_time", SUSPECTTIME)):
            n = int(np.count_nonzero(flags & bit))
            if n:
                self.flags[name] += n
        f = vals[:, -1] if plan.has_freq else None
        nv = plan.n_voltage
        v = self._phasors(vals[:, :2 * nv])
        voltage = v[:, 0] if nv == 1 else v
        stat = stat.astype(np.uint16)
        if plan.bm.power is not None:
            return power_batch(plan.bm, t, voltage, vals[:, 2 * nv], vals[:, 2 * nv + 1], f, stat)
        currents, at = [], 2 * nv
        for size in plan.feeder_sizes:
            z = self._phasors(vals[:, at:at + 2 * size])
            currents.append(z[:, 0] if size == 1 else z)
            at += 2 * size
        return bus_batch(plan.bm, t, voltage, currents, f, stat)

    def _phasors(self, pairs: np.ndarray) -> np.ndarray:
        """(n, 2k) magnitude/angle columns → (n, k) complex."""
        return pairs[:, 0::2] * np.exp(1j * pairs[:, 1::2] * self.angle_scale)

    def counts(self) -> dict:
        """Counters as plain JSON-able values."""
        return {"measurements": self.measurements, "frames": self.frames, "delivered": self.delivered,
                "rejected": dict(self.rejected), "bad_measurements": dict(self.bad_measurements),
                "flags": dict(self.flags), "pending": sum(len(p) for p in self.pending)}


# --- the subscriber -------------------------------------------------------------------------------------


class SttpClient:
    """A reconnecting STTP subscriber whose buses' frames go to ``emit(bus, batch)``.

    Parameters
    ----------
    settings : SttpSettings
    mapping : Mapping
    emit : callable
        ``emit(bus, FrameBatch)``, called from the subscriber's threads (one at a time).
    """

    name = "sttp"

    def __init__(self, settings: SttpSettings, mapping: Mapping, emit: Callable[[str, FrameBatch], None]) -> None:
        self.settings = settings
        self.mapping = mapping
        self.gather = Gatherer(emit, settings.batch_s)
        self.assembler: FrameAssembler | None = None
        self._retired: list[dict] = []  # counters of the assemblers of earlier metadata
        self.connects = 0
        self.disconnects: dict[str, int] = {}  # reason → count: "terminated" (by the socket), "silent", "dispose_stuck"
        self.configs = 0
        self.config_errors: list[str] = []
        self.no_config = 0  # measurements received while the mapping did not resolve against the metadata
        self.connected = threading.Event()
        self.resolved = threading.Event()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._sub = None
        self._last_data = time.monotonic()  # of the newest measurement or connection [s, monotonic]

    # --- life cycle -------------------------------------------------------------------------------

    def start_thread(self) -> None:
        """Connect (retrying with backoff) and keep handing frames on, in daemon threads, until :meth:`close`."""
        self._open()
        thread = threading.Thread(target=self._tick, name="sttp-batches", daemon=True)
        thread.start()
        self._threads.append(thread)

    def _open(self) -> None:
        """A new subscriber, connecting in a thread of its own; callbacks of earlier ones are ignored."""
        from sttp.subscriber import Subscriber

        sub = Subscriber()

        def current(callback):
            return lambda *args: callback(*args) if sub is self._sub else None

        sub.statusmessage_logger = lambda msg: log.debug("STTP: %s", msg)
        sub.errormessage_logger = current(lambda msg: log.warning("STTP %s:%d: %s", self.settings.host,
                                                                  self.settings.port, msg.strip()))
        sub.connectionestablished_receiver = current(self._on_connected)
        sub.connectionterminated_receiver = current(self._on_terminated)
        sub.metadatanotification_receiver = current(self._on_metadata)
        sub.newmeasurements_receiver = current(self._on_measurements)
        self._sub = sub
        self._last_data = time.monotonic()
        thread = threading.Thread(target=self._connect, args=(sub,), name="sttp-connect", daemon=True)
        thread.start()
        self._threads.append(thread)

    def _connect(self, sub: Any) -> None:
        from sttp.config import Config

        first, longest = self.settings.backoff_s
        # Metadata first, then the subscription: sttpapi subscribes once the metadata callback has returned, on
        # every connection.  (A subscription sent from within that callback delivered no data in trials, so
        # the filter is one known before any metadata.)
        config = Config(maxretries=-1, retryinterval=first, maxretryinterval=longest, autoreconnect=True,
                        autorequestmetadata=True, autosubscribe=True, compress_payloaddata=self.settings.compress)
        sub.subscribe(self.settings.filter or filter_expression(self.mapping, self.settings))
        err = sub.connect(f"{self.settings.host}:{self.settings.port}", config)
        if err is not None and not self._stop.is_set():
            log.error("STTP %s:%d: %s", self.settings.host, self.settings.port, err)

    def _tick(self) -> None:
        while not self._stop.wait(min(0.1, self.settings.batch_s)):
            with self._lock:
                if self.assembler is not None:
                    self.assembler.expire()
                if self.gather.due():
                    self._hand_on()
            if self.connected.is_set() and time.monotonic() - self._last_data > self.settings.timeout_s:
                self._reopen("silent")

    def _reopen(self, reason: str) -> None:
        """Drop the connection for a new subscriber (sttpapi reconnects only when the socket reports an end)."""
        log.warning("STTP %s:%d: %s for %.1f s; reconnecting", self.settings.host, self.settings.port, reason,
                    self.settings.timeout_s)
        self.disconnects[reason] = self.disconnects.get(reason, 0) + 1
        self.connected.clear()
        self.resolved.clear()
        old = self._sub
        self._open()
        threading.Thread(target=old.dispose, name="sttp-dispose", daemon=True).start()  # takes ~2 s

    def close(self) -> None:
        """Disconnect, drop the frames still incomplete (counted) and hand on what is held (idempotent)."""
        self._stop.set()
        if self._sub is not None:
            disposing = threading.Thread(target=self._sub.dispose, name="sttp-dispose", daemon=True)
            disposing.start()
            disposing.join(DISPOSE_WAIT_S)
            if disposing.is_alive():
                log.warning("STTP %s:%d: the subscriber did not dispose in %.0f s (sttpapi's reconnect); closing without it",
                            self.settings.host, self.settings.port, DISPOSE_WAIT_S)
                self.disconnects["dispose_stuck"] = self.disconnects.get("dispose_stuck", 0) + 1
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(5.0)
        with self._lock:
            if self.assembler is not None:
                self.assembler.expire(everything=True)
            self._hand_on()

    def _hand_on(self) -> None:
        """Everything completed, one batch per bus, to ``emit`` (under the lock)."""
        if self.assembler is not None:
            self.gather.add(self.assembler.take())
        self.gather.flush()

    def counts(self) -> dict:
        """Assembly counters (summed over metadata changes), connection counts and frames handed on."""
        with self._lock:
            parts = [*self._retired, *([self.assembler.counts()] if self.assembler is not None else [])]
        out: dict[str, Any] = {"measurements": 0, "frames": 0, "delivered": 0, "pending": 0}
        for key in ("rejected", "bad_measurements", "flags"):
            total: Counter[str] = Counter()
            for p in parts:
                total.update(p[key])
            out[key] = dict(total)
        for p in parts:
            for key in ("measurements", "frames", "delivered", "pending"):
                out[key] += p[key]
        if self.no_config:
            out["measurements"] += self.no_config
            out["bad_measurements"]["no_config"] = self.no_config
        return {**out, "configs": self.configs, "config_errors": list(self.config_errors),
                "connects": self.connects, "disconnects": dict(self.disconnects), "frames_out": self.gather.frames_out}

    # --- subscriber callbacks ---------------------------------------------------------------------

    def _on_connected(self) -> None:
        self.connects += 1
        self._last_data = time.monotonic()
        self.connected.set()

    def _on_terminated(self) -> None:
        self.disconnects["terminated"] = self.disconnects.get("terminated", 0) + 1
        self.connected.clear()
        self.resolved.clear()

    def _on_metadata(self, _dataset: Any) -> None:
        cache = self._sub.metadatacache
        try:
            plans = resolve(cache, self.mapping.buses, self.settings)
        except MappingError as exc:
            self.config_errors.append(str(exc))
            log.error("STTP %s:%d: %s; its measurements are counted as no_config", self.settings.host,
                      self.settings.port, exc)
            with self._lock:
                self._retire()
            return
        adjust = {}
        for plan in plans:
            for sid in plan.slots:
                rec = cache.find_measurement_signalid(sid)
                if rec is not None and (rec.multiplier != 1.0 or rec.adder != 0.0):
                    adjust[sid] = (float(rec.multiplier), float(rec.adder))
        with self._lock:
            self._retire()
            self.assembler = FrameAssembler(plans, lag_s=self.settings.lag_s, angle_unit=self.settings.angle_unit,
                                            adjust=adjust)
            self.configs += 1
        self.resolved.set()
        log.info("STTP %s:%d: metadata resolved, %d signals for %d bus(es)", self.settings.host,
                 self.settings.port, len(self.assembler.targets), len(plans))

    def _retire(self) -> None:
        """Close the current assembler's pending frames and keep its counters (under the lock)."""
        if self.assembler is not None:
            self.assembler.expire(everything=True)
            self.gather.add(self.assembler.take())
            self._retired.append(self.assembler.counts())
            self.assembler = None

    def _on_measurements(self, measurements: list) -> None:
        self._last_data = time.monotonic()
        with self._lock:
            if self.assembler is None:
                self.no_config += len(measurements)
            else:
                self.assembler.add(measurements)
                if self.gather.due():
                    self._hand_on()


class SttpSource:
    """The STTP subscriber as a source of ``aslm serve``: its batches go to the service's Inlet."""

    name = "sttp"

    def __init__(self, settings: SttpSettings, mapping: Mapping) -> None:
        self.settings = settings
        self.mapping = mapping
        self.client: SttpClient | None = None

    def start(self, inlet: Inlet) -> None:
        """Start the subscriber; its frames go to ``inlet.frames``."""
        self.client = SttpClient(self.settings, self.mapping, inlet.frames)
        self.client.start_thread()

    def close(self) -> None:
        """Stop the subscriber."""
        if self.client is not None:
            self.client.close()


def load(path) -> tuple[SttpSettings, Mapping]:
    """The STTP settings and mapping of a mapping file with an ``[sttp]`` table."""
    mapping = load_mapping(path, power=True)
    table = mapping.tables.get("sttp")
    if table is None:
        raise MappingError(f"{path}: no [sttp] table saying where the publisher is")
    return SttpSettings.from_table(table), mapping


def build(ctx: Context) -> SttpSource:
    """The STTP source of the settings' ``pmu_mapping`` file."""
    path = ctx.settings.pmu_mapping
    if path is None:
        raise MappingError("sources has 'sttp' but pmu_mapping (ASLM_PMU_MAPPING) names no mapping file")
    return SttpSource(*load(path))
