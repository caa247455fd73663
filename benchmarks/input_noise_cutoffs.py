"""Where one window's Wiener smoother cuts the inputs off, per reporting rate, and what the spectrum's tail changes.

For issue 11's rates bench (DL 2, 0.1 % / 1e-3 rad white noise on V and θ, the windows and draws of
``benchmarks.input_noise --rates``): each noisy window's V and θ cut-offs without the tail, where the tail's
spectrum ends, and the smoothed V's error against the clean V with the tail over without (docs/numerics.md,
"Stop 42: the tail at 25 and 30 frames/s").  Prints; writes nothing.

    .venv/bin/python -m benchmarks.input_noise_cutoffs [--rates 25 30 50 100] [--n 40] [--seed 49]
"""

from __future__ import annotations

import argparse

import numpy as np

from aslm_core.noise import wiener_smooth
from aslm_core.preprocess import prepare
from benchmarks import common
from benchmarks.input_noise import INPUT_NOISE, with_input_noise


def rate_summary(fs: float, n: int, seed: int, level: int = 2) -> dict:
    """The smoother's cut-offs with and without the spectrum's tail on one rate's noisy windows.

    Parameters
    ----------
    fs : float
        Reporting rate [frames/s].
    n : int
        Windows [-].
    seed : int
        Seed of the cases and of the 0.1 % / 1e-3 rad draws (as ``benchmarks.input_noise --rates``).
    level : int
        Table I's DL of P and Q's noise.

    Returns
    -------
    dict
        ``cut_v``: V's cut-off without the tail, 10th / 50th / 90th percentile [Hz]; ``cut_theta``: θ's median [Hz];
        ``end_v``: the median of where V's tailed spectrum ends [Hz]; ``share_tailed``: windows whose V spectrum the
        tail carried past its cut-off [-]; ``error_ratio_v``: median of the smoothed V's error std against the clean
        V, with the tail over without [-].
    """
    cs = common.cases(n, level=level, seed=seed, input_noise=False, fs=fs)
    k = len(INPUT_NOISE) - 1  # the 0.1 % / 1e-3 rad class, its draws as input_noise.run_level makes them
    _, v_rel, th = INPUT_NOISE[k]
    rng = np.random.default_rng([seed, level, k])
    cuts, ends, ratio = [], [], []
    for c in cs:
        p = prepare(with_input_noise(c.window, c.clean, v_rel, th, rng), floors=True)
        sigma = np.array([p.noise["noise_v"], p.noise["noise_theta"]])
        x = np.stack([p.V, p.theta])
        s0, k0 = wiener_smooth(x, 1.0 / p.dt, sigma, return_cutoffs=True)
        s1, k1 = wiener_smooth(x, 1.0 / p.dt, sigma, return_cutoffs=True, tail=True)
        v = prepare(c.clean).V
        m = min(v.shape[0], s0.shape[1])
        cuts.append(k0)
        ends.append(k1)
        ratio.append(np.std(s1[0, :m] - v[:m]) / np.std(s0[0, :m] - v[:m]))
    cuts, ends = np.array(cuts), np.array(ends)
    return {"fs": fs, "cut_v": np.percentile(cuts[:, 0], [10, 50, 90]), "cut_theta": np.median(cuts[:, 1]),
            "end_v": np.median(ends[:, 0]), "share_tailed": float(np.mean(ends[:, 0] > cuts[:, 0] + 1e-9)),
            "error_ratio_v": float(np.median(ratio))}


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[25.0, 30.0, 50.0, 100.0])
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--seed", type=int, default=49)
    args = ap.parse_args(argv)
    out = []
    for fs in args.rates:
        r = rate_summary(fs, args.n, args.seed)
        out.append(r)
        lo, med, hi = r["cut_v"]
        print(f"{fs:5.0f} frames/s: V cut-off {med:.2f} Hz [{lo:.2f}, {hi:.2f}], θ {r['cut_theta']:.2f} Hz; tail ends "
              f"{r['end_v']:.2f} Hz; windows tailed {r['share_tailed']:.2f}; V error tail / none {r['error_ratio_v']:.3f}")
    return out


if __name__ == "__main__":
    main()
