"""Period latency: N buses' windows cut, checked, identified in the local pool, persisted and published.

Windows come from a synthetic fleet (noise level 2) of up to 50 distinct buses, repeated under N bus
names (identification cost does not depend on the name).  Latency is what the service reports: from the
end of the late-data allowance to the last result published (here: from the start of the period run,
the boundary being in the past).

    .venv/bin/python benchmarks/bench_period.py --buses 1000 --workers 2
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
         seed: int = 0) -> list[str]:
    """Put ``seconds`` of frames ending at ``boundary`` into ``store`` for n_buses buses."""
    from aslm_core.synthetic import SyntheticFleet

    n = int(seconds * FS)
    fleet = SyntheticFleet(min(distinct, n_buses), fs=FS, level=2, seed=seed, t0=boundary - (n - 1) / FS)
    d = fleet.advance(n)
    names = [f"bus{i:05d}" for i in range(n_buses)]
    for i, bus in enumerate(names):
        j = i % fleet.n_buses
        for k in range(0, n, 50):  # 1 s messages, as over the wire
            sl = slice(k, k + 50)
            store.add(bus, FrameBatch(t=d["t"][sl], V=d["V"][j, sl], theta=d["theta"][j, sl], P=d["P"][j, sl],
                                      Q=d["Q"][j, sl], f=d["f"][j, sl]))
    return names


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--starts", type=int, default=3, help="random starts per window (service default 3)")
    ap.add_argument("--periods", type=int, default=2, help="periods to run (the 2nd is warm-started)")
    args = ap.parse_args()

    import zenoh

    from service.models import PeriodSummary
    from service.pool import LocalPool
    from service.publish import ResultPublisher
    from service.scheduler import QualityRules, Scheduler
    from service.storage import Storage
    from service.zenoh_config import zenoh_config

    pool = LocalPool(args.workers, "service.worker:identify_window", timeout_s=120)
    pool.wait_ready(120)
    session = zenoh.open(zenoh_config("peer", listen=["tcp/127.0.0.1:0"], connect=[]))
    tmp = tempfile.TemporaryDirectory()
    storage = Storage(Path(tmp.name) / "bench.sqlite")
    latest: dict = {}
    publisher = ResultPublisher(session, "bench", "bench", lambda: latest.copy())
    warm: dict = {}

    def on_results(batch):
        storage.save_results(batch)
        for r in batch:
            latest[r.bus] = r
            publisher.publish(r)

    summaries: list[PeriodSummary] = []
    period_s = 60.0
    for p in range(args.periods):
        boundary = (np.floor(time.time() / period_s) - args.periods + p) * period_s
        store = BufferStore(10.0, FS, 1.0)
        t0 = time.perf_counter()
        fill(store, args.buses, boundary, seed=p)
        t_fill = time.perf_counter() - t0
        sched = Scheduler(store, pool, QualityRules(10.0, FS, 0.9, 0.2, 1e-5), late_s=1.0, f0=50.0,
                          period_s=lambda: period_s, on_results=on_results, on_period=summaries.append,
                          warm_starts=warm, options={"n_starts": args.starts})
        s = sched.run_period(boundary, period_s)
        ident = [r.parameters.elapsed_s for r in latest.values() if r.parameters is not None]
        print(f"period {p + 1}: {args.buses} buses, {args.workers} workers, warm-started: {p > 0}: "
              f"ok {s.n_ok}, failed {s.n_failed}, skipped {s.n_skipped}; latency {s.latency_s:.2f} s "
              f"(identify per window: median {1e3 * np.median(ident):.1f} ms, p95 {1e3 * np.percentile(ident, 95):.1f} ms;"
              f" filling buffers took {t_fill:.1f} s, not counted)")
        busy = sum(ident) / args.workers
        print(f"  compute bound sum(identify)/workers = {busy:.2f} s; scheduling/IPC/storage/publish overhead "
              f"{s.latency_s - busy:.2f} s; load average now {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"published {publisher.published} results on Zenoh, {len(storage.buses())} buses in SQLite")
    publisher.close()
    pool.close()
    session.close()
    storage.close()


if __name__ == "__main__":
    main()
