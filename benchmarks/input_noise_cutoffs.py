"""Where one window's Wiener smoother cuts the inputs off, per reporting rate, and what the spectrum's tail changes.

For issue 11's rates bench (DL 2, 0.1 % / 1e-3 rad white noise on V and θ, the windows and draws of
``benchmarks.input_noise --rates``): each noisy window's V and θ cut-offs without the tail, where the tail's
spectrum ends, and the smoothed V's error against the clean V with the tail over without (docs/numerics.md,
"Stop 42: the tail at 25 and 30 frames/s").  ``--edges``: where in the window the smoothed inputs' error lies — its
mean square near each end over mid-window's (docs/numerics.md, "Stop 43").  Prints; writes nothing.

    .venv/bin/python -m benchmarks.input_noise_cutoffs [--rates 25 30 50 100] [--n 40] [--seed 49] [--edges]
"""

from __future__ import annotations

import argparse

import numpy as np

from aslm_core.noise import wiener_smooth
from aslm_core.preprocess import prepare
from benchmarks import common
from benchmarks.input_noise import INPUT_NOISE, with_input_noise


def _noisy_windows(fs: float, n: int, seed: int, level: int):
    """The rates bench's noisy windows at one rate (0.1 % / 1e-3 rad, its draws as ``benchmarks.input_noise
    --rates`` makes them): per window the prepared noisy window (with its floors), the floors σ_V [pu], σ_θ [rad] and
    the prepared clean window."""
    cs = common.cases(n, level=level, seed=seed, input_noise=False, fs=fs)
    k = len(INPUT_NOISE) - 1
    _, v_rel, th = INPUT_NOISE[k]
    rng = np.random.default_rng([seed, level, k])
    for c in cs:
        p = prepare(with_input_noise(c.window, c.clean, v_rel, th, rng), floors=True)
        yield p, np.array([p.noise["noise_v"], p.noise["noise_theta"]]), prepare(c.clean)


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
    cuts, ends, ratio = [], [], []
    for p, sigma, clean in _noisy_windows(fs, n, seed, level):
        x = np.stack([p.V, p.theta])
        s0, k0 = wiener_smooth(x, 1.0 / p.dt, sigma, return_cutoffs=True)
        s1, k1 = wiener_smooth(x, 1.0 / p.dt, sigma, return_cutoffs=True, tail=True)
        m = min(clean.V.shape[0], s0.shape[1])
        cuts.append(k0)
        ends.append(k1)
        ratio.append(np.std(s1[0, :m] - clean.V[:m]) / np.std(s0[0, :m] - clean.V[:m]))
    cuts, ends = np.array(cuts), np.array(ends)
    return {"fs": fs, "cut_v": np.percentile(cuts[:, 0], [10, 50, 90]), "cut_theta": np.median(cuts[:, 1]),
            "end_v": np.median(ends[:, 0]), "share_tailed": float(np.mean(ends[:, 0] > cuts[:, 0] + 1e-9)),
            "error_ratio_v": float(np.median(ratio))}


#: Spans from each end of the window over which :func:`edge_profile` averages the error [s].
EDGE_SPANS = ((0.0, 0.1), (0.1, 0.25), (0.25, 0.5), (0.5, 1.0))


def edge_profile(fs: float, n: int, seed: int, level: int = 2) -> dict:
    """The smoothed inputs' error near the window's ends against mid-window, on one rate's noisy windows.

    Parameters
    ----------
    fs, n, seed, level
        As :func:`rate_summary` (the same windows and draws).

    Returns
    -------
    dict
        ``start`` and ``end``: per span of :data:`EDGE_SPANS` [s] from that end, the mean square of the Wiener smoother's
        V and θ error (the refinement's smoother, its spectrum's tail on) over the mean square in the middle half of
        the window, (V, θ) [-]; each window's error taken about its mean.
    """
    err = []
    for p, sigma, clean in _noisy_windows(fs, n, seed, level):
        s = wiener_smooth(np.stack([p.V, p.theta]), 1.0 / p.dt, sigma, tail=True)
        m = min(clean.V.size, s.shape[1])
        e = np.stack([s[0, :m] - clean.V[:m], s[1, :m] - clean.theta[:m]])
        err.append((e - e.mean(axis=1, keepdims=True)) ** 2)
    m = min(e.shape[1] for e in err)
    sq = np.mean([e[:, :m] for e in err], axis=0)
    mid = sq[:, m // 4: 3 * m // 4].mean(axis=1)
    spans = [(int(round(a * fs)), int(round(b * fs))) for a, b in EDGE_SPANS]
    return {"fs": fs, "spans_s": EDGE_SPANS,
            "start": [(sq[:, a:b].mean(axis=1) / mid).tolist() for a, b in spans],
            "end": [(sq[:, m - b:m - a].mean(axis=1) / mid).tolist() for a, b in spans]}


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[25.0, 30.0, 50.0, 100.0])
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--seed", type=int, default=49)
    ap.add_argument("--edges", action="store_true", help="the smoothed inputs' error near the ends over mid-window's")
    args = ap.parse_args(argv)
    out = []
    if args.edges:
        for fs in args.rates:
            r = edge_profile(fs, args.n, args.seed)
            out.append(r)
            cells = "; ".join(f"{a:.2f}–{b:.2f} s: start {r['start'][i][0]:.2f} / {r['start'][i][1]:.2f}, end "
                              f"{r['end'][i][0]:.2f} / {r['end'][i][1]:.2f}" for i, (a, b) in enumerate(EDGE_SPANS))
            print(f"{fs:5.0f} frames/s, error² over mid-window's, V / θ: {cells}")
        return out
    for fs in args.rates:
        r = rate_summary(fs, args.n, args.seed)
        out.append(r)
        lo, med, hi = r["cut_v"]
        print(f"{fs:5.0f} frames/s: V cut-off {med:.2f} Hz [{lo:.2f}, {hi:.2f}], θ {r['cut_theta']:.2f} Hz; tail ends "
              f"{r['end_v']:.2f} Hz; windows tailed {r['share_tailed']:.2f}; V error tail / none {r['error_ratio_v']:.3f}")
    return out


if __name__ == "__main__":
    main()
