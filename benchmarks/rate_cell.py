"""One reporting-rate cell of ``benchmarks.input_noise --rates`` window by window: where a bias comes from.

DL 2, 0.1 % / 1e-3 rad on V and θ (the rates bench's windows and draws for a seed), ``input_weighting="none"``
and ``"spectral"`` on each window in turn.  Per seed and pooled: μ of a and b, μ of a on the windows flagged
``input_noise_too_large`` (V's PMU noise above half its ambient std) and on the others, the median, and the
lowest a with the flags they carry — so a mean pulled by a few windows is told from a shift of the whole
distribution.  Issue 11's follow-up: μ(a) 0.965 at 60 frames/s on seed 43 (docs/numerics.md).

    .venv/bin/python -m benchmarks.rate_cell [--fs 60] [--seeds 43 41 44 48 49 50] [--n 100] [--tag NAME] [--summary-only]

Results in ``docs/results/rate_cell_<fs>[_<tag>].json`` (``--tag`` keeps a run of record).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, identify  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE, with_input_noise  # noqa: E402

ESTIMATORS = {"none": IdentifyConfig(**common.OUTPUT_ERROR),
              "spectral": IdentifyConfig(input_weighting="spectral", disturbance="none")}
SWAMPED = "input_noise_too_large"


def windows_of(seed: int, fs: float, n: int) -> tuple[list, list]:
    """The rates bench's cases and 0.1 % / 1e-3 rad windows of ``seed`` at ``fs`` (its draws: class index 2)."""
    cs = common.cases(n, level=2, seed=seed, input_noise=False, fs=fs)
    k = 2
    _, v_rel, th = INPUT_NOISE[k]
    rng = np.random.default_rng([seed, 2, k])
    return cs, [with_input_noise(c.window, c.clean, v_rel, th, rng) for c in cs]


def per_window(seed: int, fs: float, n: int) -> list[dict]:
    """Per window and estimator: D/D_real, SE/D_real and flags."""
    cs, ws = windows_of(seed, fs, n)
    out = []
    for c, w in zip(cs, ws, strict=True):
        rec = {}
        for name, cfg in ESTIMATORS.items():
            r = identify(w, config=cfg)
            rec[name] = {"ratio": (r.d / c.truth.d).tolist(),
                         "se": (np.array([r.stderr[p] for p in common.PARAMS]) / c.truth.d).tolist(), "flags": r.flags}
        out.append(rec)
    return out


def summary(recs: list[dict]) -> dict:
    """Per estimator: μ a, b; μ a with and without the swamped flag; median a; the five lowest a and their flags."""
    out = {}
    for name in ESTIMATORS:
        r = np.array([x[name]["ratio"] for x in recs])
        sw = np.array([SWAMPED in x[name]["flags"] for x in recs])
        low = np.argsort(r[:, 0])[:5]
        out[name] = {"n": len(recs), "mu_a": float(r[:, 0].mean()), "mu_b": float(r[:, 1].mean()),
                     "se_mu_a": float(r[:, 0].std(ddof=1) / np.sqrt(len(r))), "median_a": float(np.median(r[:, 0])),
                     "n_swamped": int(sw.sum()), "mu_a_swamped": float(r[sw, 0].mean()) if sw.any() else None,
                     "mu_a_others": float(r[~sw, 0].mean()),
                     "lowest_a": [[int(k), float(r[k, 0]), recs[k][name]["flags"]] for k in low]}
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--fs", type=float, default=60.0, help="reporting rate [frames/s]")
    ap.add_argument("--seeds", type=int, nargs="+", default=[43, 41, 44, 48, 49, 50])
    ap.add_argument("--n", type=int, default=None, help="windows per seed (default 100; --quick: 10)")
    ap.add_argument("--tag", default="", help="suffix of the results file")
    ap.add_argument("--summary-only", action="store_true", help="write the summaries without the per-window records")
    args = ap.parse_args(argv)
    n = args.n or (10 if args.quick else 100)
    t0 = time.perf_counter()
    per = {s: per_window(s, args.fs, n) for s in args.seeds}
    out = {"machine": common.machine(), "fs": args.fs, "n": n, "seeds": args.seeds, "per_window": per,
           "summary": {str(s): summary(v) for s, v in per.items()}}
    if len(args.seeds) > 1:
        out["summary"]["pooled, all but the first seed"] = summary([x for s in args.seeds[1:] for x in per[s]])
        out["summary"]["pooled, all seeds"] = summary([x for s in args.seeds for x in per[s]])
    out["total_s"] = time.perf_counter() - t0
    rows = [[key, name, st["n"], f"{st['mu_a']:.3f} ± {st['se_mu_a']:.3f}", f"{st['mu_b']:.3f}", f"{st['median_a']:.3f}",
             f"{st['n_swamped']}: {st['mu_a_swamped']:.3f}" if st["mu_a_swamped"] is not None else "0",
             f"{st['mu_a_others']:.3f}", ", ".join(f"{v:.2f}" for _, v, _ in st["lowest_a"])]
            for key, per_est in out["summary"].items() for name, st in per_est.items()]
    print(common.md_table(["seed", "estimator", "n", "μ a ± SE", "μ b", "median a", f"{SWAMPED}: n, μ a",
                           "μ a, others", "lowest a"], rows))
    if args.summary_only:
        del out["per_window"]
    if not args.no_write:
        common.write_json(f"rate_cell_{args.fs:g}" + (f"_{args.tag}" if args.tag else "") + ("_quick" if args.quick else ""),
                          out)
    return out


if __name__ == "__main__":
    main()
