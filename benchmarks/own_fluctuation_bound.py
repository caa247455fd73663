"""The synthetic own-fluctuation bench against the Cramér–Rao bound of its data-generating process.

Issue 20's targets on the synthetic bench (:mod:`benchmarks.own_fluctuation`: DL 2, the load's own
constant-power part fluctuating at std ratio 0.5 or 0.9 to the clean P) were missed by the default (median
|error| of a 3.9 % at 0.5 against 3 %, 13.2 % at 0.9 against 10 %).  The issue asks, where a target is
impossible, to show it with the bound of the process and to meet the bound within 1.3×.  The ANDES bench has
its bound (:mod:`benchmarks.own_fluctuation_andes`); this is the same bound on the synthetic windows, exact V
and θ: per window, from the truth's Jacobian on the window's inputs and the true disturbance covariance
Σ = g·gᵀ ⊗ σ_own²·C + diag(σ_P², σ_Q²) ⊗ I (:mod:`aslm_core.information`; C the own shape's covariance over a
window, the Toeplitz matrix of its autocovariance from one long realisation, :func:`aslm_sim.own.window_covariance`; σ_own² the window's
own ΔP variance over the regression samples; σ_P², σ_Q² the white noise injected), the static part a nuisance.
``crb`` keeps the P–Q cross-covariance (ΔQ_own = 0.33·ΔP_own exactly on this bench), ``crb_sep`` each
channel's own spectrum only (the bound for estimators that model the channels separately, as the default's
AR and IV do; a real load's ΔQ/ΔP is not a constant).  The bound treats V and θ as given; the own process
moves them a little through the network (the loop is weak on this bench: std V changes by 0–6 %).

What a target needs of the bound: an efficient unbiased estimator's error on window i is N(0, v_i), so its
median |error| over the windows is the median of that mixture and its worst over n windows has a
distribution too (both computed here from the per-window v_i, the worst by simulation).  A target below
those is impossible on this bench whatever the estimator.

Every estimator in ``--candidates`` runs on the same windows as the bench (its seed, the first ``--n``
cases per row), one after the other, 3 random starts; per row: median |error|, bias, σ, RMSE, σ / bound
and RMSE / bound (bound = RMS of the per-window relative bound), and the median |error| and expected worst
that the bound allows.

    .venv/bin/python -m benchmarks.own_fluctuation_bound [--seed 243] [--n 50] [--shapes lowpass switching pink]
        [--candidates default uncoupled PEM IV] [--coherence 1]

Results: ``docs/results/own_fluctuation_bound[_TAG]_seed<seed>.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import math  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ThreadPoolExecutor  # noqa: E402

import numpy as np  # noqa: E402
from scipy import special  # noqa: E402

from aslm_core import IdentifyConfig  # noqa: E402
from aslm_core.information import model_jacobian  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from aslm_sim.own import window_covariance  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation import LEVEL, RATIOS, own_cases  # noqa: E402
from benchmarks.own_fluctuation_andes import relative_bounds  # noqa: E402
from benchmarks.own_gate import WARNING_FLAGS, window_records  # noqa: E402

#: The bench's confirmation seed of the default (stop 26's re-measurement, ``own_fluctuation_default_seed243``).
SEED = 243
#: Confirmation seed of the IV by LIML (stop 37), fixed before any run on it: ``--seed 251 --candidates default
#: "default, LIML" --tag liml`` at ``--coherence`` 1 and 0.7.
LIML_CONFIRM_SEED = 251
#: Confirmation seed of both (LIML and the own fluctuation's AR models, stop 37), fixed before any run on it:
#: ``--seed 257 --candidates default "default, LIML, own whitening" --tag liml_own`` at ``--coherence`` 1 and 0.7.
BOTH_CONFIRM_SEED = 257
#: Seed of the long realisation behind each shape's window covariance (not a window's: an independent draw).
COV_SEED = 4320
COV_WINDOWS = 600
#: ``default`` is the library's (since stop 34 with the coupled second channel); ``uncoupled`` is the default of stops
#: 26–33 (the channels as measured).
CANDIDATES = {"default": IdentifyConfig(), "uncoupled": IdentifyConfig(couple_channels=False),
              "output error": IdentifyConfig(**common.OUTPUT_ERROR),
              # The gated default's two branches alone (stop 35: which is nearer the bound when ΔQ follows ΔP
              # only in part, --coherence < 1).
              "PEM": IdentifyConfig(disturbance="ar", input_weighting="none"),
              "IV": IdentifyConfig(disturbance="ar_iv", input_weighting="none"),
              # The IV by LIML instead of 2SLS (stop 37), alone and in the default.
              "IV, LIML": IdentifyConfig(disturbance="ar_iv", input_weighting="none", iv_estimator="liml"),
              "default, LIML": IdentifyConfig(iv_estimator="liml"),
              # The IV's AR models of the own fluctuation alone (stop 37).
              "default, own whitening": IdentifyConfig(iv_whitening="own"),
              "default, LIML, own whitening": IdentifyConfig(iv_estimator="liml", iv_whitening="own")}


def window_bound(case, cov: np.ndarray | None, coherence: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Relative bound variances var(D_i)/D_i² of one case's window (:func:`own_fluctuation_andes.relative_bounds`).
    ``cov``: the shape's unit covariance over the regression samples (None: no own process)."""
    own = None if cov is None else float(np.var(case.states["P_own"][-cov.shape[0]:])) * cov
    white = (float(np.var(case.window.P - case.clean.P)), float(np.var(case.window.Q - case.clean.Q)))
    return relative_bounds(case.window, case.truth.d, own, white, coherence)


def mixture_median(var: np.ndarray) -> float:
    """Median of |e| when e ~ N(0, var_i) with i uniform over the windows (bisection on the mixture's CDF)."""
    sd = np.sqrt(var)
    lo, hi = 0.0, 10.0 * float(sd.max())
    for _ in range(80):
        m = 0.5 * (lo + hi)
        if np.mean(special.erf(m / (sd * math.sqrt(2.0)))) < 0.5:
            lo = m
        else:
            hi = m
    return 0.5 * (lo + hi)


def expected_worst(var: np.ndarray, draws: int = 4000, seed: int = 0) -> tuple[float, float]:
    """Median and 90th percentile of max_i |e_i| over the windows, e_i ~ N(0, var_i) independent."""
    rng = np.random.default_rng(seed)
    worst = np.abs(rng.standard_normal((draws, var.size)) * np.sqrt(var)).max(axis=1)
    return float(np.median(worst)), float(np.quantile(worst, 0.9))


def row_summary(truths: list, results: list, names: list[str], bounds: np.ndarray) -> dict:
    """Per candidate and bound kind: the estimator's figures against what the bound allows.

    ``bounds``: (2, windows, 4) relative variances (with cross-covariance, per channel).
    """
    from benchmarks.own_fluctuation import candidate_stats

    per = candidate_stats(truths, results, names, WARNING_FLAGS)
    allowed = {}
    for k, kind in enumerate(("crb", "crb_sep")):
        v = bounds[k]
        allowed[kind] = {
            "rms": dict(zip(common.PARAMS, np.sqrt(v.mean(axis=0)).tolist(), strict=True)),
            "median_abs_err": dict(zip(common.PARAMS, [mixture_median(v[:, j]) for j in range(4)], strict=True)),
            # The worst over all four parameters is what the "worst" target reads.
            "worst_any_median": expected_worst(v.reshape(-1))[0],
            "worst_any_p90": expected_worst(v.reshape(-1))[1],
        }
    for name, st in per.items():
        errs = np.array([np.full(4, np.nan) if isinstance(r[name][0], Exception) else r[name][0].d / t - 1.0
                         for r, t in zip(results, truths, strict=True)])
        sigma = np.array([st["sigma"][p] for p in common.PARAMS])
        bias = np.array([st["mu"][p] - 1.0 for p in common.PARAMS])
        rmse = np.sqrt(bias**2 + sigma**2 * (st["n"] - 1) / st["n"])
        st["rmse"] = dict(zip(common.PARAMS, rmse.tolist(), strict=True))
        for kind, al in allowed.items():
            rms = np.array([al["rms"][p] for p in common.PARAMS])
            st[f"sigma_over_{kind}"] = dict(zip(common.PARAMS, (sigma / rms).tolist(), strict=True))
            st[f"rmse_over_{kind}"] = dict(zip(common.PARAMS, (rmse / rms).tolist(), strict=True))
            # Each window's error over its own bound: 1 for an efficient unbiased estimator, whatever the
            # windows' spread of bounds (the RMS bound above is dominated by the few least informative windows).
            z = errs / np.sqrt(bounds[0 if kind == "crb" else 1])
            ok = np.isfinite(z).all(axis=1)
            med = np.median(z[ok], axis=0)
            st[f"robust_z_{kind}"] = dict(zip(common.PARAMS, (1.4826 * np.median(np.abs(z[ok] - med), axis=0)).tolist(),
                                              strict=True))
            st[f"median_abs_z_{kind}"] = dict(zip(common.PARAMS, (np.median(np.abs(z[ok]), axis=0) / 0.6745).tolist(),
                                                  strict=True))
    return {"candidates": per, "bound": allowed}


HEAD = ["own/clean", "shape", "bound", "bound σ a / b / H2 / Tm [%]", "bound's median |err| [%]",
        "bound's worst of n (median / p90) [%]", "candidate", "median |err| [%]", "worst [%]", "bias μ−1 [%]",
        "σ / bound", "RMSE / bound", "window's |err| / its bound (median ÷ 0.674)"]


def table_rows(ratio: float, shape: str, summ: dict) -> list[list]:
    p = common.PARAMS
    out = []
    for kind, al in summ["bound"].items():
        for name, st in summ["candidates"].items():
            out.append([f"{ratio:g}", shape, "with cross-cov." if kind == "crb" else "per channel",
                        " / ".join(f"{100 * al['rms'][k]:.1f}" for k in p),
                        " / ".join(f"{100 * al['median_abs_err'][k]:.1f}" for k in p),
                        f"{100 * al['worst_any_median']:.0f} / {100 * al['worst_any_p90']:.0f}", name,
                        " / ".join(f"{100 * st['median_abs_err'][k]:.1f}" for k in p),
                        f"{100 * max(st['max_abs_err'].values()):.0f}",
                        " / ".join(f"{100 * (st['mu'][k] - 1):+.1f}" for k in p),
                        " / ".join(f"{st[f'sigma_over_{kind}'][k]:.2f}" for k in p),
                        " / ".join(f"{st[f'rmse_over_{kind}'][k]:.2f}" for k in p),
                        " / ".join(f"{st[f'median_abs_z_{kind}'][k]:.2f}" for k in p)])
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows per row (default 50; --quick: 8)")
    ap.add_argument("--seed", type=int, default=SEED, help="seed of the bench's cases")
    ap.add_argument("--shapes", nargs="+", default=["lowpass", "switching", "pink"])
    ap.add_argument("--workers", type=int, default=2, help="threads for the identifications")
    ap.add_argument("--candidates", nargs="+", default=["default", "uncoupled"], choices=list(CANDIDATES))
    ap.add_argument("--coherence", type=float, default=1.0,
                    help="correlation of the own ΔQ with the own ΔP (1: ΔQ = 0.33·ΔP, the bench as it was)")
    ap.add_argument("--tag", default="", help="name suffix of the JSON")
    args = ap.parse_args(argv)
    n = args.n or (8 if args.quick else 50)
    names = args.candidates
    t_all = time.perf_counter()
    out = {"machine": common.machine(), "seed": args.seed, "level": LEVEL, "n_per_row": n, "quick": args.quick,
           "candidates": {k: CANDIDATES[k].to_dict() for k in names}, "cov_seed": COV_SEED,
           "cov_windows": COV_WINDOWS, "coherence": args.coherence, "runs": []}
    base = make_cases(n, level=LEVEL, seed=args.seed, input_noise=False)
    run = {k: CANDIDATES[k] for k in names}
    _one_cfg = lambda w: {k: _timed(w, cfg) for k, cfg in run.items()}  # noqa: E731
    _one_cfg(base[0].window)  # compilation outside the rows
    table, covs = [], {}
    for si, shape in enumerate(args.shapes):
        for ratio in RATIOS:
            if ratio == 0.0 and si > 0:
                continue
            cs = own_cases(n, ratio, shape, base, args.seed, args.coherence)
            l = model_jacobian(cs[0].window, cs[0].truth.d)[0].shape[0] // 2
            if ratio > 0 and (shape, l) not in covs:
                covs[shape, l] = window_covariance(shape, l, 100.0, COV_WINDOWS, COV_SEED)
            cov = covs.get((shape, l)) if ratio > 0 else None
            bounds = np.array([window_bound(c, cov, args.coherence) for c in cs]).transpose(1, 0, 2)
            with ThreadPoolExecutor(max_workers=args.workers) as pool:
                results = list(pool.map(_one_cfg, [c.window for c in cs]))
            truths = [c.truth.d for c in cs]
            summ = row_summary(truths, results, names, bounds)
            out["runs"].append({"shape": shape if ratio > 0 else "-", "ratio": ratio,
                                "achieved_ratio": [float(np.std(c.states["P_own"]) / np.std(c.clean.P))
                                                   if ratio > 0 else 0.0 for c in cs],
                                "bound_rel_var": bounds.tolist(), **summ,
                                **window_records(truths, results, names)})
            table.extend(table_rows(ratio, shape if ratio > 0 else "-", summ))
            print(f"{shape} {ratio}: done ({time.perf_counter() - t_all:.0f} s)", flush=True)
    out["total_s"] = time.perf_counter() - t_all
    print(common.md_table(HEAD, table))
    if not args.no_write:
        name = ("own_fluctuation_bound" + (f"_{args.tag}" if args.tag else "") + f"_seed{args.seed}"
                + ("" if args.coherence == 1.0 else f"_coh{args.coherence:g}"))
        common.write_json(name + ("_quick" if args.quick else ""), out)
    return out


def _timed(window, cfg: IdentifyConfig):
    from aslm_core import WindowError, identify

    t0 = time.perf_counter()
    try:
        return identify(window, config=cfg), time.perf_counter() - t0
    except WindowError as exc:
        return exc, time.perf_counter() - t0


if __name__ == "__main__":
    main()
