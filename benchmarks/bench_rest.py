"""REST latency of ``GET /buses/{bus}/parameters/latest`` at a fixed request rate while a period computes.

A full service (uvicorn, SQLite, Zenoh, local pool) holds N buses with results from a first period;
a second period is then run while a client process (spawned, its own interpreter) sends requests at
``--rate`` per second for ``--seconds``, open loop (a slow answer does not delay the next request).

    .venv/bin/python benchmarks/bench_rest.py --buses 1000 --rate 200 --seconds 15
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))


def client(url: str, buses: list[str], rate: float, seconds: float, out, connections: int = 16) -> None:
    """Open-loop load: request i is due at start + i/rate; its latency counts from that due time, so
    queueing behind slow answers is included (no coordinated omission).  A minimal HTTP/1.1 keep-alive
    client on raw asyncio streams keeps the client's own cost small."""
    import asyncio
    import re
    from urllib.parse import urlparse

    u = urlparse(url)
    length = re.compile(rb"content-length:\s*(\d+)", re.I)

    async def run() -> list[float]:
        lat: list[float] = []
        queue: asyncio.Queue = asyncio.Queue()

        async def conn_worker() -> None:
            reader, writer = await asyncio.open_connection(u.hostname, u.port)
            while True:
                item = await queue.get()
                if item is None:
                    writer.close()
                    return
                bus, due = item
                writer.write(f"GET /buses/{bus}/parameters/latest HTTP/1.1\r\nHost: {u.hostname}\r\n\r\n".encode())
                await writer.drain()
                head = await reader.readuntil(b"\r\n\r\n")
                await reader.readexactly(int(length.search(head).group(1)))
                ok = head.split(b" ", 2)[1] == b"200"
                lat.append((due, time.perf_counter() - due if ok else float("inf")))

        workers = [asyncio.create_task(conn_worker()) for _ in range(connections)]
        for bus in buses[:50]:  # warm-up
            queue.put_nowait((bus, time.perf_counter()))
        while len(lat) < 50:
            await asyncio.sleep(0.01)
        lat.clear()
        out.put("ready")
        start = time.perf_counter()
        for i in range(int(rate * seconds)):
            due = start + i / rate
            delay = due - time.perf_counter()
            if delay > 0:
                await asyncio.sleep(delay)
            queue.put_nowait((buses[i % len(buses)], due))
        for _ in workers:
            queue.put_nowait(None)
        await asyncio.gather(*workers)
        return lat

    out.put(asyncio.run(run()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=1000)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--idle", action="store_true", help="measure without a period computing (baseline)")
    ap.add_argument("--timeline", type=float, default=0.0, metavar="S",
                    help="also print p99/max per S-second bin, relative to the period's start")
    args = ap.parse_args()

    from bench_period import fill

    from service.app import Service
    from service.settings import load_settings

    tmp = tempfile.TemporaryDirectory()
    port = 17599
    settings = load_settings(period_s=86400, window_s=10, late_s=1, storage_url=str(Path(tmp.name) / "r.sqlite"),
                             http_port=0, zenoh_listen=[f"tcp/127.0.0.1:{port}"], workers=2, instance="bench")
    import aslm_sim.fleet  # noqa: F401 - the fleet's numba, imported before start: frozen with the startup objects (the service itself never imports numba here)

    svc = Service(settings).start()
    try:
        b1 = (np.floor(time.time() / 60) - 2) * 60
        names = fill(svc.store, args.buses, b1)
        s1 = svc.scheduler.run_period(b1, 60.0)
        print(f"first period: {s1.n_ok} ok in {s1.latency_s:.1f} s (results now served)")
        fill(svc.store, args.buses, b1 + 60, skip_s=60.0)  # the same buses, one period later: warm-started
        span = []  # perf_counter (CLOCK_MONOTONIC: comparable across processes) at the period's start and end

        def run_second() -> None:
            span.append(time.perf_counter())
            s2 = svc.scheduler.run_period(b1 + 60, 60.0)
            span.append(time.perf_counter())
            print_period(s2)

        period = threading.Thread(target=lambda: None if args.idle else run_second())
        ctx = mp.get_context("spawn")
        out = ctx.Queue()
        proc = ctx.Process(target=client, args=(svc.url, names, args.rate, args.seconds, out))
        proc.start()
        assert out.get(timeout=120) == "ready"
        period.start()
        res = np.array(out.get(timeout=args.seconds + 120))
        proc.join(10)
        computing = svc.scheduler.running_period is not None
        period.join()
        due, lat = res[:, 0], res[:, 1]
        ok = np.isfinite(lat)
        print(f"REST latest at {args.rate:g} req/s for {args.seconds:g} s over {args.buses} buses "
              f"{'idle' if args.idle else 'while a period computes'} (still computing at the end: {computing}): "
              f"{ok.sum()} ok / {lat.size} requests; load average {os.getloadavg()[0]:.1f}")
        print("  all requests: " + stats(lat))
        if len(span) == 2:
            during = (due >= span[0]) & (due <= span[1])
            print(f"  requests due while the period ran ({span[1] - span[0]:.1f} s): " + stats(lat[during]))
            if args.timeline > 0:
                rel = due - span[0]
                for k in np.arange(np.floor(rel.min() / args.timeline), np.ceil(rel.max() / args.timeline)):
                    sel = (rel >= k * args.timeline) & (rel < (k + 1) * args.timeline)
                    if sel.any():
                        print(f"    t = {k * args.timeline:+6.1f} s: " + stats(lat[sel]))
    finally:
        svc.stop()


def stats(lat: np.ndarray) -> str:
    """Percentiles of latencies [s] as text [ms]."""
    ms = 1e3 * lat[np.isfinite(lat)]
    if ms.size == 0:
        return "no successful requests"
    return (f"n {ms.size}, p50 {np.percentile(ms, 50):.1f} ms, p95 {np.percentile(ms, 95):.1f} ms, "
            f"p99 {np.percentile(ms, 99):.1f} ms, max {ms.max():.1f} ms")


def print_period(s) -> None:
    print(f"second period: {s.n_ok} ok, {s.n_failed} failed in {s.latency_s:.1f} s")


if __name__ == "__main__":
    main()
