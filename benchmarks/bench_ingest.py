"""Ingest throughput over Zenoh on loopback: N PMUs, batched frames per message, zero loss check.

A publisher process (spawned: its own core) sends pre-encoded binary batches as fast as reliable +
blocking congestion control allows; this process runs the service's ingest (subscriber → decode →
validate → per-bus ring buffers).  Printed: frames/s sustained at the receiver, messages/s, and the
accounting sent = buffered + rejected.  Also the in-process decode+buffer rate without Zenoh.

    .venv/bin/python benchmarks/bench_ingest.py --pmus 10000 --batch 50 --seconds 60
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from service.buffers import BufferStore  # noqa: E402
from service.frames import BINARY_ENCODING, FrameBatch, encode_binary  # noqa: E402
from service.sources.base import Inlet  # noqa: E402
from service.sources.zenoh import ZenohSource  # noqa: E402
from service.zenoh_config import zenoh_config  # noqa: E402

FS = 50.0


def payloads(n_pmus: int, batch: int, t0: float) -> list[bytearray]:
    """One binary message per PMU, times t0 + [0, batch)/FS; the t column is patched in place later."""
    rng = np.random.default_rng(0)
    t = t0 + np.arange(batch) / FS
    out = []
    for _ in range(n_pmus):
        b = FrameBatch(t=t, V=1 + 0.01 * rng.standard_normal(batch), theta=0.1 * rng.standard_normal(batch),
                       P=0.8 + 0.01 * rng.standard_normal(batch), Q=0.3 + 0.01 * rng.standard_normal(batch))
        out.append(bytearray(encode_binary(b)))
    return out


def publisher(port: int, n_pmus: int, batch: int, rounds: int, t0: float, ready, result) -> None:
    import zenoh

    session = zenoh.open(zenoh_config("peer", connect=[f"tcp/127.0.0.1:{port}"], listen=[]))
    pubs = [session.declare_publisher(f"aslm/pmu/pmu{i:05d}", encoding=zenoh.Encoding(BINARY_ENCODING),
                                      congestion_control=zenoh.CongestionControl.BLOCK,
                                      reliability=zenoh.Reliability.RELIABLE) for i in range(n_pmus)]
    msgs = payloads(n_pmus, batch, t0)
    tviews = [np.frombuffer(m, dtype="<f8", count=batch, offset=16) for m in msgs]
    ready.set()
    time.sleep(1.0)
    sent = 0
    start = time.perf_counter()
    for _ in range(rounds):
        for pub, msg, tv in zip(pubs, msgs, tviews, strict=True):
            pub.put(bytes(msg))
            tv += batch / FS  # next batch of this PMU: the following seconds
            sent += batch
    elapsed = time.perf_counter() - start
    result.put((sent, elapsed))
    time.sleep(2.0)
    session.close()


def in_process(n_pmus: int, batch: int, rounds: int) -> None:
    store = BufferStore(10.0, FS, 2.0)
    msgs = payloads(n_pmus, batch, time.time() - 86400)
    tviews = [np.frombuffer(m, dtype="<f8", count=batch, offset=16) for m in msgs]
    inlet = Inlet(store, max_future_s=5.0, f0=50.0)
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(rounds):
        for i, (msg, tv) in enumerate(zip(msgs, tviews, strict=True)):
            inlet.message(f"pmu{i:05d}", bytes(msg), BINARY_ENCODING)
            tv += batch / FS
    dt, cpu = time.perf_counter() - start, time.process_time() - cpu
    tot = store.totals()
    # CPU time per message as well: unlike the rate, other jobs on the machine barely change it.
    print(f"in-process decode+validate+buffer: {tot.frames_received / dt:,.0f} frames/s "
          f"({tot.messages / dt:,.0f} msg/s of {batch} frames, {cpu / tot.messages * 1e6:.1f} µs CPU each), "
          f"rejected {tot.frames_rejected}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pmus", type=int, default=10000)
    ap.add_argument("--batch", type=int, default=50, help="frames per message (50 = 1 s of one PMU)")
    ap.add_argument("--seconds", type=float, default=30.0, help="seconds of PMU data per PMU to send")
    ap.add_argument("--port", type=int, default=17499)
    args = ap.parse_args()
    rounds = max(1, int(args.seconds * FS / args.batch))
    in_process(min(args.pmus, 2000), args.batch, max(1, rounds // 5))

    import zenoh

    store = BufferStore(10.0, FS, 2.0)
    session = zenoh.open(zenoh_config("peer", listen=[f"tcp/127.0.0.1:{args.port}"], connect=[]))
    ingest = ZenohSource(session, "aslm")
    ingest.start(Inlet(store, max_future_s=5.0, f0=50.0))
    ctx = mp.get_context("spawn")
    ready, result = ctx.Event(), ctx.Queue()
    t0 = time.time() - 86400  # data a day old: virtual time may run ahead without being "future"
    proc = ctx.Process(target=publisher, args=(args.port, args.pmus, args.batch, rounds, t0, ready, result))
    proc.start()
    ready.wait(120)
    expected = args.pmus * args.batch * rounds
    first = None
    last_count, last_change = 0, time.monotonic()
    while True:
        tot = store.totals()
        n = tot.frames_received
        if n and first is None:
            first = (time.perf_counter(), n)
        if n != last_count:
            last_count, last_change = n, time.monotonic()
        if n >= expected or time.monotonic() - last_change > 10:
            break
        time.sleep(0.5)  # totals() walks every bus: polling it often would steal the GIL from ingest
    end = time.perf_counter()
    sent, pub_elapsed = result.get(timeout=60)
    proc.join(30)
    tot = store.totals()
    rate = (tot.frames_received - first[1]) / (end - first[0])
    rejected = sum(tot.frames_rejected.values())
    print(f"zenoh ingest: {args.pmus} PMUs x {args.batch} frames/message, {rounds} rounds")
    print(f"  sent {sent:,} frames in {pub_elapsed:.1f} s ({sent / pub_elapsed:,.0f} frames/s publisher side)")
    print(f"  received {tot.frames_received:,} frames, {tot.messages:,} messages; "
          f"sustained {rate:,.0f} frames/s ({rate / args.batch:,.0f} msg/s) at the receiver")
    print(f"  buffered {tot.frames_buffered:,} + rejected {rejected:,} {tot.frames_rejected} = "
          f"{tot.frames_buffered + rejected:,}; lost {sent - tot.frames_received:,}; "
          f"callback errors {ingest.internal_errors}")
    print(f"  real-time equivalent: {rate / FS:,.0f} PMUs at {FS:g} frames/s")
    ingest.close()
    session.close()


if __name__ == "__main__":
    main()
