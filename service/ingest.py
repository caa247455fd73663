"""Zenoh ingest: a subscriber on ``{prefix}/pmu/**`` whose callback decodes, validates and buffers.

The callback stays tiny and vectorised: with reliable transport and blocking congestion control a slow
subscriber stalls the publishers (and a send queue blocked for 5 s closes the link), so nothing here
waits on anything but the bus's buffer lock.  Never a RingChannel here: it drops by design.
"""

from __future__ import annotations

import logging
import time

import zenoh

from service.buffers import BufferStore
from service.frames import FrameError, decode, validate

log = logging.getLogger(__name__)


def handle_message(store: BufferStore, bus: str, payload: bytes, encoding: str, *, now: float,
                   max_future_s: float, f0: float) -> None:
    """Decode, validate and buffer one message of ``bus``; every outcome is counted in ``store``.

    Parameters
    ----------
    store : BufferStore
    bus : str
        Bus name (the key expression after ``{prefix}/pmu/``).
    payload : bytes
    encoding : str
        Zenoh encoding of the sample (selects the codec).
    now : float
        Arrival time, UTC [s].
    max_future_s : float
        Allowed clock skew of PMU timestamps ahead of ``now`` [s].
    f0 : float
        Nominal frequency [Hz].
    """
    try:
        batch = decode(payload, encoding)
    except FrameError as exc:
        store.reject_message(bus, exc.reason, exc.n)
        return
    checked = validate(batch, now=now, max_future_s=max_future_s, f0=f0)
    store.add(bus, checked.good, checked.rejected, arrival=now)


class Ingest:
    """The PMU subscriber of one service instance.

    Parameters
    ----------
    session : zenoh.Session
    prefix : str
        Key-expression prefix.
    store : BufferStore
    keys : str
        Key expression below ``{prefix}/pmu/`` to subscribe to (default ``**``: all buses).
    max_future_s, f0 : float
        Passed to :func:`handle_message`.
    """

    def __init__(self, session: zenoh.Session, prefix: str, store: BufferStore, *, max_future_s: float,
                 f0: float, keys: str = "**") -> None:
        self.store = store
        self._skip = len(prefix) + len("/pmu/")
        self._max_future_s = max_future_s
        self._f0 = f0
        self.internal_errors = 0
        # keys narrows the subscription (sharding buses between instances); the bus name stays the full
        # remainder after {prefix}/pmu/.
        self.subscriber = session.declare_subscriber(f"{prefix}/pmu/{keys}", self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            bus = str(sample.key_expr)[self._skip:]
            handle_message(self.store, bus, sample.payload.to_bytes(), str(sample.encoding), now=time.time(),
                           max_future_s=self._max_future_s, f0=self._f0)
        except Exception:  # noqa: BLE001 - bad input never kills the service
            self.internal_errors += 1
            if self.internal_errors <= 10:
                log.exception("ingest error on %s", sample.key_expr)

    def close(self) -> None:
        """Undeclare the subscriber."""
        try:
            self.subscriber.undeclare()
        except Exception:  # noqa: BLE001 - session may already be closed
            pass
