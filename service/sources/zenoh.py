"""Zenoh source: a subscriber on ``{prefix}/pmu/{pmu_keys}`` whose callback decodes, validates and buffers.

The callback stays tiny and vectorised: with reliable transport and blocking congestion control a slow
subscriber stalls the publishers (and a send queue blocked for 5 s closes the link), so nothing here
waits on anything but the bus's buffer lock.  Never a RingChannel here: it drops by design.
"""

from __future__ import annotations

import logging

import zenoh

from service.context import Context
from service.sources.base import Inlet

log = logging.getLogger(__name__)


class ZenohSource:
    """The PMU subscriber of one service instance.

    Parameters
    ----------
    session : zenoh.Session
    prefix : str
        Key-expression prefix.
    keys : str
        Key expression below ``{prefix}/pmu/`` to subscribe to (default ``**``: all buses).
    """

    name = "zenoh"

    def __init__(self, session: zenoh.Session, prefix: str, *, keys: str = "**") -> None:
        self.session = session
        self.prefix = prefix
        self.keys = keys
        self._skip = len(prefix) + len("/pmu/")
        self._inlet: Inlet | None = None
        self.subscriber: zenoh.Subscriber | None = None
        self.internal_errors = 0

    def start(self, inlet: Inlet) -> None:
        """Declare the subscriber; its samples go to ``inlet``."""
        self._inlet = inlet
        # keys narrows the subscription (sharding buses between instances); the bus name stays the full
        # remainder after {prefix}/pmu/.
        self.subscriber = self.session.declare_subscriber(f"{self.prefix}/pmu/{self.keys}", self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            bus = str(sample.key_expr)[self._skip:]
            self._inlet.message(bus, sample.payload.to_bytes(), str(sample.encoding))
        except Exception:  # noqa: BLE001 - bad input never kills the service
            self.internal_errors += 1
            if self.internal_errors <= 10:
                log.exception("ingest error on %s", sample.key_expr)

    def close(self) -> None:
        """Undeclare the subscriber."""
        if self.subscriber is None:
            return
        try:
            self.subscriber.undeclare()
        except Exception:  # noqa: BLE001 - session may already be closed
            pass
        self.subscriber = None


def build(ctx: Context) -> ZenohSource:
    """The Zenoh source of the settings' ``prefix`` and ``pmu_keys`` on the instance's session."""
    return ZenohSource(ctx.zenoh_session(), ctx.settings.prefix, keys=ctx.settings.pmu_keys)
