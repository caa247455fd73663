"""Identification when the load's own fluctuation drives P and Q too (closed loop): estimators compared.

Windows of the synthetic generator (P and Q noise at DL 2, i.e. ~25 dB) with the load's own constant-power part
fluctuating (:mod:`aslm_sim.own`) so that std(own ΔP) / std(clean P) hits a target ratio per window (0, 0.5,
0.9): each case is first simulated without it, its std of P sets the case's own σ, and the case is simulated
again with it (same load, network, grid-side forcing and noise streams).  At the lowpass shape, white noise on V
and θ at the two PMU classes is added as in ``benchmarks.input_noise``.  Every candidate runs on the same
windows, one after the other (interleaved), 3 random starts each.  Per candidate: median and worst |error|,
bias μ − 1 and σ of D_opt/D_real, coverage of ±1.96 SE, windows off by more than 20 % and how many of them
carry no flag, median time per identification (wall clock inside the pool, so with ``--workers 2`` on a shared
machine it is an upper bound).

    .venv/bin/python -m benchmarks.own_fluctuation [--quick] [--n 50] [--workers 2] [--seed 43]
        [--candidates ...] [--tag NAME] [--gate]

Seed 43 (:data:`SEED`) is the development set; :data:`CONFIRM_SEEDS` were fixed before any run on them (issue
20's gate work, 2026-11-24).  Every run keeps per-window records (errors, standard errors, flags, quality:
:mod:`benchmarks.own_gate`), so ``--gate`` prints the gated composite from the JSON without identifying.
Results go to ``docs/results/own_fluctuation[_TAG][_seedS].json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import math  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ThreadPoolExecutor  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, identify  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE, with_input_noise  # noqa: E402
from benchmarks.own_gate import GATE_HEAD, WARNING_FLAGS, gated_row, print_confirm, window_records  # noqa: E402

SEED = 43
#: Seeds of the confirmation runs, fixed before any run on them (243: the gated estimator's flag
#: ``iv_error_may_exceed_20pct``, 2026-11-24, with ``--candidates "output error" gated``; 245: the IV's standard
#: errors scaled by its reduced χ², 2026-11-25, ``--n 100 --candidates "gated, spectral weighting" --tag cover``;
#: 246: stop 28's tail flags, 2026-11-25, the same command with ``--tag flags``; 247: the coupled channels
#: (``couple_channels``), 2026-12-02, ``--candidates "gated, spectral weighting" "gated, spectral weighting, coupled
#: channels" --noise-shapes lowpass switching --tag coupled`` at ``--coherence`` 1, 0.9 and 0.7).
CONFIRM_SEEDS = (143, 243, 245, 246, 247)
LEVEL = 2
#: Target std(own ΔP) / std(clean P) of the windows.
RATIOS = (0.0, 0.5, 0.9)
#: Each with the options it was measured with, not the defaults (which became the S-weighted, gated estimator).
CANDIDATES = {
    "output error": IdentifyConfig(**common.OUTPUT_ERROR),
    "low-pass 2 Hz": IdentifyConfig(lowpass_hz=2.0, **common.OUTPUT_ERROR),
    "Wiener V/θ + adaptive low-pass": IdentifyConfig(input_smoother="wiener_lowpass", **common.OUTPUT_ERROR),
    "AR disturbance (PEM)": IdentifyConfig(disturbance="ar", input_weighting="none"),
    "Wiener V/θ + AR disturbance": IdentifyConfig(input_smoother="wiener", disturbance="ar",
                                                  input_weighting="none"),
    "AR disturbance (IV)": IdentifyConfig(disturbance="ar_iv", input_weighting="none"),
    "Wiener V/θ + AR disturbance (IV)": IdentifyConfig(input_smoother="wiener", disturbance="ar_iv",
                                                       input_weighting="none"),
    "AR disturbance (IV), white SEs": IdentifyConfig(disturbance="ar_iv", stderr_method="ar1", input_weighting="none"),
    "gated": IdentifyConfig(disturbance="gated", input_weighting="none"),
    # The default of stops 26–33 (the channels as measured); the default since stop 34 is the coupled one below.
    "gated, spectral weighting": IdentifyConfig(disturbance="gated", input_weighting="spectral"),
    "gated, spectral weighting, coupled channels": IdentifyConfig(disturbance="gated", input_weighting="spectral",
                                                                  couple_channels=True),
}
# Every candidate but the last was measured with the channels as measured (couple_channels did not exist before
# stop 34): pinned, so that its name keeps meaning what its rows in docs/ measured.
CANDIDATES = {k: v if k.endswith("coupled channels") else replace(v, couple_channels=False) for k, v in CANDIDATES.items()}
#: The default with the IV's options of stop 37 (LIML, the own fluctuation's AR models alone).
CANDIDATES["default, LIML, own whitening"] = IdentifyConfig(iv_estimator="liml", iv_whitening="own")


def own_cases(n: int, ratio: float, shape: str, base: list, seed: int = SEED, coherence: float = 1.0) -> list:
    """The n cases of ``base`` (made with ``seed``) again, with an own fluctuation at std ratio ``ratio`` to the
    clean P (its ΔQ correlated with its ΔP by ``coherence``: :func:`aslm_sim.cases.make_cases`)."""
    if ratio <= 0.0:
        return base
    # own std = k·p_v with k = r/√(1 − r²) gives own/total = r when the two are uncorrelated.
    k = ratio / math.sqrt(1.0 - ratio * ratio)
    sig = [k * float(np.std(c.clean.P)) / c.truth.power(1.0)[0] for c in base]
    return make_cases(n, level=LEVEL, seed=seed, input_noise=False, own_sigma=sig, own_shape=shape,
                      own_q_coherence=coherence)


def bench_window(i: int, ratio: float, shape: str, noise: int, seed: int = SEED):
    """Window ``i`` of a row of the bench (own ratio, shape, index into ``INPUT_NOISE``) and its case.

    The bench draws the V/θ noise of a row's windows in order from one generator, so the windows before ``i`` are
    made too (the cases themselves do not depend on how many are made).
    """
    base = make_cases(i + 1, level=LEVEL, seed=seed, input_noise=False)
    cs = own_cases(i + 1, ratio, shape, base, seed)
    _, v_rel, th = INPUT_NOISE[noise]
    rng = np.random.default_rng([seed, int(100 * ratio), noise])
    windows = [with_input_noise(c.window, c.clean, v_rel, th, rng) for c in cs]
    return windows[i], cs[i]


def _one(w, names: list[str]) -> dict:
    """The candidates ``names`` on one window, in turn, with their wall times [s]."""
    out = {}
    for name in names:
        cfg = CANDIDATES[name]
        t0 = time.perf_counter()
        try:
            out[name] = (identify(w, config=cfg), time.perf_counter() - t0)
        except WindowError as exc:
            out[name] = (exc, time.perf_counter() - t0)
    return out


def stats(cases: list, results: list, names: list[str]) -> dict:
    """Per candidate: the accuracy, calibration and flag statistics of the module docstring."""
    return candidate_stats([c.truth.d for c in cases], results, names, WARNING_FLAGS)


def candidate_stats(truths: list, results: list, names: list[str], warning_flags: tuple[str, ...]) -> dict:
    """Per candidate name: μ, σ, median and worst |error|, coverage of ±1.96 SE, windows off by more than 20 %
    and how many of them carry none of ``warning_flags``, failures and median time.

    ``truths``: D per window; ``results``: per window, {name: (result or WindowError, seconds)}.
    """
    out = {}
    for name in names:
        ratios, cover, times, unflagged, failed = [], [], [], 0, 0
        for truth, res in zip(truths, results, strict=True):
            r, dt = res[name]
            times.append(dt)
            if isinstance(r, WindowError):
                failed += 1
                continue
            ratios.append(r.d / truth)
            cover.append(np.abs(r.d - truth) < 1.96 * np.array([r.stderr[p] for p in common.PARAMS]))
            if np.abs(ratios[-1] - 1).max() > 0.2 and not any(f.startswith(warning_flags) for f in r.flags):
                unflagged += 1
        rr = np.array(ratios)
        st = common.ratio_stats(rr)
        st.update({
            "median_abs_err": dict(zip(common.PARAMS, np.median(np.abs(rr - 1), axis=0).tolist(), strict=True)),
            "coverage_95": dict(zip(common.PARAMS, np.mean(cover, axis=0).tolist(), strict=True)),
            "off_20pct_unflagged": unflagged, "failed": failed, "median_time_ms": float(np.median(times) * 1e3),
        })
        out[name] = st
    return out


HEAD = ["own/clean P std", "input noise", "candidate", "median |err| a / b / H2 / Tm [%]", "worst [%]",
        "bias μ−1 a / b / H2 / Tm [%]", "σ a / b / H2 / Tm", "±1.96 SE cover [%]", "off > 20 % (unflagged)", "ms"]


def rows(label: str, cls: str, per: dict) -> list[list]:
    p = common.PARAMS
    return [[label, cls, name, " / ".join(f"{100 * st['median_abs_err'][k]:.1f}" for k in p),
             f"{100 * max(st['max_abs_err'].values()):.0f}",
             " / ".join(f"{100 * (st['mu'][k] - 1):+.1f}" for k in p),
             " / ".join(f"{st['sigma'][k]:.3f}" for k in p),
             " / ".join(f"{100 * st['coverage_95'][k]:.0f}" for k in p),
             f"{st['n_off_20pct']} ({st['off_20pct_unflagged']})", f"{st['median_time_ms']:.0f}"]
            for name, st in per.items()]


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows per ratio (default 50; --quick: 8)")
    ap.add_argument("--workers", type=int, default=2, help="threads (the machine is shared)")
    ap.add_argument("--shapes", nargs="+", default=["lowpass", "switching", "pink"],
                    help="own-fluctuation shapes")
    ap.add_argument("--noise-shapes", nargs="+", default=None,
                    help="shapes that also get noisy V/θ at the two PMU classes (default: the first shape)")
    ap.add_argument("--seed", type=int, default=SEED, help="seed of the cases (43: development)")
    ap.add_argument("--candidates", nargs="+", default=list(CANDIDATES), choices=list(CANDIDATES))
    ap.add_argument("--coherence", type=float, default=1.0,
                    help="correlation of the own ΔQ with the own ΔP (1: ΔQ = 0.33·ΔP, the bench as it was)")
    ap.add_argument("--tag", default="", help="name suffix of the JSON")
    ap.add_argument("--gate", action="store_true", help="print the gated composite from the JSON (no identification)")
    args = ap.parse_args(argv)
    name = ("own_fluctuation" + (f"_{args.tag}" if args.tag else "") + ("" if args.seed == SEED else f"_seed{args.seed}")
            + ("" if args.coherence == 1.0 else f"_coh{args.coherence:g}"))
    if args.gate:
        recorded = common.read_json(name)
        if any(k.startswith("gated") for k in recorded["candidates"]):
            print_confirm(recorded, lambda run: f"{run['shape']}, {run['input_noise']}")
            return recorded
        return print_gate(recorded)
    names = args.candidates
    noisy = args.noise_shapes if args.noise_shapes is not None else args.shapes[:1]
    n = args.n or (8 if args.quick else 50)
    t_all = time.perf_counter()
    out = {"machine": common.machine(), "n_per_ratio": n, "seed": args.seed, "level": LEVEL, "quick": args.quick,
           "coherence": args.coherence,
           "candidates": {k: CANDIDATES[k].to_dict() for k in names}, "runs": []}
    base = make_cases(n, level=LEVEL, seed=args.seed, input_noise=False)
    _one(base[0].window, names)  # numba compilation / cache load outside the timings
    table = []
    for si, shape in enumerate(args.shapes):
        for ratio in RATIOS:
            if ratio == 0.0 and si > 0:
                continue  # no own fluctuation: the shape does not matter
            cs = own_cases(n, ratio, shape, base, args.seed, args.coherence)
            achieved = [float(np.std(c.states["P_own"]) / np.std(c.clean.P)) if ratio > 0 else 0.0 for c in cs]
            label = f"{ratio:g} {shape} (achieved {np.median(achieved):.2f})" if ratio > 0 else "0"
            for k, (cls, v_rel, th) in enumerate(INPUT_NOISE if shape in noisy or ratio == 0.0 else INPUT_NOISE[:1]):
                rng = np.random.default_rng([args.seed, int(100 * ratio), k])
                windows = [with_input_noise(c.window, c.clean, v_rel, th, rng) for c in cs]
                with ThreadPoolExecutor(max_workers=args.workers) as pool:
                    results = list(pool.map(lambda w: _one(w, names), windows))
                per = stats(cs, results, names)
                out["runs"].append({"shape": shape, "ratio": ratio, "achieved_ratio": achieved, "input_noise": cls,
                                    "stats": per, **window_records([c.truth.d for c in cs], results, names)})
                table.extend(rows(label, cls, per))
                print(f"{shape} {ratio}, {cls}: done ({time.perf_counter() - t_all:.0f} s)", flush=True)
    out["total_s"] = time.perf_counter() - t_all
    print(common.md_table(HEAD, table))
    if "output error" in names and any(k.startswith("gated") for k in names):
        out["confirm"] = print_confirm(out, lambda run: f"{run['shape']}, {run['input_noise']}")
    if not args.no_write:
        common.write_json(name + ("_quick" if args.quick else ""), out)
    if "output error" in names and "AR disturbance (IV)" in names:
        print_gate(out)
    return out


def print_gate(recorded: dict) -> dict:
    """Print the gated composites (on ``own_ratio_p``; and with the IV's over-identification test) of a run."""
    from aslm_core.identify import IV_OVERID_MAX

    for title, bound in (("gate on own_ratio_p", None), (f"and iv_overid ≤ {IV_OVERID_MAX:g}", IV_OVERID_MAX)):
        body = [gated_row(run, overid_max=bound, label=f"{run['shape']}, {run['input_noise']}")
                for run in recorded["runs"]]
        print(f"\n{title}\n" + common.md_table(GATE_HEAD, body))
    return recorded


if __name__ == "__main__":
    main()
