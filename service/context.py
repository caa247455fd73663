"""What the factories of sources and sinks are built from: the settings and the service's shared parts.

The Zenoh session is opened on first use, so a service whose sources and sinks need no Zenoh opens none
(and one that needs it opens one session, shared by the Zenoh source and the Zenoh sink).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from service.clock import SYSTEM_CLOCK, Clock
from service.latest import LatestResults
from service.metrics import ServiceMetrics
from service.settings import ServiceSettings
from service.storage import Storage

if TYPE_CHECKING:  # zenoh is imported only when a session is opened
    import zenoh

    from service.executors.base import Executor


@dataclass
class Context:
    """Settings and shared parts of one service instance.

    Attributes
    ----------
    settings : ServiceSettings
    storage : Storage
        The SQLite store (history, periods, configuration); also REST's read side.
    latest : LatestResults
        The latest result and diagnosis of each bus (answers the Zenoh "latest" queryable).
    metrics : ServiceMetrics
        ``request_errors`` counts what sources and sinks catch.
    clock : Clock
    executor : Executor or None
        The worker pool, set before the sinks are built (a sink may hand it background tasks: the
        tracking sink's joint fits); None outside a running service.
    tracked_listeners : list of callable
        Called with a bus whose tracked model changed between its results (a joint fit arrived); a sink
        that publishes from the tracked model (the records sink) adds itself when it is built.
    """

    settings: ServiceSettings
    storage: Storage
    latest: LatestResults
    metrics: ServiceMetrics
    clock: Clock = SYSTEM_CLOCK
    executor: Executor | None = None
    tracked_listeners: list[Callable[[str], None]] = field(default_factory=list)
    _session: zenoh.Session | None = field(default=None, init=False, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False)

    def zenoh_session(self) -> zenoh.Session:
        """The instance's Zenoh session, opened from the settings on first call."""
        with self._lock:
            if self._session is None:
                import zenoh

                from service.zenoh_config import from_settings

                self._session = zenoh.open(from_settings(self.settings))
            return self._session

    @property
    def zenoh_opened(self) -> bool:
        """Whether a source or sink has asked for the Zenoh session."""
        return self._session is not None

    def close(self) -> None:
        """Close the Zenoh session if one was opened (after the sources and sinks that use it)."""
        with self._lock:
            if self._session is not None:
                self._session.close()
                self._session = None
