"""The 1,000-window batch target (≤ 4 s), interleaved: the default against output error, or pool against pool.

``benchmarks.speed`` times the batch once per worker count; on this shared machine one run moves by ±15 %
from the next.  Here the same 1,000 DL 1 windows (``benchmarks.speed``'s) go through ``identify_many``, the
variants taking turns (the order alternating between repetitions), ``--reps`` times:

* ``--mode configs``: the default (``input_weighting="spectral"``, ``disturbance="gated"``) and output error
  (:data:`benchmarks.common.OUTPUT_ERROR`) on 2 and on 1 worker, so that what the default costs on exact inputs is
  told apart from the machine's drift (``docs/results/batch_ab.json``);
* ``--mode pools``: the default configuration on 2 forked processes (``pool="process"``, what ``auto`` runs for
  such a batch), on 2 threads (``pool="thread"``, the path before) and on 1 worker
  (``docs/results/batch_ab_pools.json``).

Each call is timed whole (pool start-up and tear-down included), in wall time and in CPU time (this process's
threads plus its reaped children): on a machine shared with other jobs the wall time says what the caller waits,
the CPU time what the batch costs.

    .venv/bin/python -m benchmarks.batch_ab [--mode configs|pools] [--reps 3] [--n 1000]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, identify, identify_many  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.speed import SEED  # noqa: E402

CONFIGS = {"default": IdentifyConfig(), "output error": IdentifyConfig(**common.OUTPUT_ERROR)}
WORKERS = (2, 1)
#: ``--mode pools``: name → (pool, workers) of ``identify_many`` with the default configuration.
POOLS = {"process, 2 workers": ("process", 2), "thread, 2 workers": ("thread", 2), "1 worker": ("thread", 1)}


def _cpu_s() -> float:
    """CPU seconds so far of this process's threads and of its children that have been waited for."""
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + c.ru_utime + c.ru_stime


def timed_call(windows: list, config: IdentifyConfig, workers: int, pool: str = "auto") -> tuple[float, float]:
    """Wall and CPU seconds of one ``identify_many`` call."""
    c0, t0 = _cpu_s(), time.perf_counter()
    identify_many(windows, config=config, workers=workers, pool=pool)
    return time.perf_counter() - t0, _cpu_s() - c0


def batch_times(n: int, reps: int, mode: str = "configs") -> dict[str, dict]:
    """Per variant, the wall and CPU times [s] of each repetition of the n-window batch.

    ``configs``: {configuration: {workers: [wall, ...]}} and the CPU times under ``"cpu"``; ``pools``:
    {pool variant: {"wall": [...], "cpu": [...]}}.
    """
    windows = [c.window for c in common.cases(n, level=1, seed=SEED, input_noise=False)]
    for cfg in CONFIGS.values():
        identify(windows[0], config=cfg)  # numba caches loaded outside the timings
    if mode == "pools":
        runs = [(name, CONFIGS["default"], w, pool) for name, (pool, w) in POOLS.items()]
    else:
        runs = [(name, CONFIGS[name], w, "auto") for w in WORKERS for name in CONFIGS]
    wall: dict = {}
    cpu: dict = {}
    for rep in range(reps):
        # Alternate the order, so a slow spell does not always fall on the same variant.
        for name, cfg, workers, pool in runs if rep % 2 == 0 else runs[::-1]:
            key = name if mode == "pools" else (name, workers)
            t, c = timed_call(windows, cfg, workers, pool)
            wall.setdefault(key, []).append(t)
            cpu.setdefault(key, []).append(c)
    if mode == "pools":
        return {name: {"wall": wall[name], "cpu": cpu[name]} for name in POOLS}
    out: dict = {name: {w: wall[(name, w)] for w in WORKERS} for name in CONFIGS}
    out["cpu"] = {name: {w: cpu[(name, w)] for w in WORKERS} for name in CONFIGS}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", choices=("configs", "pools"), default="configs")
    p.add_argument("--n", type=int, default=1000, help="windows per batch")
    p.add_argument("--reps", type=int, default=3)
    args = p.parse_args(argv)
    res = {"machine": common.machine(), "n": args.n, "reps": args.reps,
           "seconds": batch_times(args.n, args.reps, args.mode)}
    res["load_avg_at_end"] = list(os.getloadavg())
    if args.mode == "pools":
        print("| pool | wall times [s] | median [s] | CPU times [s] | median [s] |\n|---|---|---|---|---|")
        for name, r in res["seconds"].items():
            print(f"| {name} | {' / '.join(f'{t:.2f}' for t in r['wall'])} | {np.median(r['wall']):.2f} | "
                  f"{' / '.join(f'{t:.2f}' for t in r['cpu'])} | {np.median(r['cpu']):.2f} |")
        common.write_json("batch_ab_pools", res)
        return 0
    print("| configuration | workers | batch times [s] | median [s] |\n|---|---|---|---|")
    for name in CONFIGS:
        for w, ts in res["seconds"][name].items():
            print(f"| {name} | {w} | {' / '.join(f'{t:.2f}' for t in ts)} | {np.median(ts):.2f} |")
    common.write_json("batch_ab", res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
