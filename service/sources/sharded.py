"""Sharded Zenoh source: this instance ingests only the buses it owns among the live instances.

Ownership is :func:`service.sharding.owner` over the instances' liveliness tokens
(:class:`service.sharding.Membership`).  Three subscriptions per instance:

- one subscriber per owned bus on ``{prefix}/pmu/{bus}`` (the frames, into the :class:`Inlet`);
- **discovery**: every ``discovery_every_s`` a subscriber on ``{prefix}/pmu/{pmu_keys}`` that lives
  ``discovery_s`` and only notes the bus names it sees.  That is how an instance learns of a bus it
  does not subscribe to (a new PMU, or the buses of an instance that died before this one saw them):
  it carries all the fleet's frames, but for ``discovery_s / discovery_every_s`` of the time (1 s in
  60 s: 1.7 %), and its callback only looks the name up in a set;
- ``{prefix}/params/**``: the results the other instances publish, kept in this instance's storage
  and latest results, so REST answers for every bus from any instance (history included, from the
  moment this instance started).

When the live instances change (a token appears or disappears) the buses are reassigned at once:
an instance unsubscribes from the buses it no longer owns and drops their buffers (so it does not
identify them at the next boundary), and subscribes to those it gained, whose windows fill from then
on.  A taken-over bus therefore misses at most the period in progress and the next one (its first
window is incomplete): takeover and hand-back within 2 periods.
"""

from __future__ import annotations

import logging
import threading

import zenoh

from service.context import Context
from service.models import BusResult
from service.sharding import Membership, owned
from service.sources.base import Inlet

log = logging.getLogger(__name__)

#: Seconds the discovery subscriber lives, and seconds between its runs (at most).
DISCOVERY_S = 1.0
DISCOVERY_EVERY_S = 60.0


class ShardedZenohSource:
    """The PMU subscriptions of one instance of a sharded fleet.

    Parameters
    ----------
    session : zenoh.Session
    prefix : str
    instance : str
        This instance's name (its liveliness token ``{prefix}/service/{instance}`` is the Zenoh sink's).
    keys : str
        Key expression below ``{prefix}/pmu/`` the fleet's buses are under (discovery's scope).
    ctx : Context, optional
        Storage and latest results that the other instances' results are written to (None: not kept).
    discovery_s, discovery_every_s : float
        Life of each discovery subscriber and time between them [s].
    """

    name = "zenoh-sharded"

    def __init__(self, session: zenoh.Session, prefix: str, instance: str, *, keys: str = "**",
                 ctx: Context | None = None, discovery_s: float = DISCOVERY_S,
                 discovery_every_s: float = DISCOVERY_EVERY_S) -> None:
        self.session = session
        self.prefix = prefix
        self.instance = instance
        self.keys = keys
        self.ctx = ctx
        self.discovery_s = discovery_s
        self.discovery_every_s = discovery_every_s
        self._skip = len(prefix) + len("/pmu/")
        self._inlet: Inlet | None = None
        self.known: set[str] = set()
        self.subscribers: dict[str, zenoh.Subscriber] = {}
        self._owned: frozenset[str] = frozenset()
        self._lock = threading.Lock()
        self._dirty = threading.Event()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.membership: Membership | None = None
        self._results: zenoh.Subscriber | None = None
        self.internal_errors = 0
        self.reassignments = 0

    # --- lifecycle ------------------------------------------------------------------------------------
    def start(self, inlet: Inlet) -> None:
        """Follow the live instances, discover the buses, subscribe to the owned ones."""
        self._inlet = inlet
        self.membership = Membership(self.session, self.prefix, self.instance, self._dirty.set)
        if self.ctx is not None:
            self._results = self.session.declare_subscriber(f"{self.prefix}/params/**", self._on_result)
        # Zenoh callbacks only flag work: (un)declaring subscribers happens on this source's own thread.
        for target, name in ((self._assign_loop, "aslm-shard-assign"), (self._discover_loop, "aslm-shard-discover")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)

    def close(self) -> None:
        """Undeclare every subscription (idempotent)."""
        self._stop.set()
        self._dirty.set()
        for thread in self._threads:
            thread.join(5.0)
        self._threads = []
        with self._lock:
            subs, self.subscribers = list(self.subscribers.values()), {}
            self._owned = frozenset()
        for sub in [*subs, self._results]:
            _undeclare(sub)
        self._results = None
        if self.membership is not None:
            self.membership.close()
            self.membership = None

    # --- ownership ------------------------------------------------------------------------------------
    @property
    def owned(self) -> frozenset[str]:
        """The buses this instance ingests now."""
        return self._owned

    def _assign_loop(self) -> None:
        while not self._stop.is_set():
            self._dirty.wait()
            if self._stop.is_set():
                return
            self._dirty.clear()
            try:
                self.reassign()
            except Exception:  # noqa: BLE001 - a failed (un)declaration is tried again a second later
                log.exception("reassigning buses failed")
                self._stop.wait(1.0)
                self._dirty.set()

    def reassign(self) -> None:
        """Subscribe to the buses this instance owns among the live instances; drop the others."""
        live = self.membership.live() if self.membership is not None else [self.instance]
        with self._lock:
            known = list(self.known)
        want = owned(known, live, self.instance)  # ~2.5 µs a bus and instance: outside the lock
        with self._lock:
            self._owned = frozenset(want)  # the per-bus callbacks check this before buffering
        # Against the subscribers that exist: a declaration that failed last time is tried again.
        lost, gained = self.subscribers.keys() - want, want - self.subscribers.keys()
        for bus in sorted(lost):
            _undeclare(self.subscribers.pop(bus, None))
            self._inlet.store.discard(bus)  # otherwise its stale window is cut at the next boundary
        for bus in sorted(gained):
            self.subscribers[bus] = self.session.declare_subscriber(
                f"{self.prefix}/pmu/{bus}", lambda sample, bus=bus: self._on_sample(bus, sample))
        if lost or gained:
            self.reassignments += 1
            log.info("instance %s of %d: %d buses (+%d, -%d)", self.instance, len(live), len(want),
                     len(gained), len(lost))

    # --- discovery ------------------------------------------------------------------------------------
    def _discover_loop(self) -> None:
        while not self._stop.is_set():
            try:
                self.discover()
            except Exception:  # noqa: BLE001 - tried again at the next interval
                log.exception("bus discovery failed")
            self._stop.wait(self.discovery_every_s)

    def discover(self) -> None:
        """Note every bus that publishes within ``discovery_s``; reassign if any was new."""
        sub = self.session.declare_subscriber(f"{self.prefix}/pmu/{self.keys}", self._on_discovery)
        try:
            self._stop.wait(self.discovery_s)
        finally:
            _undeclare(sub)

    def _on_discovery(self, sample: zenoh.Sample) -> None:
        bus = str(sample.key_expr)[self._skip:]
        if bus not in self.known:
            with self._lock:
                self.known.add(bus)
            self._dirty.set()

    # --- data -------------------------------------------------------------------------------------------
    def _on_sample(self, bus: str, sample: zenoh.Sample) -> None:
        if bus not in self._owned:
            return  # released while this sample was on its way
        try:
            self._inlet.message(bus, sample.payload.to_bytes(), str(sample.encoding))
        except Exception:  # noqa: BLE001 - bad input never kills the service
            self.internal_errors += 1
            if self.internal_errors <= 10:
                log.exception("ingest error on %s", sample.key_expr)

    def _on_result(self, sample: zenoh.Sample) -> None:
        """Keep another instance's result (this instance's own are in its latest results already)."""
        try:
            js = sample.payload.to_string()
            res = BusResult.model_validate_json(js)
            mine = self.ctx.latest.results.get(res.bus)
            if mine is not None and mine.period >= res.period:
                return
            self.ctx.storage.save_results([res], [js])
            self.ctx.latest.write_results([res], [js])
        except Exception:  # noqa: BLE001 - a bad publication never stops the service
            self.internal_errors += 1
            if self.internal_errors <= 10:
                log.exception("peer result on %s not kept", sample.key_expr)


def _undeclare(sub) -> None:
    if sub is None:
        return
    try:
        sub.undeclare()
    except Exception:  # noqa: BLE001 - the session may be closed already
        pass


def build(ctx: Context) -> ShardedZenohSource:
    """The sharded source of the settings' ``prefix``, ``instance`` and ``pmu_keys``.

    Discovery runs every T/2, between 5 and 60 s.  Needs the ``zenoh`` sink, whose liveliness
    token makes this instance count for the others.
    """
    s = ctx.settings
    if "zenoh" not in s.sinks:
        raise ValueError("the zenoh-sharded source needs the zenoh sink (its liveliness token is the instance's "
                         "membership of the fleet)")
    every = min(max(s.period_s / 2.0, 5.0), DISCOVERY_EVERY_S)
    return ShardedZenohSource(ctx.zenoh_session(), s.prefix, s.instance, keys=s.pmu_keys, ctx=ctx,
                              discovery_every_s=every)
