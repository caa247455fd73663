"""Publishing PMU frames onto Zenoh: a synthetic fleet with known truth, or recorded files, in real time."""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path

import numpy as np
import zenoh

from service.frames import BINARY_ENCODING, FrameBatch, encode_binary, encode_json

log = logging.getLogger(__name__)


class FramePublisher:
    """Per-bus Zenoh publishers on ``{prefix}/pmu/{bus}``: reliable, blocking congestion control.

    Parameters
    ----------
    session : zenoh.Session
    prefix : str
    encoding : {"binary", "json"}
        Payload codec (see :mod:`service.frames`).
    """

    def __init__(self, session: zenoh.Session, prefix: str, encoding: str = "binary") -> None:
        if encoding not in ("binary", "json"):
            raise ValueError(f"encoding must be 'binary' or 'json' (got {encoding!r})")
        self.session = session
        self.prefix = prefix
        self.encoding = encoding
        self._zenc = zenoh.Encoding(BINARY_ENCODING) if encoding == "binary" else zenoh.Encoding.APPLICATION_JSON
        self._pubs: dict[str, zenoh.Publisher] = {}
        self.frames_sent = 0
        self.messages_sent = 0

    def publisher(self, bus: str) -> zenoh.Publisher:
        pub = self._pubs.get(bus)
        if pub is None:
            pub = self._pubs[bus] = self.session.declare_publisher(
                f"{self.prefix}/pmu/{bus}", encoding=self._zenc,
                congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE,
            )
        return pub

    def send(self, bus: str, batch: FrameBatch) -> None:
        """Publish one batch of one bus."""
        payload = encode_binary(batch) if self.encoding == "binary" else encode_json(batch)
        self.publisher(bus).put(payload)
        self.frames_sent += len(batch)
        self.messages_sent += 1

    def close(self) -> None:
        for pub in self._pubs.values():
            try:
                pub.undeclare()
            except Exception:  # noqa: BLE001 - session may be closed already
                pass
        self._pubs.clear()


class FleetReplayer:
    """Streams a :class:`aslm_sim.fleet.SyntheticFleet` in real time, ``batch_s`` per message.

    Parameters
    ----------
    publisher : FramePublisher
    fleet : SyntheticFleet
        Its ``t0`` should be close to the current UTC time [s].
    batch_s : float
        Frames per message = batch_s · fs; a batch goes out once its last frame is in the past [s].
    """

    def __init__(self, publisher: FramePublisher, fleet, batch_s: float = 0.2) -> None:
        self.publisher = publisher
        self.fleet = fleet
        self.n_batch = max(1, int(round(batch_s * fleet.fs)))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def truth(self) -> dict[str, dict]:
        """bus → true parameters (``LoadTruth.to_dict()``)."""
        return {bus: tr.to_dict() for bus, tr in zip(self.fleet.bus_names, self.fleet.truths, strict=True)}

    def step(self) -> None:
        """Publish the next batch of every bus."""
        d = self.fleet.advance(self.n_batch)
        for i, bus in enumerate(self.fleet.bus_names):
            self.publisher.send(bus, FrameBatch(t=d["t"], V=d["V"][i], theta=d["theta"][i], P=d["P"][i],
                                                Q=d["Q"][i], f=d["f"][i]))

    def run(self, duration_s: float | None = None) -> None:
        """Publish in real time until stopped (or ``duration_s`` of wall time passed)."""
        end = None if duration_s is None else time.time() + duration_s
        dt = self.n_batch / self.fleet.fs
        next_t = self.fleet.t0 + (self.fleet._k + self.n_batch - 1) / self.fleet.fs
        while not self._stop.is_set() and (end is None or time.time() < end):
            wait = next_t - time.time()
            if wait > 0 and self._stop.wait(wait):
                break
            self.step()
            next_t += dt

    def start(self, duration_s: float | None = None) -> FleetReplayer:
        """Run in a background thread."""
        def body():
            try:
                self.run(duration_s)
            except BaseException as exc:  # noqa: BLE001 - reported to the owner
                self.error = exc
                log.exception("replayer stopped")
        self._thread = threading.Thread(target=body, name="aslm-replay", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10)


def replay_files(publisher: FramePublisher, paths: list[Path], *, batch_s: float = 0.2, loop: bool = False,
                 stop: threading.Event | None = None, mapping: str | Path | None = None) -> None:
    """Replay recorded windows (``.npz``/``.csv``, one bus per file named by its stem; COMTRADE, the
    ``mapping``'s buses) in real time.

    Times are re-stamped so the first frame is now; with ``loop`` the recordings repeat end to end.
    """
    from service.files import read_windows

    stop = stop or threading.Event()
    windows = [w for p in paths for w in read_windows(p, mapping=mapping)]
    start = time.time()
    offset = 0.0
    while not stop.is_set():
        span = 0.0
        cursors = [0] * len(windows)
        while not stop.is_set() and any(c < w.n for c, w in zip(cursors, windows, strict=True)):
            now = time.time()
            for k, w in enumerate(windows):
                t_rel = w.t - w.t[0]
                j = int(np.searchsorted(t_rel + start + offset, now, side="right"))
                if j > cursors[k]:
                    sl = slice(cursors[k], j)
                    publisher.send(w.bus, FrameBatch(
                        t=t_rel[sl] + start + offset, V=w.V[sl], theta=w.theta[sl], P=w.P[sl], Q=w.Q[sl],
                        f=None if w.f is None else w.f[sl]))
                    cursors[k] = j
                span = max(span, float(t_rel[-1]) + (w.dt if np.isfinite(w.dt) else 0.02))
            stop.wait(batch_s)
        if not loop:
            return
        offset += span


def write_truth(path: str | Path, truth: dict[str, dict]) -> None:
    """Write the fleet's true parameters as JSON."""
    Path(path).write_text(json.dumps(truth, indent=2))
