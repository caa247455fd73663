"""Period latency: N buses' windows cut, checked, identified in the local pool, persisted and published.

Windows come from a synthetic fleet (noise level 2) of up to 50 distinct buses, repeated under N bus
names (identification cost does not depend on the name).  Each period is the next stretch of the same
fleet's stream, so from the 2nd period on each bus is warm-started from its own previous result, as in
the service.  Identification options are the service's defaults (n_starts, n_starts_warm, lowpass_hz).
Latency is what the service reports: from the end of the late-data allowance to the last result
published (here: from the start of the period run, the boundary being in the past).

Besides the latency it prints the compute part: the CPU time of the worker processes during the period
(Σ identify alone is the wall time inside ``identify``, inflated when other jobs share the cores) and
the CPU time of this process (cutting, scheduling, IPC, SQLite, Zenoh).

    .venv/bin/python benchmarks/bench_period.py --buses 1000 --workers 2
    .venv/bin/python benchmarks/bench_period.py --buses 1000 --workers 2 --history 6

``--history K``: the service's ``input_history_windows`` = K (the K windows before each one cut from the ring, which then
holds K·10 s more, and carried to the workers with the task; the fleet's V and θ are noisy, so every window is refined
with their pooled spectrum).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from service.buffers import BufferStore  # noqa: E402
from service.frames import FrameBatch  # noqa: E402

FS = 50.0


def fill(store: BufferStore, n_buses: int, boundary: float, seconds: float = 12.0, distinct: int = 50,
         seed: int = 0, skip_s: float = 0.0) -> list[str]:
    """Put ``seconds`` of frames ending at ``boundary`` into ``store`` for n_buses buses.

    ``skip_s``: seconds of the fleet's stream skipped first (a later stretch of the same buses).
    """
    from aslm_sim.fleet import SyntheticFleet

    n, skip = int(seconds * FS), int(skip_s * FS)
    fleet = SyntheticFleet(min(distinct, n_buses), fs=FS, level=2, seed=seed, t0=boundary - (n + skip - 1) / FS)
    if skip:
        fleet.advance(skip)
    d = fleet.advance(n)
    names = [f"bus{i:05d}" for i in range(n_buses)]
    for i, bus in enumerate(names):
        j = i % fleet.n_buses
        for k in range(0, n, 50):  # 1 s messages, as over the wire
            sl = slice(k, k + 50)
            store.add(bus, FrameBatch(t=d["t"][sl], V=d["V"][j, sl], theta=d["theta"][j, sl], P=d["P"][j, sl],
                                      Q=d["Q"][j, sl], f=d["f"][j, sl]))
    return names


def cpu_s(pids: list[int]) -> float:
    """User + system CPU time of processes [s] (Linux /proc), 0 for one that has gone."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
        except (OSError, IndexError, ValueError):
            pass
    return total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--starts", type=int, default=None, help="random starts without a warm start (service setting n_starts)")
    ap.add_argument("--starts-warm", type=int, default=None,
                    help="random starts besides a warm start (service setting n_starts_warm)")
    ap.add_argument("--depth", type=int, default=None, help="tasks in flight per worker (pool default)")
    ap.add_argument("--periods", type=int, default=2, help="periods to run (from the 2nd on warm-started)")
    ap.add_argument("--history", type=int, default=0, help="the service's input_history_windows")
    args = ap.parse_args()

    import zenoh

    from service.executors.local import LocalPool
    from service.latest import LatestResults
    from service.models import PeriodSummary
    from service.scheduler import QualityRules, Scheduler
    from service.settings import ServiceSettings
    from service.sinks.base import SinkChain
    from service.sinks.storage import StorageSink
    from service.sinks.zenoh import ZenohSink
    from service.storage import Storage
    from service.zenoh_config import zenoh_config

    defaults = ServiceSettings.model_fields
    starts = args.starts if args.starts is not None else defaults["n_starts"].default
    starts_warm = args.starts_warm if args.starts_warm is not None else defaults["n_starts_warm"].default
    options = {"n_starts": starts, "lowpass_hz": defaults["lowpass_hz"].default}
    print(f"options {options}, n_starts_warm {starts_warm}")
    pool = LocalPool(args.workers, "service.worker:identify_window", timeout_s=120,
                     **({"depth": args.depth} if args.depth else {}))
    pool.wait_ready(300)
    session = zenoh.open(zenoh_config("peer", listen=["tcp/127.0.0.1:0"], connect=[]))
    tmp = tempfile.TemporaryDirectory()
    storage = Storage(Path(tmp.name) / "bench.sqlite")
    latest = LatestResults()
    publisher = ZenohSink(session, "bench", "bench", latest.snapshot)
    # as in the service: serialise once, persist, keep as latest, publish
    sinks = SinkChain([StorageSink(storage, 1e12), latest, publisher], on_error=lambda where: None)
    warm: dict = {}

    summaries: list[PeriodSummary] = []
    period_s = 60.0
    for p in range(args.periods):
        boundary = (np.floor(time.time() / period_s) - args.periods + p) * period_s
        store = BufferStore(10.0, FS, 1.0, history_s=10.0 * args.history)
        t0 = time.perf_counter()
        fill(store, args.buses, boundary, seconds=12.0 + 10.0 * args.history, skip_s=p * period_s)
        t_fill = time.perf_counter() - t0
        sched = Scheduler(store, pool, QualityRules(10.0, FS, 0.9, 0.2, 1e-5), late_s=1.0, f0=50.0,
                          period_s=lambda: period_s, on_results=sinks.write_results, on_period=summaries.append,
                          warm_starts=warm, options=options, n_starts_warm=starts_warm,
                          input_history=args.history or None)
        load0, pids = os.getloadavg()[0], pool.pids()
        w0, m0 = cpu_s(pids), time.process_time()
        s = sched.run_period(boundary, period_s)
        w1, m1 = cpu_s(pids), time.process_time()
        ident = [r.parameters.elapsed_s for r in latest.results.values() if r.parameters is not None]
        with_history = sum(int(r.parameters.quality.get("input_spectrum_windows", 0)) > 0
                           for r in latest.results.values() if r.parameters is not None)
        print(f"period {p + 1}: {args.buses} buses, {args.workers} workers, warm-started: {p > 0}: "
              f"ok {s.n_ok}, failed {s.n_failed}, skipped {s.n_skipped}; latency {s.latency_s:.2f} s "
              f"(identify per window: median {1e3 * np.median(ident):.1f} ms, mean {1e3 * np.mean(ident):.1f} ms, "
              f"p95 {1e3 * np.percentile(ident, 95):.1f} ms; filling buffers took {t_fill:.1f} s, not counted; "
              f"with a history {with_history})")
        busy = sum(ident) / args.workers
        print(f"  sum(identify)/workers = {busy:.2f} s; worker CPU {w1 - w0:.2f} s "
              f"({1e3 * (w1 - w0) / max(s.n_ok, 1):.2f} ms per window; /workers = {(w1 - w0) / args.workers:.2f} s); "
              f"this process CPU {m1 - m0:.2f} s ({1e3 * (m1 - m0) / max(s.n_ok, 1):.2f} ms per window); "
              f"load average {load0:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"published {publisher.published} results on Zenoh, {len(storage.buses())} buses in SQLite")
    publisher.close()
    pool.close()
    session.close()
    storage.close()


if __name__ == "__main__":
    main()
