"""A sharded fleet on loopback: a Zenoh router, ``aslm serve`` processes, a log of their results.

Used by the sharding test (``tests/service/test_service_sharding.py``) and the takeover benchmark
(``benchmarks/bench_takeover.py``): every instance is a real ``aslm serve`` process with the
``zenoh-sharded`` source, in Zenoh client mode on a router-mode session of this process, so killing
one (SIGKILL) is a crash as the router sees it.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import zenoh

from service.models import BusResult
from service.zenoh_config import zenoh_config


def router(port: int) -> zenoh.Session:
    """A router-mode Zenoh session listening on ``tcp/127.0.0.1:port`` (the deployment's ``zenohd``)."""
    return zenoh.open(zenoh_config("router", listen=[f"tcp/127.0.0.1:{port}"]))


def client(port: int) -> zenoh.Session:
    """A client-mode session of the router on ``port``."""
    return zenoh.open(zenoh_config("client", connect=[f"tcp/127.0.0.1:{port}"], listen=[]))


class Instance:
    """One ``aslm serve`` process of the fleet.

    Parameters
    ----------
    name : str
        Instance name (its liveliness token; the same name after a restart owns the same buses).
    router_port : int
    workdir : Path
        Its SQLite file and log go here.
    http_port : int
    settings : dict
        Further ``ASLM_*`` settings (field → value), e.g. ``period_s``.
    pythonpath : list of str
        Added to ``PYTHONPATH`` (where a stand-in ``identify_fn`` lives).
    """

    def __init__(self, name: str, router_port: int, workdir: Path, http_port: int, settings: dict,
                 pythonpath: list[str] = ()) -> None:
        self.name = name
        self.http_port = http_port
        env = {k: v for k, v in os.environ.items() if not k.startswith("ASLM_")}
        env["PYTHONPATH"] = os.pathsep.join([*pythonpath, *filter(None, [env.get("PYTHONPATH")])])
        values = {
            "instance": name, "zenoh_mode": "client", "zenoh_connect": [f"tcp/127.0.0.1:{router_port}"],
            "zenoh_listen": [], "http_host": "127.0.0.1", "http_port": http_port, "sources": ["zenoh-sharded"],
            "storage_url": str(workdir / f"{name}.sqlite"), **settings,
        }
        env.update({f"ASLM_{k.upper()}": v if isinstance(v, str) else json.dumps(v) for k, v in values.items()})
        self.log_path = workdir / f"{name}.log"
        self._log = open(self.log_path, "ab")
        self.process = subprocess.Popen([sys.executable, "-m", "service.cli", "serve", "--log-level", "INFO"],
                                        env=env, stdout=self._log, stderr=subprocess.STDOUT)

    @property
    def url(self) -> str:
        """Base URL of its REST API."""
        return f"http://127.0.0.1:{self.http_port}"

    def kill(self) -> None:
        """SIGKILL: no goodbye to the router, the way a crashed host leaves."""
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(10)
        self._log.close()

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after 10 s."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)
        self._log.close()


class ResultLog:
    """Every result published on ``{prefix}/params/**``: (bus, period) → statuses, as they arrive."""

    def __init__(self, session: zenoh.Session, prefix: str = "aslm") -> None:
        self.by_period: dict[float, Counter] = {}
        self.skipped: dict[float, Counter] = {}
        self._lock = threading.Lock()
        self.subscriber = session.declare_subscriber(f"{prefix}/params/**", self._on_result)

    def _on_result(self, sample: zenoh.Sample) -> None:
        res = BusResult.model_validate_json(sample.payload.to_bytes())
        with self._lock:
            target = self.by_period if res.status == "ok" else self.skipped
            target.setdefault(res.period, Counter())[res.bus] += 1

    def identified(self, period: float) -> Counter:
        """bus → times identified (status ok) for ``period``."""
        with self._lock:
            return Counter(self.by_period.get(period, Counter()))

    def exactly_once(self, period: float, buses: list[str]) -> bool:
        """Whether every bus of ``buses`` was identified once, and no other, for ``period``."""
        return self.identified(period) == Counter(dict.fromkeys(buses, 1))

    def close(self) -> None:
        """Stop logging."""
        self.subscriber.undeclare()


def wait_until(t: float) -> None:
    """Sleep until wall time ``t`` [s]."""
    while (d := t - time.time()) > 0:
        time.sleep(min(d, 0.5))


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class Fleet:
    """A router, a stream of frames, a :class:`ResultLog` and named :class:`Instance` s (a context manager).

    Parameters
    ----------
    names : list of str
        Instances started at once.
    buses : list of str
    workdir : Path
    settings : dict
        ``ASLM_*`` settings of every instance (see :class:`Instance`).
    streamer : callable
        ``streamer(session, buses)`` returns an object with ``start()`` (returning itself) and
        ``stop()`` that publishes the buses' frames.
    pythonpath : list of str
    """

    def __init__(self, names: list[str], buses: list[str], workdir: Path, settings: dict,
                 streamer: Callable, pythonpath: list[str] = ()) -> None:
        self.workdir, self.settings, self.pythonpath = workdir, settings, list(pythonpath)
        self.router_port = free_port()
        self.hub = router(self.router_port)
        self.sessions = [client(self.router_port), client(self.router_port)]
        self.log = ResultLog(self.sessions[0])
        self.streamer = streamer(self.sessions[1], buses).start()
        self.instances: dict[str, Instance] = {}
        for name in names:
            self.start(name)

    def start(self, name: str) -> Instance:
        """Start (or start again) the instance ``name``."""
        self.instances[name] = Instance(name, self.router_port, self.workdir, free_port(), self.settings,
                                        pythonpath=self.pythonpath)
        return self.instances[name]

    def close(self) -> None:
        """Stop every instance, the stream, the log and the sessions."""
        for inst in self.instances.values():
            inst.stop()
        self.streamer.stop()
        self.log.close()
        for session in [*self.sessions, self.hub]:
            session.close()

    def __enter__(self) -> Fleet:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
