"""Which live service instance owns which bus: rendezvous hashing over the instances' liveliness tokens.

Every instance of a fleet declares the liveliness token ``{prefix}/service/{instance}`` (the Zenoh
sink does); :class:`Membership` follows those tokens through a Zenoh router, and :func:`owner` maps a
bus to one of the live instances.  Every instance computes the same map from the same tokens, with no
coordination: rendezvous (highest random weight) hashing.  When an instance leaves, only its buses
move (spread over the survivors); when it returns, exactly those come back to it.
"""

from __future__ import annotations

import hashlib
import logging
import threading
from collections.abc import Callable, Iterable

log = logging.getLogger(__name__)


def _seeds(instances: Iterable[str]) -> list[tuple[str, object]]:
    # blake2b rather than hash(): the same on every host and interpreter (str hashes are salted).  Each
    # instance's hash state is prepared once and copied per bus (half the cost of hashing both).
    return [(inst, hashlib.blake2b(f"{inst}\0".encode(), digest_size=8)) for inst in sorted(set(instances))]


def _owner(bus: str, seeds: list[tuple[str, object]]) -> str | None:
    key = bus.encode()
    best, best_w = None, b""
    for inst, seed in seeds:  # sorted by name: a tie (never seen with 64 bits) goes to the first
        h = seed.copy()
        h.update(key)
        w = h.digest()
        if best is None or w > best_w:
            best, best_w = inst, w
    return best


def owner(bus: str, instances: Iterable[str]) -> str | None:
    """The instance that owns ``bus`` among ``instances`` (None if there is none).

    Parameters
    ----------
    bus : str
        Bus name (the key expression after ``{prefix}/pmu/``).
    instances : iterable of str
        Names of the live instances.
    """
    return _owner(bus, _seeds(instances))


def owned(buses: Iterable[str], instances: Iterable[str], instance: str) -> set[str]:
    """The buses among ``buses`` that ``instance`` owns when ``instances`` are live."""
    seeds = _seeds([*instances, instance])
    return {bus for bus in buses if _owner(bus, seeds) == instance}


class Membership:
    """The live instances of a fleet, from their liveliness tokens ``{prefix}/service/{instance}``.

    Parameters
    ----------
    session : zenoh.Session
    prefix : str
    instance : str
        This instance's name: always counted live (its own token may reach the router after this
        subscriber starts).
    on_change : callable
        Called (from a Zenoh thread: it must not block) after an instance appears or disappears.
    """

    def __init__(self, session, prefix: str, instance: str, on_change: Callable[[], None]) -> None:
        self.instance = instance
        self._skip = len(prefix) + len("/service/")
        self._live: set[str] = {instance}
        self._lock = threading.Lock()
        self._on_change = on_change
        # history: the tokens already alive are delivered too, so a starting instance sees the fleet.
        self.subscriber = session.liveliness().declare_subscriber(f"{prefix}/service/*", self._on_token,
                                                                  history=True)

    def _on_token(self, sample) -> None:
        import zenoh

        name = str(sample.key_expr)[self._skip:]
        with self._lock:
            before = set(self._live)
            if sample.kind == zenoh.SampleKind.PUT:
                self._live.add(name)
            elif name != self.instance:
                self._live.discard(name)
            changed = self._live != before
        if changed:
            log.info("instances now %s", sorted(self._live))
            self._on_change()

    def live(self) -> list[str]:
        """Names of the live instances, sorted (this one included)."""
        with self._lock:
            return sorted(self._live)

    def close(self) -> None:
        """Stop following the tokens."""
        try:
            self.subscriber.undeclare()
        except Exception:  # noqa: BLE001 - the session may be closed already
            pass
