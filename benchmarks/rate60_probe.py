"""Where the S-weighted fit's −1 % in a at 60 frames/s comes from (issue 11 follow-up, stop 29).

Three experiments on development seeds, DL 2, 0.1 % / 1e-3 rad on V and θ (the rates bench's class):

``paired``: the same records at several rates.  Cases are made at a base rate (120 or 100 frames/s), the PMU noise
is added there, and the noisy windows are decimated by 1, 2, 4 (120 → 120, 60, 30; 100 → 100, 50, 25): every rate
sees the same ambient record and the same noise values at its samples, so a rate-specific bias shows up in the
paired differences of a, free of the draw-to-draw spread that separate windows per rate carry.

``knobs``: the rates bench's own 60 frames/s windows (:func:`benchmarks.rate_cell.windows_of`) under the weighting
with one of its rate-dependent settings changed: the band (``BAND_FRACTION``), the RK4 sub-step
(``motor.MAX_STEP_S``: 2 sub-steps at 60 frames/s by default), the taper and the periodogram's smoothing width.

``density``: the noise density.  The bench holds the PMU noise's std per sample fixed, so halving the rate doubles
its density per Hz; here the base rate's records carry the same noise draws at 1 and √2 times the std (√2 at
120 frames/s is 60 frames/s's density), without decimation.

    .venv/bin/python -m benchmarks.rate60_probe paired [--seeds 41 43 44 46] [--n 100] [--base 120] [--noise-scale 1]
    .venv/bin/python -m benchmarks.rate60_probe density [--seeds ...] [--base 120]
    .venv/bin/python -m benchmarks.rate60_probe knobs [--seeds 41 43 44 46] [--n 100] [--fs 60] [--variants ...]

Results in ``docs/results/rate60_probe_<mode>[_<base>[_noise<scale>] | _<fs>].json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import math  # noqa: E402
import time  # noqa: E402
from contextlib import contextmanager  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, Window, identify, input_weighting, motor  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE, with_input_noise  # noqa: E402
from benchmarks.rate_cell import windows_of  # noqa: E402

ESTIMATORS = {"none": IdentifyConfig(**common.OUTPUT_ERROR),
              "spectral": IdentifyConfig(input_weighting="spectral", disturbance="none")}
DECIMATIONS = (1, 2, 4)
#: The knobs' variants: (module, attribute, value).
VARIANTS = {
    "default": (),
    "band 0.08": ((input_weighting, "BAND_FRACTION", 0.08), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.12": ((input_weighting, "BAND_FRACTION", 0.12), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.05": ((input_weighting, "BAND_FRACTION", 0.05), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.025": ((input_weighting, "BAND_FRACTION", 0.025), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "RK4 4 sub-steps": ((motor, "MAX_STEP_S", 0.0045),),
    "RK4 1 sub-step": ((motor, "MAX_STEP_S", 0.0170),),
    "no taper": ((input_weighting, "TAPER", 0.0),),
    "residual smoothing 0.5 Hz": ((input_weighting, "RESIDUAL_SMOOTH_HZ", 0.5),),
    "residual smoothing 2 Hz": ((input_weighting, "RESIDUAL_SMOOTH_HZ", 2.0),),
}


@contextmanager
def patched(changes):
    """The module attributes set for the block, restored after."""
    old = [(m, a, getattr(m, a)) for m, a, _ in changes]
    try:
        for m, a, v in changes:
            setattr(m, a, v)
        yield
    finally:
        for m, a, v in old:
            setattr(m, a, v)


def decimated(w: Window, k: int) -> Window:
    """Every k-th sample of the window."""
    return Window(t=w.t[::k], V=w.V[::k], theta=w.theta[::k], P=w.P[::k], Q=w.Q[::k], f0=w.f0, bus=w.bus, meta=w.meta)


def ratios(ws: list, truths: list, cfg: IdentifyConfig) -> np.ndarray:
    """(n, 4) D/D_real."""
    return np.array([identify(w, config=cfg).d / t.d for w, t in zip(ws, truths, strict=True)])


def stats(r: np.ndarray) -> dict:
    return {"n": int(r.shape[0]), "mu_a": float(r[:, 0].mean()), "se_mu_a": float(r[:, 0].std(ddof=1) / np.sqrt(len(r))),
            "mu_b": float(r[:, 1].mean()), "median_a": float(np.median(r[:, 0]))}


def paired(seeds: list[int], n: int, base: float, noise_scale: float = 1.0) -> dict:
    """Per decimation and estimator: ratios on the same records; paired differences against the base rate.
    ``noise_scale``: factor on the PMU noise's std (√2 at 120 frames/s gives the noise density of 60)."""
    per = {str(k): {e: [] for e in ESTIMATORS} for k in DECIMATIONS}
    for seed in seeds:
        cs = common.cases(n, level=2, seed=seed, input_noise=False, fs=base)
        _, v_rel, th = INPUT_NOISE[2]
        rng = np.random.default_rng([seed, 2, 2, int(base)])
        ws = [with_input_noise(c.window, c.clean, noise_scale * v_rel, noise_scale * th, rng) for c in cs]
        truths = [c.truth for c in cs]
        for k in DECIMATIONS:
            wk = [decimated(w, k) for w in ws]
            for e, cfg in ESTIMATORS.items():
                per[str(k)][e].append(ratios(wk, truths, cfg))
    out = {}
    for k in DECIMATIONS:
        key = f"{base / k:g}"
        out[key] = {}
        for e in ESTIMATORS:
            r = np.concatenate(per[str(k)][e])
            r0 = np.concatenate(per["1"][e])
            st = stats(r)
            st["per_seed_mu_a"] = [float(x[:, 0].mean()) for x in per[str(k)][e]]
            d = r[:, 0] - r0[:, 0]
            st["paired_da"] = float(d.mean())
            st["se_paired_da"] = float(d.std(ddof=1) / np.sqrt(d.size))
            out[key][e] = st
    return out


def density(seeds: list[int], n: int, base: float, scales: tuple[float, ...] = (1.0, 2.0 ** 0.5)) -> dict:
    """Per noise scale and estimator at the base rate (no decimation), the same records and noise draws scaled:
    paired differences against the first scale."""
    per = {sc: {e: [] for e in ESTIMATORS} for sc in scales}
    for seed in seeds:
        cs = common.cases(n, level=2, seed=seed, input_noise=False, fs=base)
        _, v_rel, th = INPUT_NOISE[2]
        truths = [c.truth for c in cs]
        for sc in scales:
            rng = np.random.default_rng([seed, 2, 2, int(base)])
            ws = [with_input_noise(c.window, c.clean, sc * v_rel, sc * th, rng) for c in cs]
            for e, cfg in ESTIMATORS.items():
                per[sc][e].append(ratios(ws, truths, cfg))
    out = {}
    for sc in scales:
        out[f"{sc:.4g}"] = {}
        for e in ESTIMATORS:
            r, r0 = np.concatenate(per[sc][e]), np.concatenate(per[scales[0]][e])
            st = stats(r)
            d = r[:, 0] - r0[:, 0]
            st["paired_da"], st["se_paired_da"] = float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))
            out[f"{sc:.4g}"][e] = st
            print(f"noise x{sc:.4g}", e, f"{st['mu_a']:.4f} ± {st['se_mu_a']:.4f}",
                  f"Δ {st['paired_da']:+.4f} ± {st['se_paired_da']:.4f}", flush=True)
    return out


def knobs(seeds: list[int], n: int, fs: float = 60.0, variants: list[str] | None = None) -> dict:
    """Per variant: the weighting's μ(a) on the rates bench's windows at ``fs``, and the paired difference to
    the default."""
    data = []
    for seed in seeds:
        cs, ws = windows_of(seed, fs, n)
        data.append((ws, [c.truth for c in cs]))
    out, base = {}, None
    for name, changes in VARIANTS.items():
        if variants and name != "default" and name not in variants:
            continue
        with patched(changes):
            per = [ratios(ws, tr, ESTIMATORS["spectral"]) for ws, tr in data]
        r = np.concatenate(per)
        if base is None:
            base = r
        st = stats(r)
        st["per_seed_mu_a"] = [float(x[:, 0].mean()) for x in per]
        d = r[:, 0] - base[:, 0]
        st["paired_da"] = float(d.mean())
        st["se_paired_da"] = float(d.std(ddof=1) / np.sqrt(d.size))
        out[name] = st
        print(name, f"{st['mu_a']:.4f} ± {st['se_mu_a']:.4f}", f"Δ {st['paired_da']:+.4f} ± {st['se_paired_da']:.4f}",
              flush=True)
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("mode", choices=["paired", "knobs", "density"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[41, 43, 44, 46])
    ap.add_argument("--n", type=int, default=100, help="windows per seed")
    ap.add_argument("--base", type=float, default=120.0, help="paired: the rate the records are made at")
    ap.add_argument("--noise-scale", type=float, default=1.0, help="paired: factor on the PMU noise's std")
    ap.add_argument("--fs", type=float, default=60.0, help="knobs: the reporting rate [frames/s]")
    ap.add_argument("--variants", nargs="+", default=None, help="knobs: these variants only (and the default)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.mode == "density":
        res = density(args.seeds, args.n, args.base)
    elif args.mode == "paired":
        res = paired(args.seeds, args.n, args.base, args.noise_scale)
    else:
        res = knobs(args.seeds, args.n, args.fs, args.variants)
    out = {"machine": common.machine(), "mode": args.mode, "seeds": args.seeds, "n": args.n, "result": res}
    if args.mode == "paired":
        out["base"], out["noise_scale"] = args.base, args.noise_scale
        rows = [[fs, e, f"{st['mu_a']:.4f} ± {st['se_mu_a']:.4f}", f"{st['mu_b']:.4f}", f"{st['median_a']:.4f}",
                 f"{st['paired_da']:+.4f} ± {st['se_paired_da']:.4f}",
                 " / ".join(f"{x:.3f}" for x in st["per_seed_mu_a"])]
                for fs, per in res.items() for e, st in per.items()]
        print(common.md_table(["fs", "estimator", "μ a ± SE", "μ b", "median a", "Δa vs base (paired)",
                               "μ a per seed"], rows))
    out["total_s"] = time.perf_counter() - t0
    if not args.no_write:
        name = f"rate60_probe_{args.mode}" + (f"_{args.base:g}" + (f"_noise{args.noise_scale:g}" if args.noise_scale != 1.0 else "")
                                               if args.mode in ("paired", "density") else
                                               (f"_{args.fs:g}" if args.fs != 60.0 else ""))
        common.write_json(name, out)
    return out


if __name__ == "__main__":
    main()
