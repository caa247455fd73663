"""The inputs inside a sample step, with exact V and θ, at every reporting rate: the not-a-knot cubic spline (the
default since stop 50, ``aslm_core.motor.SPLINE_INPUTS``) against the 4-point Lagrange cubics before it, on the same
windows (issue 11: "RK4 at the sample step may need sub-steps for fast motors — check it").

    .venv/bin/python -m benchmarks.input_interpolation [--seed 11] [--n 300] [--rates 25 30 50 60 100 120] [--tag NAME]
        [--levels noise-free "DL 1" "DL 2" "DL 3"]

Per rate, on ``n`` windows of the project's generator (``aslm_sim``, 1 ms steps) with exact inputs, noise-free and at
DL 2 by default (P and Q at the level's SNR): μ of D/D_real − 1 for both interpolations, their paired difference with
its standard error, the worst |error| and the coverage of ±1.96 SE.  ANDES's records (an independent simulator) at 100, 50 and 25 frames/s:
``benchmarks.andes_rates`` with ``--tag spline`` against its run of record.  Written to
``docs/results/input_interpolation_seed<seed>[_<tag>].json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import identify, motor  # noqa: E402
from benchmarks import common  # noqa: E402

RATES = (25.0, 30.0, 50.0, 60.0, 100.0, 120.0)
LEVELS = {"noise-free": None, "DL 1": 1, "DL 2": 2, "DL 3": 3}


def ratios(cases: list, spline: bool) -> tuple[np.ndarray, np.ndarray]:
    """D/D_real and SE/D_real per window (rows) with the spline (True) or the Lagrange cubics inside the sample step."""
    old = motor.SPLINE_INPUTS
    motor.SPLINE_INPUTS = spline
    try:
        rs = [identify(c.window) for c in cases]
    finally:
        motor.SPLINE_INPUTS = old
    truth = np.array([c.truth.d for c in cases])
    return (np.array([r.d for r in rs]) / truth,
            np.array([[r.stderr[k] for k in common.PARAMS] for r in rs]) / truth)


def cell(cases: list) -> dict:
    """Both interpolations on the same windows: μ − 1, the paired difference (spline − Lagrange) and its SE, the
    worst |error| and the coverage of ±1.96 SE of each."""
    (lag, lag_se), (spl, spl_se) = ratios(cases, False), ratios(cases, True)
    diff = spl - lag
    n = len(cases)
    return {"n": n, "bias_lagrange": (lag.mean(axis=0) - 1).tolist(), "bias_spline": (spl.mean(axis=0) - 1).tolist(),
            "se_bias": (spl.std(axis=0, ddof=1) / np.sqrt(n)).tolist(),
            "paired_diff": diff.mean(axis=0).tolist(), "se_paired_diff": (diff.std(axis=0, ddof=1) / np.sqrt(n)).tolist(),
            "worst_lagrange": np.abs(lag - 1).max(axis=0).tolist(), "worst_spline": np.abs(spl - 1).max(axis=0).tolist(),
            "cover_lagrange": np.mean(np.abs(lag - 1) < 1.96 * lag_se, axis=0).tolist(),
            "cover_spline": np.mean(np.abs(spl - 1) < 1.96 * spl_se, axis=0).tolist()}


def _pct(xs: list[float]) -> str:
    return " / ".join(f"{100 * x:+.2f}" for x in xs)


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--n", type=int, default=None, help="windows per rate and level (default 300; --quick: 30)")
    ap.add_argument("--rates", type=float, nargs="+", default=list(RATES))
    ap.add_argument("--tag", default="", help="suffix of the results file")
    ap.add_argument("--levels", nargs="+", choices=list(LEVELS), default=["noise-free", "DL 2"],
                    help="P and Q noise levels (names as LEVELS)")
    args = ap.parse_args(argv)
    n = args.n or (30 if args.quick else 300)
    out = {"machine": common.machine(), "seed": args.seed, "n": n, "cells": {}}
    t0 = time.perf_counter()
    print("| frames/s | P/Q | bias a / b / H2 / Tm, Lagrange [%] | spline [%] | spline − Lagrange ± SE [%] "
          "| worst, Lagrange → spline [%] | ±1.96 SE cover, Lagrange → spline [%] |")
    print("|---|---|---|---|---|---|---|")
    for fs in args.rates:
        for name in args.levels:
            level = LEVELS[name]
            c = out["cells"][f"{fs:g}|{name}"] = cell(common.cases(n, level=level, seed=args.seed, fs=fs))
            print(f"| {fs:g} | {name} | {_pct(c['bias_lagrange'])} | {_pct(c['bias_spline'])} | "
                  + " / ".join(f"{100 * d:+.2f} ± {100 * s:.2f}" for d, s in zip(c["paired_diff"], c["se_paired_diff"],
                                                                                  strict=True))
                  + " | " + " / ".join(f"{100 * a:.1f} → {100 * b:.1f}" for a, b in zip(c["worst_lagrange"],
                                                                                     c["worst_spline"], strict=True))
                  + " | " + " / ".join(f"{100 * a:.0f} → {100 * b:.0f}" for a, b in zip(c["cover_lagrange"],
                                                                                    c["cover_spline"], strict=True))
                  + " |", flush=True)
    out["total_s"] = time.perf_counter() - t0
    if not args.no_write:
        common.write_json(f"input_interpolation_seed{args.seed}" + (f"_{args.tag}" if args.tag else ""), out)
    return out


if __name__ == "__main__":
    main()
