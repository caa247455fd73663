"""Per-bus ring buffers: ordering, late/duplicate/out-of-order frames, and the accounting invariant."""

from __future__ import annotations

import numpy as np

from aslm_core.window import Window
from service.buffers import BufferStore, BusBuffer
from service.frames import FrameBatch

T0 = 1_700_000_000.0
FS = 50.0


def batch(t: np.ndarray) -> FrameBatch:
    t = np.asarray(t, float)
    return FrameBatch(t=t, V=1.0 + 0 * t, theta=t - T0, P=0.5 + 0 * t, Q=0.1 + 0 * t)


def frames_at(i0: int, i1: int) -> np.ndarray:
    return T0 + np.arange(i0, i1) / FS


def test_in_order_batches_append_and_cut():
    buf = BusBuffer(capacity=1000, tol=0.25 / FS, late_s=2.0)
    for k in range(10):
        assert buf.insert(batch(frames_at(50 * k, 50 * (k + 1)))) == {}
    assert buf.buffered == 500 and buf.size == 500
    cut = buf.cut(T0 + 2.0, T0 + 4.0, f0=60.0, bus="b7")
    assert isinstance(cut, Window) and (cut.bus, cut.f0, cut.n) == ("b7", 60.0, 100)
    np.testing.assert_allclose(cut.t, frames_at(101, 201))
    np.testing.assert_allclose(cut.theta, cut.t - T0)  # columns stay aligned with t
    assert cut.f is None


def test_ring_keeps_latest_capacity_frames_over_many_compactions():
    buf = BusBuffer(capacity=300, tol=0.25 / FS, late_s=2.0)
    for k in range(200):
        buf.insert(batch(frames_at(37 * k, 37 * (k + 1))))
    assert buf.size == 300 and buf.buffered == 200 * 37
    held = buf.data[0, buf.start:buf.end]
    np.testing.assert_allclose(held, frames_at(200 * 37 - 300, 200 * 37))


def test_out_of_order_within_allowance_is_reordered():
    buf = BusBuffer(capacity=1000, tol=0.25 / FS, late_s=2.0)
    buf.insert(batch(frames_at(0, 50)))
    buf.insert(batch(frames_at(100, 150)))
    rej = buf.insert(batch(frames_at(50, 100)[::-1]))  # 1 s late and reversed
    assert rej == {}
    np.testing.assert_allclose(buf.data[0, buf.start:buf.end], frames_at(0, 150))


def test_late_and_duplicate_frames_are_counted_and_dropped():
    buf = BusBuffer(capacity=1000, tol=0.25 / FS, late_s=2.0)
    buf.insert(batch(frames_at(0, 500)))  # newest at 9.98 s
    late = frames_at(0, 10)  # ~10 s old > 2 s allowance
    dup_held = frames_at(400, 405) + 0.001  # within tol of held frames
    new = frames_at(500, 510)
    dup_in_batch = new[:3]
    mixed = np.concatenate([new, late, dup_held, dup_in_batch])
    rej = buf.insert(batch(np.random.default_rng(0).permutation(mixed)))
    assert rej == {"late": 10, "duplicate": 8}
    assert buf.buffered == 510
    held = buf.data[0, buf.start:buf.end]
    np.testing.assert_allclose(held, frames_at(0, 510))
    assert (np.diff(held) > 0).all()


def test_store_invariant_sent_equals_buffered_plus_rejected():
    store = BufferStore(window_s=10, frame_rate=FS, late_s=2.0)
    rng = np.random.default_rng(3)
    sent = 0
    for bus in ("a", "b", "c"):
        for k in range(40):
            t = frames_at(25 * k, 25 * k + 50)  # overlapping batches: half duplicates
            if k % 7 == 0:
                t = t - 5.0  # some late
            t = rng.permutation(t)
            store.add(bus, batch(t))
            sent += t.size
    tot = store.totals()
    assert tot.frames_buffered + sum(tot.frames_rejected.values()) == sent == tot.frames_received
    assert tot.frames_rejected["duplicate"] > 0 and tot.frames_rejected["late"] > 0
    assert tot.messages == 120
    for bus in ("a", "b", "c"):
        c = store.counts(bus)
        assert c.buffered + sum(c.rejected.values()) == sent // 3
        held = store.buffer(bus).data[0, store.buffer(bus).start:store.buffer(bus).end]
        assert (np.diff(held) > 0).all()


def test_one_bus_bad_input_leaves_others_untouched():
    store = BufferStore(window_s=10, frame_rate=FS, late_s=2.0)
    store.add("good", batch(frames_at(0, 100)))
    store.add("bad", batch(frames_at(0, 100)))
    store.add("bad", batch(frames_at(0, 100)))  # all duplicates
    assert store.counts("good").rejected == {}
    assert store.counts("bad").rejected == {"duplicate": 100}
    assert store.counts("good").buffered == 100


def test_a_new_bus_beyond_the_cap_evicts_the_one_longest_without_frames():
    # Before issue 17 the new bus was refused (too_many_buses): junk names could keep real buses out.
    store = BufferStore(window_s=10, frame_rate=FS, late_s=2.0, max_buses=2)
    for k, bus in enumerate(("a", "b", "c")):
        store.add(bus, batch(frames_at(0, 10)), arrival=T0 + k)
    assert store.buses() == ["b", "c"]
    assert store.counts("a") is None
    tot = store.totals()
    assert (tot.frames_rejected, tot.frames_buffered, tot.frames_received, tot.buses_evicted) == ({}, 30, 30, 1)


def test_validation_and_message_rejects_are_accounted_per_bus():
    store = BufferStore(window_s=10, frame_rate=FS, late_s=2.0)
    store.add("a", batch(frames_at(0, 8)), rejected={"non_finite": 2})
    store.reject_message("a", "length_mismatch", 7)
    store.reject_message("a", "malformed_json")
    c = store.counts("a")
    assert c.buffered == 8 and c.rejected == {"non_finite": 2, "length_mismatch": 7}
    assert c.messages == 3 and c.messages_rejected == {"length_mismatch": 1, "malformed_json": 1}
    assert store.totals().frames_received == 17


def test_cut_has_f_only_where_every_frame_has_it():
    buf = BusBuffer(capacity=1000, tol=0.25 / FS, late_s=2.0)
    with_f = batch(frames_at(0, 50))
    with_f.f = 50.0 + 0 * with_f.t
    buf.insert(with_f)
    buf.insert(batch(frames_at(50, 100)))
    np.testing.assert_array_equal(buf.cut(T0 - 1.0, T0 + 0.5).f, np.full(26, 50.0))
    assert buf.cut(T0 - 1.0, T0 + 1.5).f is None
