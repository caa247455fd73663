"""IEEE C37.118.2 source: a PDC-side client of a PMU or PDC, its buses' frames handed on per batch.

The client opens the TCP command channel, asks for the CFG-2, turns data on once it has it, and reads
data over the same TCP connection or, with ``transport = "udp"``, from its own UDP port (the PMU is set
up to send there).  A dropped or silent connection is reopened with exponential backoff; a stream whose
configuration changes (STAT bit 10, or a data frame that no longer fits) gets a new CFG-2 request.  What
cannot be decoded is counted by :class:`~service.protocols.c37118_stream.StreamDecoder`, with reasons.

Frames are gathered per bus and handed on every ``batch_s`` seconds, to the service's ``Inlet``
(``sources = ["c37118"]`` with ``pmu_mapping`` naming the mapping file) or to Zenoh by ``aslm bridge``.
"""

from __future__ import annotations

import logging
import selectors
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from service.context import Context
from service.frames import FrameBatch
from service.protocols import c37118 as c37
from service.protocols.c37118_stream import StreamDecoder
from service.protocols.mapping import Mapping, MappingError, load_mapping
from service.sources.base import Inlet

log = logging.getLogger(__name__)


@dataclass
class StreamSettings:
    """Where the C37.118 stream is and how to read it (the ``[c37118]`` table of the mapping file)."""

    host: str = "127.0.0.1"
    port: int = 4712
    idcode: int = 1
    transport: str = "tcp"  # "tcp" or "udp" (data); commands always over TCP
    udp_host: str = "0.0.0.0"
    udp_port: int = 4713
    batch_s: float = 0.2  # frames gathered per bus before they are handed on [s]
    timeout_s: float = 5.0  # no byte for this long: the connection is taken as dropped [s]
    backoff_s: tuple[float, float] = (0.5, 30.0)  # first and longest wait before reconnecting [s]

    @classmethod
    def from_table(cls, table: dict) -> StreamSettings:
        """From the ``[c37118]`` table; unknown keys are an error naming them."""
        known = {"host", "port", "idcode", "transport", "udp_host", "udp_port", "batch_s", "timeout_s",
                 "backoff_s"}
        unknown = set(table) - known
        if unknown:
            raise MappingError(f"[c37118]: unknown key(s) {', '.join(sorted(unknown))}")
        s = cls(**{k: v for k, v in table.items() if k != "backoff_s"})
        if "backoff_s" in table:
            s.backoff_s = tuple(float(x) for x in table["backoff_s"])
        if s.transport not in ("tcp", "udp"):
            raise MappingError(f"[c37118]: transport must be 'tcp' or 'udp', got {s.transport!r}")
        return s


class Gatherer:
    """Per-bus frames held until ``batch_s`` has passed, then handed on as one batch per bus."""

    def __init__(self, emit: Callable[[str, FrameBatch], None], batch_s: float) -> None:
        self.emit = emit
        self.batch_s = batch_s
        self._held: dict[str, list[FrameBatch]] = {}
        self._since = time.monotonic()
        self.frames_out = 0

    def add(self, batches: dict[str, FrameBatch]) -> None:
        """Hold one decoded run's batches; hand on all held if ``batch_s`` has passed."""
        for bus, b in batches.items():
            self._held.setdefault(bus, []).append(b)
        if self.due():
            self.flush()

    def due(self) -> bool:
        """Whether ``batch_s`` has passed since the last hand-on."""
        return time.monotonic() - self._since >= self.batch_s

    def flush(self) -> None:
        """Hand on everything held, one batch per bus."""
        held, self._held = self._held, {}
        self._since = time.monotonic()
        for bus, parts in held.items():
            b = parts[0] if len(parts) == 1 else _concat(parts)
            self.frames_out += len(b)
            self.emit(bus, b)


def _concat(parts: list[FrameBatch]) -> FrameBatch:
    def cat(name):
        cols = [getattr(p, name) for p in parts]
        return None if any(c is None for c in cols) else np.concatenate(cols)

    return FrameBatch(t=cat("t"), V=cat("V"), theta=cat("theta"), P=cat("P"), Q=cat("Q"), f=cat("f"),
                      stat=cat("stat"))


class C37118Client:
    """A reconnecting C37.118.2 client whose buses' frames go to ``emit(bus, batch)``.

    Parameters
    ----------
    stream : StreamSettings
    mapping : Mapping
    emit : callable
        ``emit(bus, FrameBatch)``, called from the client's thread.
    """

    name = "c37118"

    def __init__(self, stream: StreamSettings, mapping: Mapping, emit: Callable[[str, FrameBatch], None]) -> None:
        self.stream = stream
        self.mapping = mapping
        self.gather = Gatherer(emit, stream.batch_s)
        self.decoder = StreamDecoder(mapping.buses, self.gather.add, idcode=stream.idcode)
        self.connects = 0
        self.disconnects: dict[str, int] = {}
        self.connected = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None
        self._cfg_asked = 0.0

    # --- life cycle -------------------------------------------------------------------------------

    def start_thread(self) -> None:
        """Run the client in a daemon thread until :meth:`close`."""
        self._thread = threading.Thread(target=self.run, name="c37118", daemon=True)
        self._thread.start()

    def run(self) -> None:
        """Connect, read, reconnect with backoff, until :meth:`close`."""
        wait = self.stream.backoff_s[0]
        while not self._stop.is_set():
            reason = self._session()
            self.disconnects[reason] = self.disconnects.get(reason, 0) + 1
            if self._stop.is_set():
                break
            log.warning("C37.118 stream %s:%d: %s; reconnecting in %.1f s", self.stream.host, self.stream.port,
                        reason, wait)
            if self._stop.wait(wait):
                break
            wait = self.stream.backoff_s[0] if reason == "closed_after_data" else min(
                wait * 2, self.stream.backoff_s[1])

    def close(self) -> None:
        """Stop the client, turn the PMU's data off and hand on what is held (idempotent)."""
        self._stop.set()
        sock = self._sock
        if sock is not None:
            try:
                sock.sendall(c37.command(self.stream.idcode, c37.CMD_DATA_OFF))
            except OSError:
                pass
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(5.0)
        self.gather.flush()

    def counts(self) -> dict:
        """Decoder counters, connection counts and frames handed on."""
        return {**self.decoder.counts(), "connects": self.connects, "disconnects": dict(self.disconnects),
                "frames_out": self.gather.frames_out}

    # --- one connection ---------------------------------------------------------------------------

    def _send(self, cmd: int) -> None:
        now = time.time()
        self._sock.sendall(c37.command(self.stream.idcode, cmd, int(now), int((now % 1) * 1e6)))

    def _session(self) -> str:
        s = self.stream
        udp = None
        try:
            sock = socket.create_connection((s.host, s.port), timeout=s.timeout_s)
        except OSError as exc:
            return f"connect_failed: {exc.__class__.__name__}"
        self._sock = sock
        self.connects += 1
        got_data = False
        sel = selectors.DefaultSelector()
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.settimeout(None)
            sel.register(sock, selectors.EVENT_READ, "tcp")
            if s.transport == "udp":
                udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                udp.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                udp.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
                udp.bind((s.udp_host, s.udp_port))
                sel.register(udp, selectors.EVENT_READ, "udp")
            # One command per write and none before the CFG-2 request: simple PMUs read one frame per recv.
            self._send(c37.CMD_CFG2)
            self._cfg_asked = time.monotonic()
            self.connected.set()
            data_on = False  # turned on once this connection has brought a configuration
            configs_before = self.decoder.configs
            last_byte = time.monotonic()
            while not self._stop.is_set():
                events = sel.select(timeout=min(0.1, s.batch_s))
                now = time.monotonic()
                for key, _ in events:
                    if key.data == "tcp":
                        chunk = sock.recv(1 << 16)
                        if not chunk:
                            self.decoder.end()
                            return "closed_after_data" if got_data else "closed"
                        self.decoder.feed(chunk)
                    else:
                        self.decoder.feed(udp.recv(1 << 16))
                        self.decoder.end()  # a datagram holds whole frames: leftovers are truncated
                    last_byte = now
                got_data = got_data or self.decoder.frames > 0
                if self.decoder.configs > configs_before and not data_on:
                    self._send(c37.CMD_DATA_ON)
                    data_on = True
                if self.decoder.need_config and now - self._cfg_asked > 1.0:
                    self._send(c37.CMD_CFG2)
                    self._cfg_asked = now
                if self.gather.due():
                    self.gather.flush()
                if now - last_byte > s.timeout_s:
                    return "silent"
            return "stopped"
        except OSError as exc:
            return f"socket_error: {exc.__class__.__name__}"
        finally:
            self.connected.clear()
            self.gather.flush()
            sel.close()
            if udp is not None:
                udp.close()
            sock.close()
            self._sock = None


class C37118Source:
    """The C37.118 client as a source of ``aslm serve``: its batches go to the service's Inlet."""

    name = "c37118"

    def __init__(self, stream: StreamSettings, mapping: Mapping) -> None:
        self.stream = stream
        self.mapping = mapping
        self.client: C37118Client | None = None

    def start(self, inlet: Inlet) -> None:
        """Start the client thread; its frames go to ``inlet.frames``."""
        self.client = C37118Client(self.stream, self.mapping, inlet.frames)
        self.client.start_thread()

    def close(self) -> None:
        """Stop the client."""
        if self.client is not None:
            self.client.close()


def load(path) -> tuple[StreamSettings, Mapping]:
    """The stream settings and mapping of a mapping file with a ``[c37118]`` table."""
    mapping = load_mapping(path)
    table = mapping.tables.get("c37118")
    if table is None:
        raise MappingError(f"{path}: no [c37118] table saying where the stream is")
    return StreamSettings.from_table(table), mapping


def build(ctx: Context) -> C37118Source:
    """The C37.118 source of the settings' ``pmu_mapping`` file."""
    path = ctx.settings.pmu_mapping
    if path is None:
        raise MappingError("sources has 'c37118' but pmu_mapping (ASLM_PMU_MAPPING) names no mapping file")
    return C37118Source(*load(path))
