"""Identification with noisy inputs V and θ (errors in variables): the input smoothers compared.

Windows of the synthetic generator at a disturbance level (P and Q noise at the level's SNR, as Table I),
plus white noise on V (std as a fraction of the window's mean V) and θ [rad] at three PMU classes: none,
0.03 % / 3e-4 rad, 0.1 % / 1e-3 rad.  The same noise draws for every candidate; the candidates run one
after the other on each window (interleaved), 3 random starts each.  Per candidate and parameter: mean of
D_opt/D_real (μ), its std (σ), median and worst |error|, the share of cases inside ±1.96 SE; per noise class
the channels' noise estimates over the injected std.  Time per identification: a separate pass on one
thread over the first ``--time-n`` windows, the candidates interleaved, minimum of 3 repeats per window,
median over windows.

``--supplement``: the Table I supplement (docs/reproduction.md): the default identifier only, DL 1–3,
300 windows per level, the three PMU classes, μ and σ with 95 % bootstrap intervals against issue 11's
targets; confirmation seed 43, fixed before the run (the thresholds were tuned on seed 5, the candidates
compared on seed 41).  ``--rates R ...``: the default at those reporting rates [frames/s], DL 2, the
same per-sample PMU noise, 150 windows per rate (seed 43); with ``--weighting`` the S-weighted option
(``input_weighting="spectral"``, the default) next to ``input_weighting="none"`` on the same windows (JSON
``input_noise_rates_weighting``).

    .venv/bin/python -m benchmarks.input_noise [--quick] [--n N] [--levels 2 3] [--workers 2] [--time-n 30]
    .venv/bin/python -m benchmarks.input_noise --supplement [--n 300]
    .venv/bin/python -m benchmarks.input_noise --rates 25 30 50 60 100 120 [--n 150] [--weighting]
    .venv/bin/python -m benchmarks.input_noise --cost [--n 60]

``--cost``: the default's time per identification against the identifier before issue 11 (no input
smoother, lag-1 SE rule), interleaved per window, minimum of 5 runs, median over DL 1 windows, one thread.
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
from benchmarks.own_gate import WARNING_FLAGS, window_records  # noqa: E402

SEED = 41
#: Confirmation seed of the supplement and the rates, fixed before their runs.
CONFIRM_SEED = 43
#: Confirmation seed of the rates' coverage of ±1.96 SE after the IV's reduced-χ² standard errors (stop 27,
#: 2026-11-25: ``--rates 25 30 50 60 100 120 --n 100 --seed 46``), fixed before any run on it.
COVER_CONFIRM_SEED = 46
#: Confirmation seed of stop 28's tail flags on the rates (2026-11-25: ``--rates 25 30 50 60 100 120 --n 100 --seed
#: 48``), fixed before any run on it (seeds 43 and 46 were the development data; 47 made floor_test's windows).
FLAGS_CONFIRM_SEED = 48
#: Confirmation seed of the rates' coverage on more windows (stop 38, 2026-12-02: ``--rates 25 30 50 60 100 120 --n 300
#: --seed 49``; read with ``benchmarks.input_noise_cover``), fixed before any run on it: a cell of 100 windows decides the
#: 90–97 % target only to about ±4 points.
COVER_POOL_SEED = 49
#: Confirmation seed of the supplement's coverage and σ on a third set (stop 38, 2026-12-02: ``--supplement --n 300
#: --seed 50``), fixed before any run on it.
SUPPLEMENT_POOL_SEED = 50
#: Seed of the supplement's headline run with the default as it stands at stop 48 (2026-12-03: ``--supplement --n 300
#: --seed 56``), fixed before any run on it; no estimator choice is made on it (a measurement of the default, beside
#: seed 43's rerun ``--tag stop48``).
HEADLINE_SEED = 56
#: PMU classes: (name, std of the V noise as a fraction of mean V [-], std of the θ noise [rad]).
INPUT_NOISE = (("none", 0.0, 0.0), ("0.03 % / 3e-4 rad", 3e-4, 3e-4), ("0.1 % / 1e-3 rad", 1e-3, 1e-3))
#: The smoothers as output error's input conditioning (``input_weighting="none"``, the default until issue 11's
#: follow-up made the S-weighted refinement the default; its row is the last).
CANDIDATES = {
    "none": IdentifyConfig(input_smoother="none", **common.OUTPUT_ERROR),
    "causal low-pass 2 Hz": IdentifyConfig(input_smoother="none", lowpass_hz=2.0, **common.OUTPUT_ERROR),
    "zero-phase V/θ 3 Hz": IdentifyConfig(input_smoother="zero_phase", input_cutoff_hz=3.0,
                                          **common.OUTPUT_ERROR),
    "Wiener V/θ": IdentifyConfig(input_smoother="wiener", **common.OUTPUT_ERROR),
    "Wiener V/θ + causal low-pass 2 Hz": IdentifyConfig(input_smoother="wiener", lowpass_hz=2.0,
                                                        **common.OUTPUT_ERROR),
    "Wiener V/θ + adaptive low-pass (default)": IdentifyConfig(**common.OUTPUT_ERROR),
    "default, lag-1 SE rule": IdentifyConfig(stderr_method="ar1", **common.OUTPUT_ERROR),
    "default with the S-weighted refinement": IdentifyConfig(),
}
DEFAULT_ONLY = {"default": IdentifyConfig()}
#: ``--rates --weighting``: the output-error fit alone and the S-weighted refinement (the default; docs/numerics.md).
WITH_WEIGHTING = {"none": IdentifyConfig(**common.OUTPUT_ERROR), "spectral": IdentifyConfig()}
COST = {"before issue 11": IdentifyConfig(input_smoother="none", stderr_method="ar1", **common.OUTPUT_ERROR),
        "default": IdentifyConfig()}
#: Issue 11's targets per PMU class: |μ − 1| bound, and σ bound (absolute, or as a multiple of exact-input σ).
TARGETS = {"0.03 % / 3e-4 rad": (0.01, "1.3x"), "0.1 % / 1e-3 rad": (0.02, 0.05)}
NOISE_KEYS = ("noise_v", "noise_theta", "noise_p", "noise_q")


def with_input_noise(w: Window, clean: Window, v_rel: float, th_rad: float, rng: np.random.Generator) -> Window:
    """The window with white noise added to V (std v_rel·mean V) and θ (std th_rad); P, Q as they are."""
    n = w.V.size
    ev = v_rel * float(np.mean(clean.V)) * rng.standard_normal(n)
    et = th_rad * rng.standard_normal(n)
    return Window(t=w.t, V=w.V + ev, theta=w.theta + et, P=w.P, Q=w.Q, f0=w.f0, bus=w.bus, meta=w.meta)


def noisy_draws(cases: dict, seed: int, n: int, levels=(1, 2, 3)):
    """The supplement's noisy windows in their draw order: (i, level, class, case, window) for the first n windows of
    ``cases`` ({level: cases}) and each noisy PMU class, one generator per level and class seeded [seed, level, k] and
    drawn for every class, the exact one too (as ``input_noise_bound`` draws them)."""
    rngs = {(level, k): np.random.default_rng([seed, level, k]) for level in levels for k in range(len(INPUT_NOISE))}
    for i in range(n):
        for level in levels:
            c = cases[level][i]
            for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
                w = with_input_noise(c.window, c.clean, v_rel, th, rngs[level, k])
                if cls != "none":
                    yield i, level, cls, c, w


def identified_draws(draws, first: int = 0, cells=None, config: IdentifyConfig | None = None):
    """The draws of :func:`noisy_draws` (or any of its shape) from window ``first`` on, in the ``cells`` ('level|class'
    keys; all when None), each with the default's (or ``config``'s) answer: (i, level, class, key, case, window,
    result); windows the identifier refuses are left out."""
    for i, level, cls, c, w in draws:
        key = f"{level}|{cls}"
        if i < first or (cells and key not in cells):
            continue
        try:
            r = identify(w, config=config or IdentifyConfig())
        except WindowError:
            continue
        yield i, level, cls, key, c, w, r


def _one(w: Window, candidates: dict | None = None) -> dict:
    """Every candidate on one window, in turn."""
    out = {}
    for name, cfg in (candidates or CANDIDATES).items():
        try:
            out[name] = identify(w, config=cfg)
        except WindowError as exc:
            out[name] = exc
    return out


def timings(windows, reps: int = 3, candidates: dict | None = None) -> dict[str, float]:
    """Median over windows of the minimum over ``reps`` of one identification [ms], candidates interleaved."""
    candidates = candidates or CANDIDATES
    ts = {k: [] for k in candidates}
    for w in windows:
        for name, cfg in candidates.items():
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


def summarise(cases, windows, results, injected, candidates: dict | None = None) -> dict:
    """Statistics per candidate over the cases (see the module docstring)."""
    out = {}
    for name in candidates or CANDIDATES:
        ratios, cover, est = [], [], []
        failed = off = off_unflagged = swamped = 0
        for c, res, inj in zip(cases, results, injected, strict=True):
            r = res[name]
            if isinstance(r, WindowError):
                failed += 1
                continue
            ratios.append(r.d / c.truth.d)
            swamped += "input_noise_too_large" in r.flags
            if np.max(np.abs(ratios[-1] - 1)) > 0.2:
                off += 1
                off_unflagged += not any(f.startswith(WARNING_FLAGS) for f in r.flags)
            cover.append([abs(r.dynamic[p] - c.truth.dynamic[p]) < 1.96 * r.stderr[p] for p in common.PARAMS])
            est.append([r.quality[k] / inj[k] if inj[k] > 0 else np.nan for k in NOISE_KEYS])
        rr = np.array(ratios)
        st = common.ratio_stats(rr)
        st["median_abs_err"] = dict(zip(common.PARAMS, np.median(np.abs(rr - 1), axis=0).tolist(), strict=True))
        st["coverage_95"] = dict(zip(common.PARAMS, np.mean(cover, axis=0).tolist(), strict=True))
        st["failed"] = failed
        # Of n_off_20pct: without any warning flag (before stop 28 only uncertain/poor_fit/at_bound/restarts counted,
        # so windows flagged input_noise_too_large showed as unflagged).
        st["off_20pct_unflagged"] = off_unflagged
        st["input_noise_too_large"] = swamped
        st["intervals"] = common.bootstrap_mu_sigma(rr)
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


def run_level(n: int, level: int, seed: int, candidates: dict, workers: int, time_n: int,
              fs: float = 100.0) -> dict:
    """Every PMU class on the same n windows of one level (and rate): summaries per class and candidate."""
    cs = common.cases(n, level=level or None, seed=seed, input_noise=False, fs=fs)  # level 0: noise-free P, Q
    out = {}
    for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
        rng = np.random.default_rng([seed, level, k])
        windows = [with_input_noise(c.window, c.clean, v_rel, th, rng) for c in cs]
        injected = [{"noise_v": v_rel * float(np.mean(c.clean.V)), "noise_theta": th,
                     "noise_p": float(np.std(c.window.P - c.clean.P)),
                     "noise_q": float(np.std(c.window.Q - c.clean.Q))} for c in cs]
        with ThreadPoolExecutor(max_workers=workers) as pool:
            results = list(pool.map(lambda w: _one(w, candidates), windows))
        out[cls] = summarise(cs, windows, results, injected, candidates)
        names = list(candidates or CANDIDATES)
        recs = window_records([c.truth.d for c in cs], [{k: (r[k], 0.0) for k in names} for r in results], names)
        for name in names:  # per window, to diagnose flags on (benchmarks.flag_tail)
            out[cls][name]["records"] = {k: v[name] for k, v in recs.items()}
        for name, ms in timings(windows[:time_n], candidates=candidates).items():
            out[cls][name]["median_time_ms"] = ms
    return out


def _interval(st: dict, key: str, p: str) -> str:
    lo, hi = st["intervals"][key][p]
    return f"{st[key][p]:.3f} [{lo:.3f}, {hi:.3f}]"


def supplement_rows(levels_out: dict) -> tuple[list[list], list[list]]:
    """The supplement's table (μ, σ with intervals) and its target check per level and noisy class."""
    table, check = [], []
    for level, per in levels_out.items():
        exact = per["none"]["default"]
        for cls, by in per.items():
            st = by["default"]
            table.append([level, cls, st["n"]] + [_interval(st, "mu", p) for p in common.PARAMS]
                         + [_interval(st, "sigma", p) for p in common.PARAMS]
                         + [" / ".join(f"{100 * st['coverage_95'][p]:.0f}" for p in common.PARAMS),
                            f"{st['n_off_20pct']} ({st['off_20pct_unflagged']})", st["input_noise_too_large"]])
            if cls not in TARGETS:
                continue
            mu_tol, sig = TARGETS[cls]
            cells = []
            for p in common.PARAMS:
                bound = 1.3 * exact["sigma"][p] if sig == "1.3x" else sig
                cells.append(f"{'met' if abs(st['mu'][p] - 1) <= mu_tol else 'NOT'} / "
                             f"{'met' if st['sigma'][p] <= bound else 'NOT'} "
                             f"(σ {st['sigma'][p]:.3f} vs {bound:.3f}, {st['sigma'][p] / exact['sigma'][p]:.1f}× exact)")
            check.append([level, cls] + cells)
    return table, check


SUPP_HEAD = (["DL", "input noise", "n"] + [f"μ {p} [95 % CI]" for p in common.PARAMS]
             + [f"σ {p} [95 % CI]" for p in common.PARAMS]
             + ["±1.96 SE cover a / b / H2 / Tm [%]", "off > 20 % (unflagged)", "input_noise_too_large"])
CHECK_HEAD = ["DL", "input noise"] + [f"{p}: bias / σ" for p in common.PARAMS]
RATE_HEAD = (["frames/s", "input noise", "n"] + [f"μ {p}" for p in common.PARAMS] + [f"σ {p}" for p in common.PARAMS]
             + ["±1.96 SE cover [%]", "off > 20 % (unflagged)", "ms"])


def rate_rows(rates_out: dict) -> list[list]:
    """One row per rate and class (and candidate, after the class, when there are several)."""
    out = []
    for fs, per in rates_out.items():
        for cls, by in per.items():
            for name, st in by.items():
                label = cls if len(by) == 1 else f"{cls}, {name}"
                out.append([fs, label, st["n"]] + [f"{st['mu'][p]:.3f}" for p in common.PARAMS]
                           + [f"{st['sigma'][p]:.3f}" for p in common.PARAMS]
                           + [" / ".join(f"{100 * st['coverage_95'][p]:.0f}" for p in common.PARAMS),
                              f"{st['n_off_20pct']} ({st['off_20pct_unflagged']})", f"{st['median_time_ms']:.1f}"])
    return out


def cost(n: int, no_write: bool) -> dict:
    """``--cost`` (module docstring): exact inputs and 0.1 % / 1e-3 rad, the same windows for both."""
    cs = common.cases(n, level=1, seed=CONFIRM_SEED, input_noise=False)
    _one(cs[0].window, COST)
    out = {"machine": common.machine(), "mode": "cost", "n": n, "seed": CONFIRM_SEED, "classes": {}}
    for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
        rng = np.random.default_rng([CONFIRM_SEED, 1, k])
        windows = [with_input_noise(c.window, c.clean, v_rel, th, rng) for c in cs]
        ms = timings(windows, reps=5, candidates=COST)
        ms["ratio"] = ms["default"] / ms["before issue 11"]
        out["classes"][cls] = ms
        print(f"{cls}: " + ", ".join(f"{k} {v:.2f}" for k, v in ms.items()), flush=True)
    out["load_avg_at_end"] = list(os.getloadavg())
    if not no_write:
        common.write_json("input_noise_cost", out)
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None,
                    help="windows per level (default 200, --supplement 300, --rates 150; --quick: 20)")
    ap.add_argument("--levels", type=int, nargs="+", default=None, help="disturbance levels (0: noise-free P, Q)")
    ap.add_argument("--workers", type=int, default=2, help="threads (the machine is shared)")
    ap.add_argument("--time-n", type=int, default=30, help="windows per class in the one-thread timing pass")
    ap.add_argument("--supplement", action="store_true", help="the Table I supplement (default identifier)")
    ap.add_argument("--rates", type=float, nargs="+", default=None, help="reporting rates [frames/s]")
    ap.add_argument("--cost", action="store_true", help="time per identification: the default against before")
    ap.add_argument("--weighting", action="store_true",
                    help="with --rates: input_weighting='none' next to the default ('spectral')")
    ap.add_argument("--tag", default=None, help="suffix of the JSON name (a rerun beside the run of record)")
    ap.add_argument("--seed", type=int, default=None,
                    help="seed of the cases (default: 41 for the comparison, 43 for --supplement and --rates)")
    args = ap.parse_args(argv)
    if args.cost:
        return cost(args.n or 60, args.no_write)
    mode = "supplement" if args.supplement else ("rates" if args.rates else "compare")
    n = args.n or (20 if args.quick else {"compare": 200, "supplement": 300, "rates": 150}[mode])
    levels = args.levels or {"compare": [2, 3], "supplement": [1, 2, 3], "rates": [2]}[mode]
    seed = args.seed if args.seed is not None else (SEED if mode == "compare" else CONFIRM_SEED)
    candidates = CANDIDATES if mode == "compare" else (WITH_WEIGHTING if args.weighting else DEFAULT_ONLY)
    t_all = time.perf_counter()
    out = {"machine": common.machine(), "mode": mode, "n_per_level": n, "seed": seed, "quick": args.quick,
           "candidates": {k: v.to_dict() for k, v in candidates.items()}, "levels": {}}
    _one(common.cases(1, level=2, seed=SEED)[0].window, candidates)  # numba compilation outside the timings
    text = []
    if mode == "rates":
        out["rates"] = {}
        for fs in args.rates:
            key = f"{fs:g}"
            out["rates"][key] = run_level(n, levels[0], seed, candidates, args.workers, args.time_n, fs=fs)
            print(f"{key} frames/s: done ({time.perf_counter() - t_all:.0f} s)", flush=True)
        text.append(f"**Reporting rates** (DL {levels[0]}, {n} windows per rate, seed {seed}):\n\n"
                    + common.md_table(RATE_HEAD, rate_rows(out["rates"])))
    else:
        for level in levels:
            out["levels"][level] = run_level(n, level, seed, candidates, args.workers, args.time_n)
            print(f"DL {level}: done ({time.perf_counter() - t_all:.0f} s)", flush=True)
            if mode == "compare":
                text.append(f"**DL {level}** ({n} windows, seed {seed}):\n\n"
                            + common.md_table(HEAD, rows(out["levels"][level])))
        if mode == "supplement":
            table, check = supplement_rows(out["levels"])
            text.append(f"**Table I supplement** ({n} windows per level, seed {seed}):\n\n"
                        + common.md_table(SUPP_HEAD, table))
            text.append("**Targets** (met / NOT):\n\n" + common.md_table(CHECK_HEAD, check))
    out["total_s"] = time.perf_counter() - t_all
    out["load_avg_at_end"] = list(os.getloadavg())
    print("\n\n".join(text))
    if not args.no_write:
        name = {"compare": "input_noise", "supplement": "input_noise_supplement", "rates": "input_noise_rates"}[mode]
        if mode == "rates" and levels != [2]:
            name += "_dl" + "-".join(str(x) for x in levels)
        if mode == "rates" and args.weighting:
            name += "_weighting"
        if args.seed is not None and seed != (SEED if mode == "compare" else CONFIRM_SEED):
            name += f"_seed{seed}"
        common.write_json(name + (f"_{args.tag}" if args.tag else "") + ("_quick" if args.quick else ""), out)
    return out


if __name__ == "__main__":
    main()
