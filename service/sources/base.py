"""What a source of PMU frames is, and the one path its frames take into the bus buffers.

A source (Zenoh today; grid-protocol bridges and file readers next) is started with an :class:`Inlet`
and hands it what it receives: raw messages (:meth:`Inlet.message`: decode, validate, buffer) or batches
it decoded itself (:meth:`Inlet.frames`: validate, buffer).  Every outcome is counted in the
:class:`~service.buffers.BufferStore`, so drop accounting is the same whatever the source.
"""

from __future__ import annotations

from typing import Protocol

from service.buffers import BufferStore
from service.clock import SYSTEM_CLOCK, Clock
from service.frames import FrameBatch, FrameError, decode, validate

MAX_MESSAGE_BYTES = 1 << 20
"""Default limit on one message [bytes]: 1 MiB holds ~18,000 binary frames (6 min of one PMU at 50/s) or
~4,000 JSON ones; anything larger is refused (``too_large``) before it is decoded or copied."""


class Inlet:
    """The place frames go: decode (for raw messages), validate against the clock, buffer by bus.

    Parameters
    ----------
    store : BufferStore
    max_future_s : float
        Allowed clock skew of PMU timestamps ahead of the clock [s].
    f0 : float
        Nominal frequency [Hz].
    clock : Clock
        Arrival time of each message (default the system clock).
    max_message_bytes : int
        Larger messages are refused whole (``too_large``, no frame counted: they are not decoded) [bytes].

    Notes
    -----
    A bus name that breaks :mod:`service.busnames` (``*``, ``a/*/b``, an empty chunk) gets no buffer:
    its frames and messages are counted as ``bad_bus`` in the store's totals.
    """

    def __init__(self, store: BufferStore, *, max_future_s: float, f0: float, clock: Clock = SYSTEM_CLOCK,
                 max_message_bytes: int = MAX_MESSAGE_BYTES) -> None:
        self.store = store
        self.max_future_s = max_future_s
        self.f0 = f0
        self.clock = clock
        self.max_message_bytes = max_message_bytes

    def message(self, bus: str, payload: bytes, encoding: str) -> None:
        """Decode, validate and buffer one message of ``bus``.

        Parameters
        ----------
        bus : str
            Bus name (for Zenoh, the key expression after ``{prefix}/pmu/``).
        payload : bytes
        encoding : str
            Encoding of the message, e.g. ``application/json`` (selects the codec).
        """
        if len(payload) > self.max_message_bytes:
            self.store.reject_message(bus, "too_large", 0, arrival=self.clock.now())
            return
        try:
            batch = decode(payload, encoding)
        except FrameError as exc:
            self.store.reject_message(bus, exc.reason, exc.n, arrival=self.clock.now())
            return
        self.frames(bus, batch)

    def frames(self, bus: str, batch: FrameBatch) -> None:
        """Validate and buffer frames of ``bus`` that the source decoded itself."""
        now = self.clock.now()
        checked = validate(batch, now=now, max_future_s=self.max_future_s, f0=self.f0)
        self.store.add(bus, checked.good, checked.rejected, arrival=now)


class Source(Protocol):
    """A source of PMU frames: started with the :class:`Inlet` its frames go to, then closed."""

    name: str

    def start(self, inlet: Inlet) -> None:
        """Begin delivering frames to ``inlet`` (from this source's own threads or callbacks)."""
        ...

    def close(self) -> None:
        """Stop delivering and release what the source holds (idempotent)."""
        ...
