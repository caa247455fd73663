"""Rendezvous ownership of buses (service/sharding.py) and the buffer release it relies on (fast, no Zenoh)."""

from __future__ import annotations

from collections import Counter

import numpy as np

from service.buffers import BufferStore
from service.frames import FrameBatch
from service.sharding import owned, owner

BUSES = [f"area{i % 7}/bus{i:05d}" for i in range(6000)]
NAMES = ["a", "b", "c"]


def test_every_bus_has_one_owner_and_the_load_is_even():
    shares = [owned(BUSES, NAMES, name) for name in NAMES]
    assert set().union(*shares) == set(BUSES) and sum(map(len, shares)) == len(BUSES)  # a partition
    counts = Counter(owner(b, NAMES) for b in BUSES)
    assert all(abs(n - 2000) < 150 for n in counts.values()), counts  # ±3.4 σ of a binomial
    assert owner("x", []) is None and owner("x", ["only"]) == "only"


def test_the_map_is_the_same_whatever_the_order_or_the_process():
    assert [owner(b, NAMES) for b in BUSES[:50]] == [owner(b, NAMES[::-1]) for b in BUSES[:50]]
    # Fixed values: blake2b, not Python's salted str hash, so every host computes the same map.
    assert [owner(f"bus{i}", NAMES) for i in range(6)] == [owner(f"bus{i}", ["c", "a", "b"]) for i in range(6)]
    assert owned(BUSES[:100], ["a"], "b") == owned(BUSES[:100], ["a", "b"], "b")  # itself always counts


def test_a_leaving_instance_moves_only_its_buses_and_gets_the_same_back():
    before = {b: owner(b, NAMES) for b in BUSES}
    after = {b: owner(b, ["a", "b"]) for b in BUSES}
    moved = {b for b in BUSES if before[b] != after[b]}
    assert moved == {b for b in BUSES if before[b] == "c"}
    assert Counter(after[b] for b in moved).keys() == {"a", "b"}  # spread over the survivors
    assert {b: owner(b, NAMES) for b in BUSES} == before  # back: exactly its own buses again


def test_a_discarded_bus_is_forgotten_with_its_frames():
    store = BufferStore(1.0, 50.0, 0.5)
    t = 1000.0 + np.arange(50) / 50.0
    for bus in ("x", "y"):
        store.add(bus, FrameBatch(t, 1 + 0 * t, 0 * t, 0.8 + 0 * t, 0.3 + 0 * t))
    store.discard("x")
    store.discard("unknown")  # no error
    assert store.buses() == ["y"] and store.counts("x") is None
