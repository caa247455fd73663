"""Period throughput: the Dask executor on a 2-worker LocalCluster against the local process pool.

Both run in one process, one after the other, on the same windows (the synthetic fleet of
``bench_period.py``, noise level 2): for each executor a cold period (no warm starts, ``n_starts``)
then a warm-started one (``n_starts_warm``), as the service runs them.  The cluster's workers are
processes with one thread each (as the compose profile runs them); its scheduler runs in this process,
as a ``LocalCluster``'s does.  Throughput is windows identified per second of period latency; the
target is Dask ≥ 0.8 × local.

    .venv/bin/python benchmarks/bench_dask.py --buses 10000
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from benchmarks.bench_period import FS, fill  # noqa: E402
from service.buffers import BufferStore  # noqa: E402
from service.scheduler import QualityRules, Scheduler  # noqa: E402
from service.settings import ServiceSettings  # noqa: E402

FN = "service.worker:identify_window"


def run_periods(executor, buses: int, options: dict, starts_warm: int) -> list[dict]:
    """A cold then a warm-started period of ``buses`` windows on ``executor``; one dict per period."""
    warm: dict = {}
    out = []
    period_s = 60.0
    for p in range(2):
        boundary = (np.floor(time.time() / period_s) - 2 + p) * period_s
        store = BufferStore(10.0, FS, 1.0)
        fill(store, buses, boundary, skip_s=p * period_s)
        results: list = []
        sched = Scheduler(store, executor, QualityRules(10.0, FS, 0.9, 0.2, 1e-5), late_s=1.0, f0=50.0,
                          period_s=lambda: period_s, on_results=results.extend, on_period=lambda s: None,
                          warm_starts=warm, options=options, n_starts_warm=starts_warm)
        load0 = os.getloadavg()[0]
        s = sched.run_period(boundary, period_s)
        out.append({"warm": p > 0, "ok": s.n_ok, "failed": s.n_failed, "latency_s": s.latency_s,
                    "throughput": s.n_ok / s.latency_s, "load": (load0, os.getloadavg()[0])})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=10_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--batch-s", type=float, default=None, help="work per batch [s] (executor default)")
    ap.add_argument("--inflight", type=int, default=None, help="batches in flight per worker thread (default)")
    args = ap.parse_args()

    import dask
    import distributed

    from service.executors.dask import DaskPool, wait_workers
    from service.executors.local import LocalPool

    defaults = ServiceSettings.model_fields
    options = {"n_starts": defaults["n_starts"].default, "lowpass_hz": defaults["lowpass_hz"].default}
    starts_warm = defaults["n_starts_warm"].default
    rows = {}
    pool = LocalPool(args.workers, FN, timeout_s=120)
    pool.wait_ready(300)
    try:
        rows["local"] = run_periods(pool, args.buses, options, starts_warm)
    finally:
        pool.close()
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}), distributed.LocalCluster(
            n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1", scheduler_port=0,
            dashboard_address=None, silence_logs=40) as cluster:
        tuning = {k: v for k, v in (("batch_s", args.batch_s), ("inflight_per_thread", args.inflight)) if v}
        dpool = DaskPool(cluster.scheduler_address, FN, timeout_s=120, **tuning)
        try:
            wait_workers(dpool, args.workers, 300)
            rows["dask"] = run_periods(dpool, args.buses, options, starts_warm)
            print(f"dask: per-window cost estimate {1e3 * dpool.cost_s:.2f} ms, batch of "
                  f"{dpool.batch_size(args.buses)} windows, {dpool.inflight_per_thread} in flight per thread")
        finally:
            dpool.close()
    for name, periods in rows.items():
        for r in periods:
            print(f"{name:5s} {'warm' if r['warm'] else 'cold'}: {args.buses} buses, ok {r['ok']}, failed {r['failed']}, "
                  f"period latency {r['latency_s']:.1f} s, {r['throughput']:.0f} windows/s, "
                  f"load {r['load'][0]:.1f} -> {r['load'][1]:.1f} on {os.cpu_count()} cores")
    for i, kind in enumerate(("cold", "warm")):
        ratio = rows["dask"][i]["throughput"] / rows["local"][i]["throughput"]
        print(f"{kind}: dask / local throughput = {ratio:.2f} (target >= 0.8)")


if __name__ == "__main__":
    main()
