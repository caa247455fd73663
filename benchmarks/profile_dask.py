"""Where the time goes: the same windows on the local pool and on a 2-worker LocalCluster.

Both executors stay up for the whole run and take turns (interleaved repetitions), each given the same
cold tasks in groups of 64, as the period scheduler hands them over.  Reported per run: wall time and
throughput; per window the worker thread's wall and CPU time inside the task (``TaskOutcome``); the
CPU time of every process group (this process, by thread: the main thread submits, ``IO loop`` are
the in-process Dask scheduler's, nannies' and client's event loops; the local pool's workers; the Dask
workers).  The idle executor's processes are counted too: their overhead is real.  The cluster runs
with the executor's ``CLUSTER_CONFIG`` unless ``--dask-defaults``.

    .venv/bin/python benchmarks/profile_dask.py --buses 1000 --reps 3
    .venv/bin/python benchmarks/profile_dask.py --buses 1000 --reps 3 --dask-defaults
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import threading
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from benchmarks.bench_period import FS, cpu_s, fill  # noqa: E402
from service.buffers import BufferStore  # noqa: E402
from service.executors.base import WindowTask  # noqa: E402
from service.settings import ServiceSettings  # noqa: E402

FN = "service.worker:identify_window"
GROUP = 64  # the period scheduler's submit group (service/scheduler.py)


def thread_cpu() -> dict[str, float]:
    """CPU time [s] of this process's threads, summed by thread name (Linux /proc)."""
    tick = os.sysconf("SC_CLK_TCK")
    out: dict[str, float] = {}
    for th in threading.enumerate():
        try:
            with open(f"/proc/self/task/{th.native_id}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        name = "main" if th is threading.main_thread() else th.name.split("_")[0].split(" (")[0]
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def make_tasks(buses: int, options: dict) -> list[WindowTask]:
    """Cold tasks for ``buses`` windows of the synthetic fleet, cut as the period scheduler cuts them."""
    period_s = 60.0
    boundary = (np.floor(time.time() / period_s) - 2) * period_s
    store = BufferStore(10.0, FS, 1.0)
    fill(store, buses, boundary)
    return [WindowTask(store.buffer(bus, create=False).cut(boundary - 10.0, boundary, f0=50.0, bus=bus),
                       options=options) for bus in store.buses()]


def sched_s(pids: list[int]) -> tuple[float, float]:
    """(CPU, run-queue wait) [s] summed over every thread of ``pids`` (Linux schedstat)."""
    cpu = wait = 0.0
    for pid in pids:
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            try:
                with open(f"/proc/{pid}/task/{tid}/schedstat") as fh:
                    fields = fh.read().split()
            except OSError:
                continue
            cpu, wait = cpu + int(fields[0]) / 1e9, wait + int(fields[1]) / 1e9
    return cpu, wait


def run(executor, tasks: list[WindowTask], groups: dict[str, list[int]], workers: list[int]) -> dict:
    """Submit ``tasks`` in groups of :data:`GROUP` and wait for all; times and CPU of the run.

    ``groups``: name → pids whose CPU time during the run is reported; ``workers``: the executor's
    worker processes, whose threads' time running and waiting for a core (run queue) is summed.
    """
    th0, t0 = thread_cpu(), time.perf_counter()
    g0 = {name: cpu_s(pids) for name, pids in groups.items()}
    b0 = getattr(executor, "batches", 0)
    s0 = sched_s(workers)
    futs = []
    for i in range(0, len(tasks), GROUP):
        futs += executor.submit_many(tasks[i:i + GROUP])
    outcomes = [f.result() for f in futs]
    wall = time.perf_counter() - t0
    th1 = thread_cpu()
    s1 = sched_s(workers)
    run_s, wait_s = s1[0] - s0[0], s1[1] - s0[1]
    g1 = {name: round(cpu_s(pids) - g0[name], 2) for name, pids in groups.items()}
    ok = [o for o in outcomes if o.ok]
    return {"n": len(tasks), "ok": len(ok), "wall_s": round(wall, 3), "throughput": len(ok) / wall,
            "window_wall_ms": 1e3 * statistics.mean(o.elapsed_s for o in ok),
            "window_cpu_ms": 1e3 * statistics.mean(o.cpu_s for o in ok),
            "dask_tasks": getattr(executor, "batches", 0) - b0,
            "threads_cpu_s": {k: round(th1[k] - th0.get(k, 0.0), 2) for k in th1 if th1[k] - th0.get(k, 0.0) >= 0.01},
            "groups_cpu_s": g1, "workers_running_s": round(run_s, 2), "workers_waiting_s": round(wait_s, 2),
            "load": os.getloadavg()[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=1000)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--dask-defaults", action="store_true",
                    help="the LocalCluster with Dask's default settings (but one retry), not CLUSTER_CONFIG")
    ap.add_argument("--out", default=None, help="JSON of every run")
    args = ap.parse_args()

    import dask
    import distributed

    from service.executors.dask import CLUSTER_CONFIG, DaskPool, wait_workers
    from service.executors.local import LocalPool

    defaults = ServiceSettings.model_fields
    options = {"n_starts": defaults["n_starts"].default, "lowpass_hz": defaults["lowpass_hz"].default}
    tasks = make_tasks(args.buses, options)
    config = {"distributed.scheduler.allowed-failures": 1} if args.dask_defaults else CLUSTER_CONFIG
    pool = LocalPool(args.workers, FN, timeout_s=120)
    pool.wait_ready(300)
    rows: dict[str, list] = {"local": [], "dask": []}
    with dask.config.set(config), distributed.LocalCluster(
            n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1", scheduler_port=0,
            dashboard_address=None, silence_logs=40) as cluster:
        dpool = DaskPool(cluster.scheduler_address, FN, timeout_s=120)
        try:
            wait_workers(dpool, args.workers, 300)
            dpids = list(dpool.client.run(os.getpid).values())
            # A LocalCluster's nannies live in this process: its CPU includes theirs.
            groups = {"this process": [os.getpid()], "local workers": pool.pids(), "dask workers": dpids}
            workers = {"local": pool.pids(), "dask": dpids}
            run(pool, tasks[:GROUP], groups, workers["local"])  # both warmed on these windows before timing
            run(dpool, tasks[:GROUP], groups, workers["dask"])
            for r in range(args.reps):
                for name, ex in (("local", pool), ("dask", dpool)):
                    row = run(ex, tasks, groups, workers[name])
                    rows[name].append(row)
                    print(f"rep {r} {name:5s}: {row['wall_s']:.2f} s, {row['throughput']:.0f} windows/s, window "
                          f"{row['window_wall_ms']:.2f} ms wall / {row['window_cpu_ms']:.2f} ms cpu, "
                          f"{row['dask_tasks']} Dask tasks, load {row['load']:.1f}\n"
                          f"    worker processes' threads: running {row['workers_running_s']} s, waiting for a core "
                          f"{row['workers_waiting_s']} s\n"
                          f"    cpu-s by process: {row['groups_cpu_s']} (sum {sum(row['groups_cpu_s'].values()):.2f}); "
                          f"this process by thread: {row['threads_cpu_s']}", flush=True)
        finally:
            dpool.close()
            pool.close()
    ratios = [d["throughput"] / lo["throughput"] for d, lo in zip(rows["dask"], rows["local"], strict=True)]
    print(f"dask / local throughput: median {statistics.median(ratios):.2f}, range {min(ratios):.2f}-{max(ratios):.2f}")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump({"buses": args.buses, "config": config, "runs": rows, "ratios": ratios}, fh, indent=1)


if __name__ == "__main__":
    main()
