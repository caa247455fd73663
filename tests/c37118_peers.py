"""Independent C37.118.2 peers for the bridge's tests: the ``synchrophasor`` package (2017, test-only).

``synchrophasor.pmu.Pmu`` is a TCP PMU server (one forked process per PDC connection) that answers
commands and sends the frames queued with ``Pmu.send``.  It has no UDP data path, so :class:`UdpPmu`
answers commands on TCP itself and sends the package's own encoded frames as datagrams.  Frames are
always encoded by the package (``ConfigFrame2``/``DataFrame.convert2bytes``), never by the code under
test.

The package predates Python 3.10: its ``set_time`` names ``collections.Sequence``, restored here.
"""

from __future__ import annotations

import collections
import collections.abc
import logging
import socket
import threading

import numpy as np

collections.Sequence = collections.abc.Sequence  # noqa: B010 - the 2017 package's alias, gone in 3.10

from synchrophasor.frame import CommandFrame, CommonFrame, ConfigFrame2, DataFrame  # noqa: E402
from synchrophasor.pmu import Pmu  # noqa: E402

Pmu.logger.setLevel(logging.WARNING)

V_UNIT, I_UNIT = 915527, 45776  # PHUNIT in 1e-5 V or A per count (the package's own sample values)
PHASORS = ["VA", "VB", "VC", "I1"]
A = np.exp(2j * np.pi / 3)  # the 120° operator of symmetrical components
STAT_OK = ("ok", True, "timestamp", False, False, False, 0, "<10", 0)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    s = socket.socket(socket.AF_INET, kind)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def config2(idcode: int, *, polar: bool = False, floating: bool = False, rate: int = 50,
            station: str = "Station A", fnom: int = 50) -> ConfigFrame2:
    """A one-PMU CFG-2 of the package: three phase voltages and one current."""
    fmt = (polar, floating, floating, floating)  # (polar, phasor float, analog float, freq float)
    units = [(V_UNIT, "v")] * 3 + [(I_UNIT, "i")]
    return ConfigFrame2(idcode, 1000000, 1, station, idcode, fmt, 4, 0, 0, PHASORS, units, [], [], fnom, 1, rate)


def data_frame(cfg: ConfigFrame2, t: float, phasors: list[complex], freq_dev: float = 0.0,
               stat=STAT_OK) -> tuple[DataFrame, np.ndarray]:
    """The package's data frame at time ``t`` with phasors given in volts/amperes, and what it carries.

    Integer formats are quantised here as a PMU does (counts of PHUNIT × 1e-5, angles in 1e-4 rad);
    float ones are rounded to float32.  The second value is the phasors the frame carries, in volts and
    amperes, worked out from those counts: what a right decoder must read.
    """
    polar, floating = cfg.get_data_format()[:2]
    units = [V_UNIT * 1e-5] * 3 + [I_UNIT * 1e-5]
    values, carried = [], []
    for z, u in zip(phasors, units, strict=True):
        if floating:
            a, b = (abs(z), np.angle(z)) if polar else (z.real, z.imag)
            a, b = float(np.float32(a)), float(np.float32(b))
        else:
            zc = z / u
            a, b = (round(abs(zc)), round(np.angle(zc) * 1e4)) if polar else (round(zc.real), round(zc.imag))
        values.append((a, b))
        scale = 1.0 if floating else u
        ang = b if floating else b * 1e-4
        carried.append(a * scale * np.exp(1j * ang) if polar else complex(a, b) * scale)
    freq = freq_dev if floating else int(round(freq_dev * 1e3))
    df = DataFrame(cfg.get_id_code(), stat, values, freq, 0, [], [], cfg)
    soc = int(t)
    df.set_soc(soc)
    df.set_frasec(min(int(round((t - soc) * 1e6)), 999999))
    return df, np.array(carried)


class SynchroPmu:
    """The package's TCP PMU server on 127.0.0.1 (``send`` queues frames for the connected PDCs)."""

    def __init__(self, cfg: ConfigFrame2, *, send_rate: float = 1000.0) -> None:
        self.port = free_port()
        # The server sleeps 1/data_rate between frames: a high send rate replays faster than real time.
        self.pmu = Pmu(pmu_id=cfg.get_id_code(), data_rate=send_rate, port=self.port, ip="127.0.0.1",
                       set_timestamp=False)
        self.pmu.set_configuration(cfg)
        self.pmu.set_header("ASLM test peer")
        self.pmu.acceptor = self._acceptor  # run() starts its listener thread on this
        self.pmu.run()

    def _acceptor(self) -> None:
        """The package's accept loop, ended quietly when :meth:`close` shuts the listening socket."""
        try:
            Pmu.acceptor(self.pmu)
        except OSError:
            pass

    def send(self, frame) -> None:
        self.pmu.send(frame)

    def clients(self) -> int:
        return len(self.pmu.client_buffers)

    def close(self) -> None:
        """Stop the listener, then the connection handlers (each polls its socket without sleeping).

        The listener first: closing the socket alone leaves the thread blocked in accept() on it, still
        accepting, and each connection it accepts forks a handler that spins once its peer goes (a handler
        forked while another thread is inside ``subprocess.Popen`` also holds that child's exec pipe open,
        which hung a later test).  shutdown() wakes the accept with an error.
        """
        try:
            self.pmu.socket.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.pmu.listener.join(5)
        for p in self.pmu.clients:
            p.terminate()
            p.join(5)
        self.pmu.clients.clear()
        self.pmu.socket.close()


class UdpPmu:
    """A PMU answering commands on TCP with the package's frames and sending data frames over UDP."""

    def __init__(self, cfg: ConfigFrame2, udp_port: int) -> None:
        self.cfg = cfg
        self.udp_port = udp_port
        self.port = free_port()
        self.commands: list[str] = []
        self.data_on = threading.Event()
        self._srv = socket.create_server(("127.0.0.1", self.port))
        self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._conn: socket.socket | None = None
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self._srv.accept()
            except OSError:
                return
            self._conn = conn
            buf = b""
            while True:
                try:
                    chunk = conn.recv(4096)
                except OSError:
                    break
                if not chunk:
                    break
                buf += chunk
                while len(buf) >= 4 and len(buf) >= int.from_bytes(buf[2:4], "big"):
                    size = int.from_bytes(buf[2:4], "big")
                    frame, buf = CommonFrame.convert2frame(buf[:size]), buf[size:]
                    if isinstance(frame, CommandFrame):
                        self._command(conn, frame.get_command())
            self.data_on.clear()

    def _command(self, conn: socket.socket, cmd: str) -> None:
        self.commands.append(cmd)
        if cmd == "cfg2":
            conn.sendall(self.cfg.convert2bytes())
        elif cmd == "start":
            self.data_on.set()
        elif cmd == "stop":
            self.data_on.clear()

    def send(self, frame) -> None:
        """One datagram (a frame of the package, or raw bytes)."""
        data = frame if isinstance(frame, bytes) else frame.convert2bytes()
        self._udp.sendto(data, ("127.0.0.1", self.udp_port))

    def close(self) -> None:
        self._srv.close()
        if self._conn is not None:
            self._conn.close()
        self._udp.close()
