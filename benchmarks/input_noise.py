"""Identification with noisy inputs V and θ (errors in variables): the input smoothers compared.

Windows of the synthetic generator at a disturbance level (P and Q noise at the level's SNR, as Table I),
plus white noise on V (std as a fraction of the window's mean V) and θ [rad] at three PMU classes: none,
0.03 % / 3e-4 rad, 0.1 % / 1e-3 rad.  The same noise draws for every candidate; the candidates run one
after the other on each window (interleaved), 3 random starts each.  Per candidate and parameter: mean of
D_opt/D_real (μ), its std (σ), median and worst |error|, the share of cases inside ±1.96 SE; per noise class
the channels' noise estimates over the injected std.  Time per identification: a separate pass on one
thread over the first ``--time-n`` windows, the candidates interleaved, minimum of 3 repeats per window,
median over windows.

    .venv/bin/python -m benchmarks.input_noise [--quick] [--n N] [--levels 2 3] [--workers 2] [--time-n 30]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402
from concurrent.futures import ThreadPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, Window, WindowError, identify  # noqa: E402
from benchmarks import common  # noqa: E402

SEED = 41
#: PMU classes: (name, std of the V noise as a fraction of mean V [-], std of the θ noise [rad]).
INPUT_NOISE = (("none", 0.0, 0.0), ("0.03 % / 3e-4 rad", 3e-4, 3e-4), ("0.1 % / 1e-3 rad", 1e-3, 1e-3))
CANDIDATES = {
    "none": IdentifyConfig(input_smoother="none"),
    "causal low-pass 2 Hz": IdentifyConfig(input_smoother="none", lowpass_hz=2.0),
    "zero-phase V/θ 3 Hz": IdentifyConfig(input_smoother="zero_phase", input_cutoff_hz=3.0),
    "Wiener V/θ": IdentifyConfig(input_smoother="wiener"),
    "Wiener V/θ + causal low-pass 2 Hz": IdentifyConfig(input_smoother="wiener", lowpass_hz=2.0),
    "Wiener V/θ + adaptive low-pass (default)": IdentifyConfig(),
}
NOISE_KEYS = ("noise_v", "noise_theta", "noise_p", "noise_q")


def with_input_noise(w: Window, clean: Window, v_rel: float, th_rad: float, rng: np.random.Generator) -> Window:
    """The window with white noise added to V (std v_rel·mean V) and θ (std th_rad); P, Q as they are."""
    n = w.V.size
    ev = v_rel * float(np.mean(clean.V)) * rng.standard_normal(n)
    et = th_rad * rng.standard_normal(n)
    return Window(t=w.t, V=w.V + ev, theta=w.theta + et, P=w.P, Q=w.Q, f0=w.f0, bus=w.bus, meta=w.meta)


def _one(w: Window) -> dict:
    """Every candidate on one window, in turn."""
    out = {}
    for name, cfg in CANDIDATES.items():
        try:
            out[name] = identify(w, config=cfg)
        except WindowError as exc:
            out[name] = exc
    return out


def timings(windows, reps: int = 3) -> dict[str, float]:
    """Median over windows of the minimum over ``reps`` of one identification [ms], candidates interleaved."""
    ts = {k: [] for k in CANDIDATES}
    for w in windows:
        for name, cfg in CANDIDATES.items():
            best = np.inf
            for _ in range(reps):
                t0 = time.perf_counter()
                try:
                    identify(w, config=cfg)
                except WindowError:
                    pass
                best = min(best, time.perf_counter() - t0)
            ts[name].append(best)
    return {k: float(np.median(v) * 1e3) for k, v in ts.items()}


def summarise(cases, windows, results, injected) -> dict:
    """Statistics per candidate over the cases (see the module docstring)."""
    out = {}
    for name in CANDIDATES:
        ratios, cover, est = [], [], []
        failed = off = off_unflagged = 0
        for c, res, inj in zip(cases, results, injected, strict=True):
            r = res[name]
            if isinstance(r, WindowError):
                failed += 1
                continue
            ratios.append(r.d / c.truth.d)
            if np.max(np.abs(ratios[-1] - 1)) > 0.2:
                off += 1
                off_unflagged += not any(f.startswith(("uncertain", "poor_fit", "at_bound", "restarts")) for f in r.flags)
            cover.append([abs(r.dynamic[p] - c.truth.dynamic[p]) < 1.96 * r.stderr[p] for p in common.PARAMS])
            est.append([r.quality[k] / inj[k] if inj[k] > 0 else np.nan for k in NOISE_KEYS])
        rr = np.array(ratios)
        st = common.ratio_stats(rr)
        st["median_abs_err"] = dict(zip(common.PARAMS, np.median(np.abs(rr - 1), axis=0).tolist(), strict=True))
        st["coverage_95"] = dict(zip(common.PARAMS, np.mean(cover, axis=0).tolist(), strict=True))
        st["failed"] = failed
        st["off_20pct_unflagged"] = off_unflagged  # of n_off_20pct: without uncertain/poor_fit/at_bound/restarts
        e = np.array(est)
        st["noise_estimate_over_injected"] = {
            k: ({"median": float(np.nanmedian(e[:, i])), "min": float(np.nanmin(e[:, i])),
                 "max": float(np.nanmax(e[:, i]))} if np.isfinite(e[:, i]).any() else None)
            for i, k in enumerate(NOISE_KEYS)}
        out[name] = st
    return out


HEAD = ["input noise", "candidate", "μ a / b / H2 / Tm", "σ a / b / H2 / Tm", "median |err| a / b / H2 / Tm [%]",
        "worst [%]", "off > 20 % (unflagged)", "±1.96 SE cover [%]", "ms"]


def rows(level_out: dict) -> list[list]:
    out = []
    for cls, per in level_out.items():
        for name, st in per.items():
            p = common.PARAMS
            out.append([cls, name, " / ".join(f"{st['mu'][k]:.3f}" for k in p),
                        " / ".join(f"{st['sigma'][k]:.3f}" for k in p),
                        " / ".join(f"{100 * st['median_abs_err'][k]:.1f}" for k in p),
                        f"{100 * max(st['max_abs_err'].values()):.0f}",
                        f"{st['n_off_20pct']} ({st['off_20pct_unflagged']})",
                        " / ".join(f"{100 * st['coverage_95'][k]:.0f}" for k in p),
                        f"{st['median_time_ms']:.1f}"])
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows per level (default 200; --quick: 20)")
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3], help="disturbance levels")
    ap.add_argument("--workers", type=int, default=2, help="threads (the machine is shared)")
    ap.add_argument("--time-n", type=int, default=30, help="windows per class in the one-thread timing pass")
    args = ap.parse_args(argv)
    n = args.n or (20 if args.quick else 200)
    t_all = time.perf_counter()
    out = {"machine": common.machine(), "n_per_level": n, "seed": SEED, "quick": args.quick,
           "candidates": {k: v.to_dict() for k, v in CANDIDATES.items()}, "levels": {}}
    _one(common.cases(1, level=2, seed=SEED)[0].window)  # numba compilation / cache load outside the timings
    text = []
    for level in args.levels:
        cs = common.cases(n, level=level, seed=SEED, input_noise=False)
        out["levels"][level] = {}
        for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
            rng = np.random.default_rng([SEED, level, k])
            windows = [with_input_noise(c.window, c.clean, v_rel, th, rng) for c in cs]
            injected = [{"noise_v": v_rel * float(np.mean(c.clean.V)), "noise_theta": th,
                         "noise_p": float(np.std(c.window.P - c.clean.P)),
                         "noise_q": float(np.std(c.window.Q - c.clean.Q))} for c in cs]
            with ThreadPoolExecutor(max_workers=args.workers) as pool:
                results = list(pool.map(_one, windows))
            out["levels"][level][cls] = summarise(cs, windows, results, injected)
            for name, ms in timings(windows[: args.time_n]).items():
                out["levels"][level][cls][name]["median_time_ms"] = ms
            print(f"DL {level}, {cls}: done ({time.perf_counter() - t_all:.0f} s)", flush=True)
        text.append(f"**DL {level}** ({n} windows, seed {SEED}):\n\n"
                    + common.md_table(HEAD, rows(out["levels"][level])))
    out["total_s"] = time.perf_counter() - t_all
    print("\n\n".join(text))
    if not args.no_write:
        common.write_json("input_noise" + ("_quick" if args.quick else ""), out)
    return out


if __name__ == "__main__":
    main()
