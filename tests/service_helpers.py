"""Helpers of the service tests: free ports, Zenoh sessions on 127.0.0.1, stand-in identify functions.

The stand-in functions run inside the real spawned worker processes (imported by ``module:function``);
they replace only the numerics, for tests about scheduling, crashes and restarts.
"""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

import httpx
import numpy as np
import zenoh

from service.settings import load_settings
from service.zenoh_config import zenoh_config

HERE = Path(__file__).resolve().parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def settings_for(tmp_path: Path, zport: int, **overrides):
    """Service settings on loopback: Zenoh listening on tcp/127.0.0.1:zport, REST on a free port."""
    base = dict(
        zenoh_listen=[f"tcp/127.0.0.1:{zport}"], zenoh_connect=[], zenoh_multicast_scouting=False,
        http_host="127.0.0.1", http_port=0, storage_url=str(tmp_path / "aslm.sqlite"), workers=2,
        operator_token="op-secret", instance=f"test-{zport}",
    )
    base.update(overrides)
    return load_settings(**base)


def client_session(zport: int) -> zenoh.Session:
    """A peer session connecting to the service's endpoint only."""
    return zenoh.open(zenoh_config("peer", connect=[f"tcp/127.0.0.1:{zport}"], listen=[]))


def wait_for(predicate, timeout: float, interval: float = 0.2):
    """Poll until predicate() is truthy; return its value or raise TimeoutError."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    raise TimeoutError(f"condition not met within {timeout} s")


def periods(url: str) -> list[dict]:
    return httpx.get(f"{url}/periods", timeout=5).json()


def fake_identify(task) -> dict:
    """Stand-in numerics: D from the warm start if any (else fixed), mean P as Tm, a few ms of work."""
    d = list(task.warm_start) if task.warm_start is not None else [40.0, 10.0, 1.0, 0.3]
    d[0] += 1.0  # successive periods differ: shows the warm start was used
    return {
        "dynamic": dict(zip(("a", "b", "H2", "Tm"), d, strict=True)),
        "static": {"Pz": 0.0, "Pi": 0.0, "Pp": float(np.mean(task.window.P)), "Qz": 0.0, "Qi": 0.0, "Qp": 0.0},
        "objective": 0.0, "fit": {"fd_p": 1.0, "fd_q": 1.0}, "elapsed_s": 0.001,
        "warm_start_given": task.warm_start is not None, "n_starts": task.options.get("n_starts"),
    }


def hang_once_identify(task) -> dict:
    """Hangs (until killed) on the bus named in $ASLM_TEST_HANG_BUS the first time only."""
    marker = Path(os.environ["ASLM_TEST_MARKER"])
    if task.bus == os.environ.get("ASLM_TEST_HANG_BUS") and not marker.exists():
        marker.write_text(str(os.getpid()))
        time.sleep(600)
    return fake_identify(task)


class NoiseStreamer:
    """Real-time stream of simple ambient-like frames for a few buses (no physics: for scheduling tests)."""

    def __init__(self, session: zenoh.Session, buses: list[str], prefix: str = "aslm", fs: float = 50.0,
                 batch: int = 10) -> None:
        import threading

        from service.replay import FramePublisher

        self.pub = FramePublisher(session, prefix)
        self.buses, self.fs, self.batch = buses, fs, batch
        self.rng = np.random.default_rng(0)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        from service.frames import FrameBatch

        k = int(time.time() * self.fs) - 5 * int(self.fs)  # start 5 s in the past: windows fill sooner
        while not self._stop.is_set():
            t = (k + np.arange(self.batch)) / self.fs
            if t[-1] > time.time():
                self._stop.wait(t[-1] - time.time())
                continue
            for bus in self.buses:
                n = self.batch
                self.pub.send(bus, FrameBatch(t=t, V=1 + 0.01 * self.rng.standard_normal(n),
                                              theta=0.01 * self.rng.standard_normal(n),
                                              P=0.8 + 0.01 * self.rng.standard_normal(n),
                                              Q=0.3 + 0.01 * self.rng.standard_normal(n)))
            k += self.batch

    def start(self) -> NoiseStreamer:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.pub.close()


def nan_for_b02_identify(task) -> dict:
    """Returns a non-finite D for bus b02 (an identifier bug), normal results for the others."""
    out = fake_identify(task)
    if task.bus == "b02":
        out["dynamic"]["a"] = float("nan")
    return out


def crash_identify(task) -> dict:
    """Kills its worker process (no exception, no answer) on the bus named in $ASLM_TEST_CRASH_BUS."""
    if task.bus == os.environ.get("ASLM_TEST_CRASH_BUS"):
        os._exit(3)
    time.sleep(0.005)
    return fake_identify(task)


def unpicklable_identify(task) -> dict:
    """Returns a value that cannot be sent back to the parent (a lambda) for bus "bad"."""
    out = fake_identify(task)
    if task.bus == "bad":
        out["oops"] = lambda: None
    return out


def slow_identify(task) -> dict:
    """fake_identify after 0.3 s of wall time (a stand-in for a diagnosis, ~0.7 s in the service)."""
    time.sleep(0.3)
    return fake_identify(task)
