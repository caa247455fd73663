"""Why the S-weighted fit's a is +2 % at 25 frames/s (issue 11, stop 30).

The rates bench's windows (:func:`benchmarks.rate_cell.windows_of`: DL 2, 0.1 % / 1e-3 rad on V and θ, development
seeds) at one rate, the S-weighted fit (``input_weighting="spectral"``, the default) with one setting changed per variant,
every variant on the same windows: μ, σ and coverage of ±1.96 SE of a / b / H2 / Tm, and the paired difference of
each parameter to the default.  ``--noise-scale`` multiplies the PMU noise's std (0.5 at 25 frames/s is
100 frames/s's density per Hz); ``--exact`` takes the windows without PMU noise (output error alone answers).

    .venv/bin/python -m benchmarks.rate25_probe [--fs 25] [--seeds 41 ... 47] [--n 100] [--variants ...]
                                                [--noise-scale 1] [--exact] [--force]
                                                [--config spectral|default] [--tag NAME]
    .venv/bin/python -m benchmarks.rate25_probe --mode calibration|gn [--fs 25] [--seeds ...] [--n 100]

``--config spectral`` (the default here) is ``rate_cell``'s "spectral", the S-weighted fit alone
(``disturbance="none"``); ``default`` is the library's default, the gated composite in front of it.  ``--force`` runs
the weighted refinement on exact inputs too (with ``--exact``: the band's own model error).  The oracle variants give
the refinement the exact V and θ (all, one channel, the first and last second, or all but those) with the weighting
formed from the noisy window as usual.  ``--mode calibration``: per band, how far the Wiener-smoothed inputs are
from the conditional mean (:func:`calibration`); ``--mode gn``: the fit's bias to first order (:func:`gauss_newton`).

Results in ``docs/results/rate25_probe_<fs>[_<tag>].json`` and ``rate25_probe_<mode>_<fs>.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import math  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, identify, input_weighting, motor  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE, with_input_noise  # noqa: E402
from benchmarks.rate60_probe import patched  # noqa: E402

#: The exact window of each noisy one (by identity), for the oracle variants.
EXACT: dict[int, object] = {}
_prepare = input_weighting.prepare


def oracle_prepare(window, **kwargs):
    """The weighted refinement's data with the true (exact) V and θ in place of the Wiener-smoothed ones, its
    weighting (the smoother's error spectrum, the floors) unchanged: what the fit gives without the inputs' error."""
    prep = _prepare(window, **kwargs)
    exact = EXACT.get(id(window))
    if exact is None or exact.V.size != prep.V.size:
        return prep
    return replace(prep, V=np.asarray(exact.V, dtype=np.float64).copy(), theta=np.asarray(exact.theta, dtype=np.float64).copy())


#: ``rate_cell``'s "spectral" (the S-weighted fit alone, as the rates bench's figures) and the library default (the
#: gated composite in front of it).
CONFIGS = {"spectral": IdentifyConfig(input_weighting="spectral", disturbance="none"), "default": IdentifyConfig()}
#: The truth of the window being identified, for the "weights at the true D" variant.
CURRENT: dict[str, np.ndarray] = {}
_build_weighting = input_weighting.build_weighting


def weighting_at_truth(problem, d, *args, **kwargs):
    """The whitening formed at the true D (H, the static slope, the residual floor) instead of the output-error D."""
    return _build_weighting(problem, CURRENT.get("d", d), *args, **kwargs)


def oracle_channel(channel: str):
    """:func:`oracle_prepare` on one input (``"V"`` or ``"theta"``), the other smoothed."""

    def prep_(window, **kwargs):
        prep = _prepare(window, **kwargs)
        exact = EXACT.get(id(window))
        if exact is None or exact.V.size != prep.V.size:
            return prep
        return replace(prep, **{channel: np.asarray(getattr(exact, channel), dtype=np.float64).copy()})

    return prep_


def oracle_part(edges_s: float, at_edges: bool):
    """:func:`oracle_prepare` on the first and last ``edges_s`` seconds only (``at_edges``) or everywhere else."""

    def prep_(window, **kwargs):
        prep = _prepare(window, **kwargs)
        exact = EXACT.get(id(window))
        if exact is None or exact.V.size != prep.V.size:
            return prep
        k = int(round(edges_s / prep.dt))
        mask = np.zeros(prep.V.size, dtype=bool)
        mask[:k], mask[prep.V.size - k:] = True, True
        if not at_edges:
            mask = ~mask
        v, th = prep.V.copy(), prep.theta.copy()
        v[mask], th[mask] = np.asarray(exact.V)[mask], np.asarray(exact.theta)[mask]
        return replace(prep, V=v, theta=th)

    return prep_


_refine = input_weighting.refine


def _refined_with_weighting(prep, f0, config, d0, skip_s, margin):
    """The unchanged refinement's answer and the weighting at ``d0`` it descends with ((answer, None) where either is
    missing)."""
    out = _refine(prep, f0, config, d0, skip_s, margin)
    if out is None:
        return out, None
    iw, pb = input_weighting, out["problem"]
    white = (prep.noise["noise_p"] ** 2, prep.noise["noise_q"] ** 2)
    return out, iw.build_weighting(pb, np.asarray(d0, dtype=np.float64), prep.input_error, white,
                                   iw.fitted_band_hz(pb.dt))


def jackknife(groups: int):
    """The refinement with a delete-a-group jackknife over its frequency bins (every ``groups``-th kept bin a group):
    D = G·D̂ − (G − 1)·mean(D̂₋g), each D̂₋g descended from D̂ with the same weighting and one group's bins at zero
    weight.  Removes a bias of order 1/(bins) (a finite-sample bias); kept where the result stays feasible."""

    def refine_(prep, f0, config, d0, skip_s, margin):
        out, wt = _refined_with_weighting(prep, f0, config, d0, skip_s, margin)
        if wt is None:
            return out
        iw = input_weighting
        pb, d = out["problem"], out["d"]
        kept = np.flatnonzero(np.abs(wt.w[0]) > 0)
        mult, phi = iw.bin_weights(pb.l), pb.basis
        zero = np.zeros_like(phi)
        reps = []
        for g in range(groups):
            mask = np.ones(wt.w[0].size)
            mask[kept[g::groups]] = 0.0
            w = tuple(x * mask for x in wt.w)
            nuis = iw._stack(w, np.hstack([phi, zero]), np.hstack([zero, phi]), mult)
            r = iw._descend(pb, d, iw.Weighting(w, nuis, np.linalg.inv(nuis.T @ nuis), wt.samples), margin)
            if not np.isfinite(r["cost"]):
                return out
            reps.append(r["d"])
        dj = groups * d - (groups - 1) * np.mean(reps, axis=0)
        if np.all(dj >= pb.lower) and np.all(dj <= pb.upper) and pb.feasible(dj):
            out = {**out, "d": dj}
        return out

    return refine_


def linear_jackknife(groups: int):
    """:func:`jackknife` with each D̂₋g one Gauss–Newton step from D̂ on the whitened residual and Jacobian at D̂, the
    group's rows left out and the static part projected off the rest: no simulation beyond the one at D̂."""

    def refine_(prep, f0, config, d0, skip_s, margin):
        out, wt = _refined_with_weighting(prep, f0, config, d0, skip_s, margin)
        iw = input_weighting
        if wt is None or not iw._simulate(out["problem"], out["d"]):
            return out
        pb, d = out["problem"], out["d"]
        k0 = pb.k0
        z = iw._stack(wt.w, np.column_stack([pb.p_meas - pb._p[k0:], pb._dp[k0:]]),
                      np.column_stack([pb.q_meas - pb._q[k0:], pb._dq[k0:]]), iw.bin_weights(pb.l))
        m = wt.w[0].size
        kept = np.flatnonzero(np.abs(wt.w[0]) > 0)
        reps = []
        for g in range(groups):
            rows = np.ones(4 * m, dtype=bool)
            for o in range(4):
                rows[o * m + kept[g::groups]] = False
            zr, nr = z[rows], wt.nuisance[rows]
            zr = zr - nr @ np.linalg.lstsq(nr, zr, rcond=None)[0]
            e, jac = zr[:, 0], zr[:, 1:]
            reps.append(d + np.linalg.solve(jac.T @ jac, jac.T @ e))
        dj = groups * d - (groups - 1) * np.mean(reps, axis=0)
        if np.all(dj >= pb.lower) and np.all(dj <= pb.upper) and pb.feasible(dj):
            out = {**out, "d": dj}
        return out

    return refine_


#: Variants: (module, attribute, value) changes; band fractions at 25 frames/s: 0.12 = 3 Hz, 0.2 = 5 Hz, 0.24 = 6 Hz
#: (without stop 49's 4 Hz cap, so that the fraction holds).
VARIANTS = {
    "default": (),
    "band 0.12": ((input_weighting, "BAND_FRACTION", 0.12), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.16": ((input_weighting, "BAND_FRACTION", 0.16), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.2": ((input_weighting, "BAND_FRACTION", 0.2), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.24": ((input_weighting, "BAND_FRACTION", 0.24), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.3": ((input_weighting, "BAND_FRACTION", 0.3), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.08": ((input_weighting, "BAND_FRACTION", 0.08), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "RK4 8 sub-steps": ((motor, "MAX_STEP_S", 0.0051),),
    "no taper": ((input_weighting, "TAPER", 0.0),),
    "taper 0.2": ((input_weighting, "TAPER", 0.2),),
    "residual smoothing 0.5 Hz": ((input_weighting, "RESIDUAL_SMOOTH_HZ", 0.5),),
    "no residual floor": ((input_weighting, "RESIDUAL_SMOOTH_HZ", 0.0),),
    "band 0.4": ((input_weighting, "BAND_FRACTION", 0.4), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "band 0.05": ((input_weighting, "BAND_FRACTION", 0.05), (input_weighting, "MAX_BAND_HZ", math.inf)),
    "oracle inputs": ((input_weighting, "prepare", oracle_prepare),),
    "oracle inputs, band 0.2": ((input_weighting, "prepare", oracle_prepare), (input_weighting, "BAND_FRACTION", 0.2),
                                (input_weighting, "MAX_BAND_HZ", math.inf)),
    "oracle edges 1 s": ((input_weighting, "prepare", oracle_part(1.0, True)),),
    "weights at the true D": ((input_weighting, "build_weighting", weighting_at_truth),),
    "2 rounds": ((input_weighting, "ROUNDS", 2),),
    "3 rounds": ((input_weighting, "ROUNDS", 3),),
    "jackknife 5": ((input_weighting, "refine", jackknife(5)),),
    "jackknife 10": ((input_weighting, "refine", jackknife(10)),),
    "linear jackknife 10": ((input_weighting, "refine", linear_jackknife(10)),),
    "linear jackknife 25": ((input_weighting, "refine", linear_jackknife(25)),),
    "oracle V": ((input_weighting, "prepare", oracle_channel("V")),),
    "oracle theta": ((input_weighting, "prepare", oracle_channel("theta")),),
    "oracle middle": ((input_weighting, "prepare", oracle_part(1.0, False)),),
    "oracle inputs, band 0.05": ((input_weighting, "prepare", oracle_prepare),
                                 (input_weighting, "BAND_FRACTION", 0.05), (input_weighting, "MAX_BAND_HZ", math.inf)),
}


def windows(seed: int, fs: float, n: int, scale: float, exact: bool) -> tuple[list, list]:
    """The rates bench's windows of ``seed`` at ``fs`` (its draws), the PMU noise's std times ``scale``."""
    cs = common.cases(n, level=2, seed=seed, input_noise=False, fs=fs)
    if exact:
        return [c.window for c in cs], [c.truth for c in cs]
    _, v_rel, th = INPUT_NOISE[2]
    rng = np.random.default_rng([seed, 2, 2])
    ws = [with_input_noise(c.window, c.clean, scale * v_rel, scale * th, rng) for c in cs]
    EXACT.update({id(w): c.window for w, c in zip(ws, cs, strict=True)})
    return ws, [c.truth for c in cs]


def run(data: list, cfg: IdentifyConfig) -> tuple[np.ndarray, np.ndarray]:
    """(n, 4) D/D_real and SE/D_real."""
    r, s = [], []
    for ws, truths in data:
        for w, t in zip(ws, truths, strict=True):
            CURRENT["d"] = np.asarray(t.d, dtype=np.float64)
            res = identify(w, config=cfg)
            r.append(res.d / t.d)
            s.append(np.array([res.stderr[p] for p in common.PARAMS]) / t.d)
    return np.array(r), np.array(s)


def stats(r: np.ndarray, s: np.ndarray, base: np.ndarray) -> dict:
    n = r.shape[0]
    d = r - base
    return {"n": n, "mu": r.mean(0).tolist(), "se_mu": (r.std(0, ddof=1) / np.sqrt(n)).tolist(),
            "sigma": r.std(0, ddof=1).tolist(), "cover": (np.abs(r - 1.0) <= 1.96 * s).mean(0).tolist(),
            "paired": d.mean(0).tolist(), "se_paired": (d.std(0, ddof=1) / np.sqrt(n)).tolist()}


#: Frequency bands of the calibration check [Hz].
CAL_EDGES = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0)


def calibration(seeds: list[int], fs: float, n: int) -> dict:
    """Per band, the regression-calibration matrix B = E[x·x̂ᴴ]·E[x̂·x̂ᴴ]⁻¹ of the Wiener-smoothed inputs x̂ against the
    exact ones x (V over its mean, θ; Hann-tapered DFT of the window, pooled over windows): I where x̂ is the
    conditional mean, a diagonal below 1 where x̂ carries noise the fit then attenuates."""
    k = len(CAL_EDGES) - 1
    sxh, shh = np.zeros((k, 2, 2), complex), np.zeros((k, 2, 2), complex)
    for seed in seeds:
        ws, _ = windows(seed, fs, n, 1.0, False)
        for w in ws:
            exact, prep = EXACT[id(w)], prepare(w, floors=True, input_smoother="wiener")
            f, tap, vm = np.fft.rfftfreq(w.V.size, 1.0 / fs), np.hanning(w.V.size), float(np.mean(exact.V))
            x = np.stack([np.asarray(exact.V) / vm, np.asarray(exact.theta)])
            xh = np.stack([prep.V / vm, prep.theta])
            fx = np.fft.rfft((x - x.mean(1, keepdims=True)) * tap, axis=1)
            fh = np.fft.rfft((xh - xh.mean(1, keepdims=True)) * tap, axis=1)
            for i in range(k):
                m = (f >= CAL_EDGES[i]) & (f < CAL_EDGES[i + 1])
                sxh[i] += fx[:, m] @ fh[:, m].conj().T
                shh[i] += fh[:, m] @ fh[:, m].conj().T
    out = {}
    for i in range(k):
        b = sxh[i] @ np.linalg.inv(shh[i])
        out[f"{CAL_EDGES[i]:g}-{CAL_EDGES[i + 1]:g} Hz"] = {"re": b.real.round(4).tolist(), "im": b.imag.round(4).tolist()}
        print(f"{fs:g} frames/s {CAL_EDGES[i]:g}-{CAL_EDGES[i + 1]:g} Hz  B_VV {b[0, 0].real:.3f}  B_θθ {b[1, 1].real:.3f}  "
              f"|B_Vθ| {abs(b[0, 1]):.3f}  |B_θV| {abs(b[1, 0]):.3f}", flush=True)
    return out


def gauss_newton(seeds: list[int], fs: float, n: int) -> dict:
    """One Gauss–Newton step of the S-weighted fit from the true D (its mean over windows is the fit's bias to
    first order in the step): δ = M⁻¹·g, M = J̃ᵀJ̃ and g = J̃ᵀẽ on the smoothed inputs, the weighting at the true D,
    skip 1 s; the same with the exact inputs (the oracle, its weighting formed on them); and the smoothed inputs' g
    with the exact inputs' M."""
    cfg, steps = IdentifyConfig(), {"smoothed": [], "exact inputs": [], "smoothed g, exact-input M": []}
    for seed in seeds:
        ws, truths = windows(seed, fs, n, 1.0, False)
        for w, t in zip(ws, truths, strict=True):
            prep, d = prepare(w, floors=True, input_smoother="wiener"), np.asarray(t.d, dtype=np.float64)
            exact = EXACT[id(w)]
            px = replace(prep, V=np.asarray(exact.V, dtype=np.float64).copy(),
                         theta=np.asarray(exact.theta, dtype=np.float64).copy())
            pb, pbx = (Problem(p_, w.f0, replace(cfg, skip_s=1.0)) for p_ in (prep, px))
            white = (prep.noise["noise_p"] ** 2, prep.noise["noise_q"] ** 2)
            band = input_weighting.fitted_band_hz(pb.dt)
            wt = input_weighting.build_weighting(pb, d, prep.input_error, white, band)
            # The exact inputs' own weighting: its static regressors (and projection) are the exact V's.
            wtx = input_weighting.build_weighting(pbx, d, prep.input_error, white, band)
            e, j = input_weighting.whitened_residuals(pb, d, wt)
            ex, jx = input_weighting.whitened_residuals(pbx, d, wtx)
            steps["smoothed"].append(np.linalg.solve(j.T @ j, j.T @ e) / d)
            steps["exact inputs"].append(np.linalg.solve(jx.T @ jx, jx.T @ ex) / d)
            steps["smoothed g, exact-input M"].append(np.linalg.solve(jx.T @ jx, j.T @ e) / d)
    out = {}
    for name, v in steps.items():
        v = np.array(v)
        out[name] = {"mean": v.mean(0).tolist(), "se": (v.std(0, ddof=1) / np.sqrt(len(v))).tolist(),
                     "median": np.median(v, 0).tolist(), "sd": v.std(0, ddof=1).tolist()}
        print(f"{fs:g} frames/s {name:28s} mean δ/D", " / ".join(f"{m:+.4f}±{e_:.4f}" for m, e_ in
                                                                 zip(out[name]["mean"], out[name]["se"], strict=True)),
              "| median", " / ".join(f"{m:+.4f}" for m in out[name]["median"]), flush=True)
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--fs", type=float, default=25.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[41, 42, 43, 44, 45, 46, 47])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--variants", nargs="+", default=None, help="these variants only (and the default)")
    ap.add_argument("--noise-scale", type=float, default=1.0)
    ap.add_argument("--exact", action="store_true", help="no PMU noise on V and θ")
    ap.add_argument("--config", choices=list(CONFIGS), default="spectral")
    ap.add_argument("--force", action="store_true",
                    help="run the weighted refinement on every window (exact inputs too: the band's model error alone)")
    ap.add_argument("--mode", choices=["variants", "calibration", "gn"], default="variants",
                    help="calibration: the smoothed inputs' B per band; gn: the Gauss–Newton step from the truth")
    ap.add_argument("--tag", default="")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.mode != "variants":
        res = (calibration if args.mode == "calibration" else gauss_newton)(args.seeds, args.fs, args.n)
        res = {"machine": common.machine(), "mode": args.mode, "fs": args.fs, "seeds": args.seeds, "n": args.n,
               "result": res, "total_s": time.perf_counter() - t0}
        if not args.no_write:
            common.write_json(f"rate25_probe_{args.mode}_{args.fs:g}", res)
        return res
    data = [windows(s, args.fs, args.n, args.noise_scale, args.exact) for s in args.seeds]
    out, base = {}, None
    for name, changes in VARIANTS.items():
        if args.variants and name != "default" and name not in args.variants:
            continue
        if args.force:
            changes = (*changes, (input_weighting, "noisy_inputs", lambda floors: True))
        with patched(changes):
            r, s = run(data, CONFIGS[args.config])
        if base is None:
            base = r
        out[name] = st = stats(r, s, base)
        print(f"{name:28s}", "μ", " / ".join(f"{x:.4f}" for x in st["mu"]),
              "| σ", " / ".join(f"{x:.3f}" for x in st["sigma"]),
              "| cover", " / ".join(f"{100 * x:.0f}" for x in st["cover"]),
              "| Δ", " / ".join(f"{x:+.4f}±{e:.4f}" for x, e in zip(st["paired"], st["se_paired"], strict=True)),
              flush=True)
    res = {"machine": common.machine(), "fs": args.fs, "seeds": args.seeds, "n": args.n,
           "noise_scale": args.noise_scale, "exact": args.exact,
           "config": args.config, "force": args.force, "result": out, "total_s": time.perf_counter() - t0}
    if not args.no_write:
        common.write_json(f"rate25_probe_{args.fs:g}" + (f"_{args.tag}" if args.tag else ""), res)
    return res


if __name__ == "__main__":
    main()
