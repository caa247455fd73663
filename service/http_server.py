"""The REST API served by uvicorn in a daemon thread of the service's process."""

from __future__ import annotations

import threading
import time

import uvicorn
from fastapi import FastAPI


class HttpServer:
    """uvicorn in a thread.

    Parameters
    ----------
    app : FastAPI
    host : str
    port : int
        0: any free port (:attr:`port` tells which once started).
    """

    def __init__(self, app: FastAPI, host: str, port: int) -> None:
        self.host = host
        self._server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level="warning",
                                                     access_log=False))
        self._thread = threading.Thread(target=self._server.run, name="aslm-rest", daemon=True)
        self.port: int | None = None

    def start(self, timeout: float = 20.0) -> None:
        """Start serving; returns once the socket listens.

        Raises
        ------
        RuntimeError
            The server did not start within ``timeout`` [s] (e.g. the port is taken).
        """
        self._thread.start()
        end = time.monotonic() + timeout
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() > end:
                raise RuntimeError(f"REST server did not start on {self.host}:{self._server.config.port}")
            time.sleep(0.02)
        self.port = self._server.servers[0].sockets[0].getsockname()[1]

    def stop(self, timeout: float = 10.0) -> None:
        """Ask uvicorn to exit and join its thread."""
        self._server.should_exit = True
        self._thread.join(timeout)
