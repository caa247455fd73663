"""The 1,000-window batch target (≤ 4 s) for the default against output error, interleaved.

``benchmarks.speed`` times the batch once per worker count; on this shared machine one run moves by ±15 %
from the next.  Here the same 1,000 DL 1 windows (``benchmarks.speed``'s) go through ``identify_many`` with the
default (``input_weighting="spectral"``, ``disturbance="gated"``) and with output error
(:data:`benchmarks.common.OUTPUT_ERROR`), the two taking turns, ``--reps`` times on 2 and on 1 worker, so that
what the default costs on exact inputs is told apart from the machine's drift.

    .venv/bin/python -m benchmarks.batch_ab [--reps 3] [--n 1000]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, identify, identify_many  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.speed import SEED  # noqa: E402

CONFIGS = {"default": IdentifyConfig(), "output error": IdentifyConfig(**common.OUTPUT_ERROR)}
WORKERS = (2, 1)


def batch_times(n: int, reps: int) -> dict[str, dict[int, list[float]]]:
    """Per configuration and worker count, the wall time [s] of each repetition of the n-window batch."""
    windows = [c.window for c in common.cases(n, level=1, seed=SEED, input_noise=False)]
    for cfg in CONFIGS.values():
        identify(windows[0], config=cfg)  # numba caches loaded outside the timings
    out: dict[str, dict[int, list[float]]] = {name: {w: [] for w in WORKERS} for name in CONFIGS}
    for rep in range(reps):
        # Alternate which configuration goes first, so a slow spell does not always fall on the same one.
        names = list(CONFIGS) if rep % 2 == 0 else list(CONFIGS)[::-1]
        for workers in WORKERS:
            for name in names:
                t0 = time.perf_counter()
                identify_many(windows, config=CONFIGS[name], workers=workers)
                out[name][workers].append(time.perf_counter() - t0)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=1000, help="windows per batch")
    p.add_argument("--reps", type=int, default=3)
    args = p.parse_args(argv)
    res = {"machine": common.machine(), "n": args.n, "reps": args.reps, "seconds": batch_times(args.n, args.reps)}
    res["load_avg_at_end"] = list(os.getloadavg())
    print("| configuration | workers | batch times [s] | median [s] |\n|---|---|---|---|")
    for name, per in res["seconds"].items():
        for w, ts in per.items():
            print(f"| {name} | {w} | {' / '.join(f'{t:.2f}' for t in ts)} | {np.median(ts):.2f} |")
    common.write_json("batch_ab", res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
