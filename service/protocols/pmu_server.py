"""A small C37.118.2 PMU on TCP that plays recorded data frames, re-stamped to the present.

It answers a PDC's commands (CFG-2 → its configuration, data on/off) and, while data is on, sends the
frames at the configuration's rate, each re-stamped (SOC, FRACSEC and CRC) to the time it is sent, so a
recording from 2007 is accepted as live data.  Used by ``aslm replay --pmu-port`` (a capture served to
the bridge), the end-to-end run of the real recording, and the bridge benchmark.
"""

from __future__ import annotations

import logging
import math
import socket
import struct
import threading
import time

from service.protocols import c37118 as c37

log = logging.getLogger(__name__)


def restamp(frame: bytes, t: float, time_base: int) -> bytes:
    """``frame`` with SOC/FRACSEC set to ``t`` [s] (time-quality bits kept) and its CRC redone."""
    soc = int(math.floor(t))
    frac = min(round((t - soc) * time_base), time_base - 1)
    (old,) = struct.unpack_from(">I", frame, 10)
    head = frame[:6] + struct.pack(">II", soc, (old & 0xFF000000) | frac) + frame[14:-2]
    return head + struct.pack(">H", c37.crc_ccitt(head))


class CapturePmu:
    """Serve ``frames`` of ``cfg`` as a PMU on ``host:port`` (one PDC at a time).

    Parameters
    ----------
    cfg : Config
        The configuration sent for a CFG-2 request.
    frames : list of bytes
        Data frames of ``cfg``, played in order.
    loop : bool
        Start again at the first frame after the last.
    rate : float, optional
        Frames per second to send (default the configuration's).
    """

    def __init__(self, cfg: c37.Config, frames: list[bytes], *, host: str = "127.0.0.1", port: int = 0,
                 loop: bool = False, rate: float | None = None) -> None:
        self.cfg = cfg
        self.frames = frames
        self.loop = loop
        self.rate = rate or cfg.data_rate
        self.server = socket.create_server((host, port))
        self.port = self.server.getsockname()[1]
        self.sent = 0
        self.commands: list[int] = []
        self.finished = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="capture-pmu", daemon=True)

    def start(self) -> CapturePmu:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        self.server.close()
        self._thread.join(5)

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.server.accept()
            except OSError:
                return
            with conn:
                self._session(conn)

    def _commands(self, conn: socket.socket, buf: bytearray) -> tuple[bool, bool | None]:
        """Answer the commands available now: (PDC still connected, data on/off or None if not said)."""
        state = None
        try:
            chunk = conn.recv(4096)
        except BlockingIOError:
            return True, state
        if not chunk:
            return False, state
        buf += chunk
        while len(buf) >= 4 and len(buf) >= (size := struct.unpack_from(">H", buf, 2)[0]) >= c37.MIN_FRAME:
            frame, buf[:] = bytes(buf[:size]), buf[size:]
            try:
                f = c37.parse(frame)
            except c37.C37Error:
                continue
            if f.ftype != c37.COMMAND:
                continue
            (cmd,) = struct.unpack_from(">H", f.body, 0)
            self.commands.append(cmd)
            if cmd in (c37.CMD_CFG2, c37.CMD_CFG1):
                now = time.time()
                conn.sendall(c37.encode_config(self.cfg, int(now), int((now % 1) * self.cfg.time_base)))
            elif cmd in (c37.CMD_DATA_ON, c37.CMD_DATA_OFF):
                state = cmd == c37.CMD_DATA_ON
        return True, state

    def _session(self, conn: socket.socket) -> None:
        conn.setblocking(False)
        buf = bytearray()
        on, k = False, 0
        period = 1.0 / self.rate
        next_t = 0.0
        while not self._stop.is_set():
            try:
                alive, state = self._commands(conn, buf)
            except OSError:
                return
            if not alive:
                return
            if state is not None:
                on = state
                # stamps on the rate's grid, from the next whole frame period
                next_t = math.ceil(time.time() * self.rate) / self.rate
            if not on:
                time.sleep(0.01)
                continue
            wait = next_t - time.time()
            if wait > 0:
                time.sleep(min(wait, 0.05))
                continue
            if k >= len(self.frames):
                if not self.loop:
                    self.finished.set()
                    time.sleep(0.05)
                    continue
                k = 0
            try:
                conn.setblocking(True)
                conn.sendall(restamp(self.frames[k], next_t, self.cfg.time_base))
                conn.setblocking(False)
            except OSError:
                return
            self.sent += 1
            k += 1
            next_t += period


def capture_stream(path, idcode: int = 1) -> tuple[c37.Config, list[bytes]]:
    """The configuration and data frames of a capture file, to serve with :class:`CapturePmu`.

    ``.pcap``: what the PMU (port 4712) sent, as C37.118.2 frames; anything else is read as IEEE 1344
    frames and re-encoded (``idcode`` is then the stream's IDCODE).

    Raises
    ------
    ValueError
        A capture without a configuration or without data frames of it.
    """
    from pathlib import Path

    if Path(path).suffix.lower() in (".pcap", ".cap"):
        from service.readers.pcap import pmu_payload

        payload, cfg, frames, pos = pmu_payload(path), None, [], 0
        while True:
            off, size = c37.split(payload, pos)
            if not size or off + size > len(payload):
                break
            frame = c37.parse(payload[off: off + size])
            if frame.ftype in (c37.CFG1, c37.CFG2) and cfg is None:
                cfg = c37.parse_config(frame)
            elif frame.ftype == c37.DATA and cfg is not None and size == cfg.data_size:
                frames.append(payload[off: off + size])
            pos = off + size
    else:
        from service.readers.ieee1344 import read_1344, to_c37118

        cfg, frames = to_c37118(read_1344(path), idcode=idcode)
    if cfg is None or not frames:
        raise ValueError(f"{path}: no configuration, or no data frames of it")
    return cfg, frames
