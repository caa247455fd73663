"""The own fluctuation's spectrum indicator (``quality["own_median_hz_p"]``) on both own benches.

Per own process shape and own/total ratio: the median and range of the indicator over the windows, and on how many
windows it is present (it is absent where nothing is above the white floor), for the default identifier on the
synthetic own bench (:mod:`benchmarks.own_fluctuation`, exact V and θ) and on the ANDES own bench
(:mod:`benchmarks.own_fluctuation_andes`, its own seed's windows).  What each shape should read: the frequency below
which half of its variance lies as 9 s windows see it (:func:`aslm_sim.own.own_process`, the average of 400
windows' detrended 10 % Tukey periodograms up to 5 Hz).

    .venv/bin/python -m benchmarks.own_spectrum_indicator [--n 30] [--seed 43] [--own-seed 1]

Results: ``docs/results/own_spectrum_indicator.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

from aslm_core import WindowError, identify  # noqa: E402
from aslm_core.noise import periodogram  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from aslm_sim.network import forcing_filter  # noqa: E402
from aslm_sim.own import own_process  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation import LEVEL, own_cases  # noqa: E402

SHAPES = ("lowpass", "switching", "pink")
RATIOS = (0.0, 0.5, 0.9)


def shape_median_hz(shape: str, fs: float = 100.0, length: int = 900, windows: int = 400, top_hz: float = 5.0) -> float:
    """Where half of a shape's variance below ``top_hz`` lies as windows of ``length`` samples see it (each
    detrended, as the indicator's periodogram does), from their average periodogram over one long realisation [Hz]."""
    sos, gain = forcing_filter(fs)
    x = own_process(np.random.default_rng(7), shape, length * windows, fs, sos, gain).reshape(windows, length)
    f, pxx = periodogram(x, fs)
    band = (f > 0.0) & (f <= top_hz)
    cum = np.cumsum(pxx.mean(axis=0)[band])
    return float(f[band][np.searchsorted(cum, 0.5 * cum[-1])])


def readings(windows: list) -> list[float]:
    out = []
    for w in windows:
        try:
            out.append(identify(w).quality.get("own_median_hz_p", np.nan))
        except WindowError:
            out.append(np.nan)
    return out


def summary(vals: list[float]) -> dict:
    v = np.array(vals, dtype=float)
    ok = np.isfinite(v)
    return {"n": int(v.size), "present": int(ok.sum()), "median_hz": float(np.median(v[ok])) if ok.any() else None,
            "min_hz": float(v[ok].min()) if ok.any() else None, "max_hz": float(v[ok].max()) if ok.any() else None}


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=30, help="windows per row")
    ap.add_argument("--seed", type=int, default=43, help="synthetic own bench seed")
    ap.add_argument("--own-seed", type=int, default=1, help="ANDES own bench seed (0: skip ANDES)")
    args = ap.parse_args(argv)
    out = {"machine": common.machine(), "n": args.n, "seed": args.seed, "own_seed": args.own_seed,
           "truth_hz": {s: shape_median_hz(s) for s in SHAPES}, "rows": []}
    base = make_cases(args.n, level=LEVEL, seed=args.seed, input_noise=False)
    benches = ["synthetic"] + (["andes"] if args.own_seed else [])
    if args.own_seed:
        from aslm_sim.andes import own_fluctuation as andes_own
        from benchmarks import own_fluctuation_andes as ab

        grid = andes_own.grid_recording(tf=ab.TF, tstep=ab.TSTEP, seed=ab.SEED, fs=ab.FS)
    table = []
    for bench in benches:
        for shape in SHAPES:
            if bench == "andes":
                own = andes_own.own_recording(shape, tf=ab.TF, tstep=ab.TSTEP, seed=args.own_seed)
            for ratio in RATIOS:
                if ratio == 0.0 and shape != SHAPES[0]:
                    continue
                if bench == "synthetic":
                    cs = own_cases(args.n, ratio, shape, base, args.seed) if ratio else base
                    windows = [c.window for c in cs]
                else:
                    windows = [ab.as_window(w) for w in ab.row_windows(grid, own if ratio else None, ratio, shape,
                                                                         args.n, args.own_seed)]
                s = summary(readings(windows))
                label = shape if ratio else "–"
                out["rows"].append({"bench": bench, "shape": label, "ratio": ratio, **s})
                rng_txt = f"{s['min_hz']:.2f}–{s['max_hz']:.2f}" if s["present"] else "–"
                med_txt = f"{s['median_hz']:.2f}" if s["present"] else "–"
                table.append([bench, label, f"{ratio:g}", f"{s['present']}/{s['n']}", med_txt, rng_txt,
                              f"{out['truth_hz'][shape]:.2f}" if ratio else "–"])
                print(f"{bench} {label} {ratio:g}: done", flush=True)
    print(common.md_table(["bench", "own shape", "own ratio", "present", "median [Hz]", "range [Hz]",
                           "the shape's own [Hz]"], table))
    if not args.no_write:
        common.write_json("own_spectrum_indicator", out)
    return out


if __name__ == "__main__":
    main()
