"""Period throughput: the Dask executor on a 2-worker LocalCluster against the local process pool.

Both executors are started (and compiled, and warmed on a first small period) before any timing and
stay up for the whole run; they then take turns on the same windows (the synthetic fleet of
``bench_period.py``, noise level 2): per repetition, the local pool's cold period (no warm starts,
``n_starts``), the cluster's cold period, the local pool's warm-started period (``n_starts_warm``), the
cluster's warm-started one, as the service runs them.  Interleaving matters on a shared machine: the
other jobs' load moves between minutes.  The cluster's workers are processes of one thread each with
the executor's ``CLUSTER_CONFIG`` (as the compose profile runs them); its scheduler runs in this
process, as a ``LocalCluster``'s does.  Throughput is windows identified per second of period
latency; the target is Dask ≥ 0.8 × local (median over the repetitions, with the range).

    .venv/bin/python benchmarks/bench_dask.py --buses 10000 --reps 2 --out docs/results/bench_dask.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from benchmarks.bench_period import FS, cpu_s, fill  # noqa: E402
from service.buffers import BufferStore  # noqa: E402
from service.scheduler import QualityRules, Scheduler  # noqa: E402
from service.settings import ServiceSettings  # noqa: E402

FN = "service.worker:identify_window"
PERIOD_S = 60.0


def run_period(executor, buses: int, p: int, warm: dict, options: dict, starts_warm: int, pids: list[int]) -> dict:
    """The ``p``-th period of ``buses`` windows on ``executor`` (warm-started from ``warm``, which it updates)."""
    boundary = (np.floor(time.time() / PERIOD_S) - 2) * PERIOD_S
    store = BufferStore(10.0, FS, 1.0)
    fill(store, buses, boundary, skip_s=p * PERIOD_S)
    sched = Scheduler(store, executor, QualityRules(10.0, FS, 0.9, 0.2, 1e-5), late_s=1.0, f0=50.0,
                      period_s=lambda: PERIOD_S, on_results=lambda r: None, on_period=lambda s: None,
                      warm_starts=warm, options=options, n_starts_warm=starts_warm)
    load0, c0, b0 = os.getloadavg()[0], cpu_s(pids), getattr(executor, "batches", 0)
    s = sched.run_period(boundary, PERIOD_S)
    return {"warm": bool(p), "ok": s.n_ok, "failed": s.n_failed, "latency_s": round(s.latency_s, 3),
            "throughput": s.n_ok / s.latency_s, "cpu_s": round(cpu_s(pids) - c0, 2),
            "dask_tasks": getattr(executor, "batches", 0) - b0, "load": (load0, os.getloadavg()[0])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=10_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--reps", type=int, default=2, help="interleaved repetitions (cold + warm period each)")
    ap.add_argument("--batch-s", type=float, default=None, help="work per batch [s of CPU] (executor default)")
    ap.add_argument("--inflight", type=int, default=None, help="batches in flight per worker thread (default)")
    ap.add_argument("--out", default=None, help="JSON of every period")
    args = ap.parse_args()

    import dask
    import distributed

    from service.executors.dask import CLUSTER_CONFIG, DaskPool, wait_workers
    from service.executors.local import LocalPool

    defaults = ServiceSettings.model_fields
    options = {"n_starts": defaults["n_starts"].default, "lowpass_hz": defaults["lowpass_hz"].default}
    starts_warm = defaults["n_starts_warm"].default
    rows: dict[str, list] = {"local": [], "dask": []}
    pool = LocalPool(args.workers, FN, timeout_s=120)
    pool.wait_ready(300)
    with dask.config.set(CLUSTER_CONFIG), distributed.LocalCluster(
            n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1", scheduler_port=0,
            dashboard_address=None, silence_logs=40) as cluster:
        tuning = {k: v for k, v in (("batch_s", args.batch_s), ("inflight_per_thread", args.inflight)) if v}
        dpool = DaskPool(cluster.scheduler_address, FN, timeout_s=120, **tuning)
        try:
            wait_workers(dpool, args.workers, 300)
            pids = {"local": [os.getpid(), *pool.pids()],
                    "dask": [os.getpid(), *dpool.client.run(os.getpid).values()]}
            executors = {"local": pool, "dask": dpool}
            for name, ex in executors.items():  # warm-up: both compiled and exercised before timing
                run_period(ex, 200, 0, {}, options, starts_warm, pids[name])
            for r in range(args.reps):
                warm: dict[str, dict] = {"local": {}, "dask": {}}
                for p in range(2):
                    for name, ex in executors.items():
                        row = run_period(ex, args.buses, p, warm[name], options, starts_warm, pids[name])
                        rows[name].append(row | {"rep": r})
                        print(f"rep {r} {name:5s} {'warm' if p else 'cold'}: {args.buses} buses, ok {row['ok']}, "
                              f"failed {row['failed']}, period latency {row['latency_s']:.1f} s, "
                              f"{row['throughput']:.0f} windows/s, {1e3 * row['cpu_s'] / max(row['ok'], 1):.2f} ms "
                              f"CPU per window (this process + workers), {row['dask_tasks']} Dask tasks, "
                              f"load {row['load'][0]:.1f} -> {row['load'][1]:.1f} on {os.cpu_count()} cores",
                              flush=True)
            print(f"dask: per-window CPU estimate {1e3 * dpool.cost_s:.2f} ms, wall {1e3 * dpool.wall_s:.2f} ms, "
                  f"batch of {dpool.batch_size(args.buses)} windows, {dpool.inflight_per_thread} in flight per thread")
        finally:
            dpool.close()
            pool.close()
    summary = {}
    for kind, warm in (("cold", False), ("warm", True)):
        pairs = [(d, lo) for d, lo in zip(rows["dask"], rows["local"], strict=True) if d["warm"] == warm]
        ratios = [d["throughput"] / lo["throughput"] for d, lo in pairs]
        summary[kind] = {"median": statistics.median(ratios), "min": min(ratios), "max": max(ratios),
                         "ratios": ratios}
        print(f"{kind}: dask / local throughput = median {summary[kind]['median']:.2f} "
              f"(range {min(ratios):.2f}-{max(ratios):.2f} over {len(ratios)}; target >= 0.8)")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"buses": args.buses, "workers": args.workers, "reps": args.reps, "cores": os.cpu_count(),
                       "cluster_config": CLUSTER_CONFIG, "periods": rows, "dask_over_local": summary}, fh, indent=1)


if __name__ == "__main__":
    main()
