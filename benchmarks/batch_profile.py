"""Where a batch window's time goes: inside the GIL-free compiled kernels, or in Python under the GIL.

``identify_many(windows[:n], workers=1)`` on ``benchmarks.speed``'s DL 1 windows, twice after a warm-up: once
with every numba kernel that Python calls wrapped by a timer (the time inside them is the part that releases
the GIL, since every kernel is ``nogil``), once under cProfile (the Python functions that hold the GIL, by own
time).  A thread pool can overlap only the first part; the second runs one thread at a time.

    .venv/bin/python -m benchmarks.batch_profile [--n 200] [--top 25]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import pstats  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

from numba.core.registry import CPUDispatcher  # noqa: E402

from aslm_core import IdentifyConfig, identify, identify_many  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.speed import SEED  # noqa: E402


def _timed(fn: CPUDispatcher, acc: dict[str, list[float]]) -> Callable:
    """``fn`` with its wall time and call count added to ``acc[fn's name]``."""
    name = f"{fn.py_func.__module__.rsplit('.', 1)[-1]}.{fn.__name__}"
    acc.setdefault(name, [0.0, 0])

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            slot = acc[name]
            slot[0] += time.perf_counter() - t0
            slot[1] += 1

    return wrapper


def kernel_times(windows: list, config: IdentifyConfig) -> tuple[float, dict[str, list[float]]]:
    """Wall time [s] of the one-worker batch and, per kernel called from Python, [seconds, calls].

    The kernels are module attributes looked up at call time, so replacing them in every ``aslm_core`` module
    (after the warm-up: nothing is compiled while they are wrapped) times each call from Python; calls between
    kernels stay inside compiled code.
    """
    acc: dict[str, list[float]] = {}
    patched = []
    for mod_name, mod in list(sys.modules.items()):
        if not mod_name.startswith("aslm_core") or mod is None:
            continue
        for attr, val in list(vars(mod).items()):
            if isinstance(val, CPUDispatcher):
                patched.append((mod, attr, val))
                setattr(mod, attr, _timed(val, acc))
    try:
        t0 = time.perf_counter()
        identify_many(windows, config=config, workers=1)
        wall = time.perf_counter() - t0
    finally:
        for mod, attr, val in patched:
            setattr(mod, attr, val)
    return wall, acc


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=200, help="windows")
    p.add_argument("--top", type=int, default=25, help="Python functions listed")
    args = p.parse_args(argv)
    windows = [c.window for c in common.cases(args.n, level=1, seed=SEED, input_noise=False)]
    config = IdentifyConfig()
    identify(windows[0], config=config)  # numba caches loaded outside the timings
    t0 = time.perf_counter()
    identify_many(windows, config=config, workers=1)
    plain = time.perf_counter() - t0
    wall, acc = kernel_times(windows, config)
    inside = sum(v[0] for v in acc.values())
    load = os.getloadavg()
    print(f"load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; {args.n} windows, 1 worker: {plain:.3f} s plain, "
          f"{wall:.3f} s with kernel timers; inside nogil kernels {inside:.3f} s ({100 * inside / wall:.1f} %), "
          f"Python under the GIL {wall - inside:.3f} s ({100 * (wall - inside) / wall:.1f} %)")
    print("| kernel | calls | s | % of wall |\n|---|---|---|---|")
    for name, (s, calls) in sorted(acc.items(), key=lambda kv: -kv[1][0]):
        if calls:
            print(f"| {name} | {calls} | {s:.3f} | {100 * s / wall:.1f} |")
    prof = cProfile.Profile()
    prof.enable()
    identify_many(windows, config=config, workers=1)
    prof.disable()
    for key in ("tottime", "cumulative"):
        out = io.StringIO()
        pstats.Stats(prof, stream=out).sort_stats(key).print_stats(args.top)
        print(out.getvalue())
    res = {"machine": common.machine(), "n": args.n, "plain_s": plain, "wall_with_timers_s": wall,
           "inside_kernels_s": inside, "kernels": {k: {"s": v[0], "calls": v[1]} for k, v in acc.items() if v[1]},
           "load_avg_at_end": list(os.getloadavg())}
    common.write_json("batch_profile", res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
