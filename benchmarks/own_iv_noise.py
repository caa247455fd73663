"""What biases the IV below full P–Q coherence: the P/Q measurement noise through the AR whitening.

At a P–Q coherence ρ < 1 of the load's own fluctuation the IV (``disturbance="ar_iv"``) is biased on step-like own
processes (a −9 to −15 % on switching at own/total 0.9, ρ = 0.7), and pooling windows does not remove it, so it is
not only the weak instruments' finite-sample pull.  The instruments (the whitened regressors at lags 2–3) carry the
own process through V (the loop); they are valid only if the whitened residual is uncorrelated with the own
process's past, i.e. if the whitening filter is the own process's own AR polynomial.  The identifier fits the AR
model to the residual, own process *plus* the white measurement noise on P and Q, whose Yule–Walker equations
differ from the own process's at lag 0: its whitened residual keeps a part of the own process's past, which the
instruments see.  Checks of that reading, on the same windows:

* the white noise on P and Q scaled down (synthetic: ``--noise-scale``, the same draws; ANDES: ``--snr-db``), the
  AR whitening as in the identifier: the bias should go with the noise;
* the noise as in the bench, the AR polynomial from the modified (high-order) Yule–Walker equations at lags
  p + 1 … p + m, which hold for the own process's AR part whatever the white noise is (an AR(p) plus white noise
  is an ARMA(p, p)): ``--myw-order``;
* the identifier's AR order and Yule–Walker fit, with the white variance read from the autocovariance at lags
  0–2 taken off γ(0) first (``--whitening deconvolved``, :func:`deconvolved_whitener`), or the white variance
  chosen by the Whittle likelihood of AR(p) + white noise (``--whitening whittle``, :func:`whittle_whitener`), or
  the deconvolved one only where the residual's autocovariance at lags 1–3 is exponential (``--whitening gated``: the
  identifier's ``iv_whitening="own"``, :func:`aslm_core.disturbance.own_whitener`).

Rows: the IV by 2SLS and by LIML (``IdentifyConfig.iv_estimator``), each with every whitening of ``--whitening``
(default: the identifier's and the modified Yule–Walker one), at the bench's noise and at the reduced noise.  Exact V
and θ.

    .venv/bin/python -m benchmarks.own_iv_noise [--andes] [--shapes switching lowpass] [--n 30] [--coherence 0.7]
        [--whitening bic myw deconvolved whittle gated] [--tag TAG] [--shape-statistics]

Results: ``docs/results/own_iv_noise_{synthetic_seed<seed>|andes_own<seed>}_coh<ρ>.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import contextlib  # noqa: E402
import math  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, disturbance, identify  # noqa: E402
from aslm_core.params import DYNAMIC_NAMES  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from benchmarks import common  # noqa: E402

#: The IV alone, as the gated default runs it where own fluctuation dominates.
IV = {est: IdentifyConfig(disturbance="ar_iv", input_weighting="none", iv_estimator=est) for est in ("2sls", "liml")}


def modified_yule_walker(r: np.ndarray, order: int, equations: int) -> np.ndarray | None:
    """AR polynomial [1, f1, …, fp] of r's coloured part from the Yule–Walker equations at lags p + 1 … p + m.

    For r = x + w with x AR(p) and w white, Σ_j f_j·γ_r(k − j) = 0 holds for k > p (γ_r(0) is not used), so f is x's
    AR polynomial whatever w's variance; least squares over ``equations`` = m lags.  None where the polynomial has
    a root on or outside the unit circle.
    """
    g = disturbance.autocovariance(r, 2 * order + equations + 1)
    a = np.array([[g[abs(k - j)] for j in range(1, order + 1)] for k in range(order + 1, order + equations + 1)])
    b = -g[order + 1:order + equations + 1]
    poly = np.r_[1.0, np.linalg.lstsq(a, b, rcond=None)[0]]
    return poly if np.max(np.abs(np.roots(poly))) < 0.999 else None


def deconvolved_whitener(r: np.ndarray, max_order: int = disturbance.AR_MAX_ORDER,
                         bic_whitener=disturbance.ar_whitener) -> np.ndarray | None:
    """The identifier's AR whitening (order by BIC on r) with the white noise's variance taken off γ(0) first.

    The white variance is read as γ(0) − γ(1)²/γ(2) (clipped at 0): exact for an AR(1) own process plus white
    noise (γ_x(0) = γ_x(1)/φ, φ = γ(2)/γ(1)); a smooth own process, whose autocovariance falls quadratically at
    the origin, gives a value below the noise's (negative on most windows: then nothing is taken off).  None where
    the deconvolved autocovariance is not positive definite at that order.  ``bic_whitener``: the identifier's
    whitening, whose order is kept.
    """
    p = len(bic_whitener(r, max_order)) - 1
    if p == 0:
        return np.array([1.0])
    g = disturbance.autocovariance(r, max(p, 2))
    white = g[0] - g[1] * g[1] / g[2] if g[2] > 0.0 else 0.0
    g = g[: p + 1].copy()
    g[0] -= min(max(white, 0.0), 0.99 * g[0])
    polys, var = disturbance.levinson(g)
    return polys[-1] if np.all(var > 0.0) else None


def whittle_whitener(r: np.ndarray, max_order: int = disturbance.AR_MAX_ORDER,
                     bic_whitener=disturbance.ar_whitener, grid: int = 24) -> np.ndarray:
    """The AR part of an AR(p) + white-noise model of r, the white variance s by the Whittle likelihood.

    p is the identifier's (BIC on r); for each s on a grid from 0 to 0.9·γ(0), Levinson on the autocovariance with s
    taken off γ(0) gives A_s and σ_e²(s), and the model spectrum σ_e²/|A_s|² + s is scored against r's periodogram
    by the Whittle likelihood; the best s's A_s is returned (s = 0: the identifier's whitening).
    """
    x = r - r.mean()
    n = x.size
    p = len(bic_whitener(r, max_order)) - 1
    if p == 0:
        return np.array([1.0])
    g = disturbance.autocovariance(r, p)
    per = np.abs(np.fft.rfft(x)) ** 2 / n  # E = the spectrum at the window's own bins
    best, best_ll = None, -math.inf
    for s in np.linspace(0.0, 0.9 * g[0], grid):
        gs = g.copy()
        gs[0] -= s
        polys, var = disturbance.levinson(gs)
        if not np.all(var > 0.0):
            break
        a = polys[-1]
        model = var[-1] / np.abs(np.fft.rfft(a, n)) ** 2 + s
        ll = -float(np.sum(np.log(model) + per / model))
        if ll > best_ll:
            best, best_ll = a, ll
    return best if best is not None else np.array([1.0])


#: Confirmation seeds of the gated whitening (``--whitening gated``, the identifier's ``iv_whitening="own"``), fixed
#: before any run on them (ANDES own seed; synthetic bench seed).
CONFIRM_OWN_SEED, CONFIRM_SEED = 61, 253


@contextlib.contextmanager
def whitening(kind: str, order: int, equations: int):
    """The identifier's AR whitening replaced inside the block: by :func:`modified_yule_walker` (``kind`` "myw"),
    :func:`deconvolved_whitener` ("deconvolved"), each falling back to the identifier's where it returns None, or
    :func:`whittle_whitener` ("whittle"); left as it is for "bic" and "gated" (which :func:`fit` runs through the
    identifier's own ``iv_whitening="own"``)."""
    chosen = disturbance.ar_whitener

    def myw(r, max_order=disturbance.AR_MAX_ORDER):
        poly = modified_yule_walker(r, order, equations)
        return chosen(r, max_order) if poly is None else poly

    def deconvolved(r, max_order=disturbance.AR_MAX_ORDER):
        poly = deconvolved_whitener(r, max_order, chosen)
        return chosen(r, max_order) if poly is None else poly

    def whittle(r, max_order=disturbance.AR_MAX_ORDER):
        return whittle_whitener(r, max_order, chosen)

    if kind == "whittle":
        disturbance.ar_whitener = whittle
    elif kind == "myw":
        disturbance.ar_whitener = myw
    elif kind == "deconvolved":
        disturbance.ar_whitener = deconvolved
    try:
        yield
    finally:
        disturbance.ar_whitener = chosen


def fit(window, truth: np.ndarray, est: str, kind: str = "bic") -> tuple[list[float], list[bool]]:
    """Relative error and ±1.96 SE coverage of the IV ``est`` on one window (NaN / False where refused); ``kind``
    "gated": the identifier's ``iv_whitening="own"``."""
    try:
        r = identify(window, config=replace(IV[est], iv_whitening="own" if kind == "gated" else "residual"))
    except WindowError:
        return [math.nan] * 4, [False] * 4
    se = np.array([r.stderr[k] for k in DYNAMIC_NAMES])
    return (r.d / truth - 1.0).tolist(), (np.abs(r.d - truth) <= 1.96 * se).tolist()


def synthetic_rows(args) -> dict:
    """Per shape and noise level the synthetic bench's windows (seed ``args.seed``): the bench's, and with the P/Q
    noise scaled by ``args.noise_scale`` (the same draws)."""
    from aslm_sim.cases import make_cases
    from benchmarks.own_fluctuation import LEVEL, own_cases

    base = make_cases(args.n, level=LEVEL, seed=args.seed, input_noise=False)
    out = {}
    for shape in args.shapes:
        cs = own_cases(args.n, args.ratio, shape, base, args.seed, args.coherence)
        for label, s in (("bench's noise", 1.0), (f"noise × {args.noise_scale:g}", args.noise_scale)):
            ws = [replace(c.window, P=c.clean.P + s * (c.window.P - c.clean.P),
                          Q=c.clean.Q + s * (c.window.Q - c.clean.Q)) for c in cs]
            out[(shape, label)] = [(w, np.asarray(c.truth.d, dtype=np.float64)) for w, c in zip(ws, cs, strict=True)]
    return out


def andes_rows(args) -> dict:
    """Per shape and noise level the ANDES own bench's windows (own seed ``args.own_seed``, each window's own run from
    its start): at the bench's 22 dB and at ``args.snr_db`` (the same draws scaled)."""
    from aslm_sim.andes import own_fluctuation as andes_own
    from benchmarks import own_fluctuation_andes as bench

    grid = andes_own.grid_recording(tf=bench.TF, tstep=bench.TSTEP, seed=bench.SEED, fs=bench.FS)
    truth = np.asarray(grid["truth"], dtype=np.float64)
    out = {}
    for shape in args.shapes:
        own = andes_own.own_recording(shape, tf=bench.TF, tstep=bench.TSTEP, seed=args.own_seed,
                                      coherence=args.coherence)
        for label, snr in ((f"{bench.SNR_DB:g} dB", bench.SNR_DB), (f"{args.snr_db:g} dB", args.snr_db)):
            ws = bench.row_windows(grid, own, args.ratio, shape, args.n, args.own_seed, horizon_s=0.0, snr_db=snr)
            out[(shape, label)] = [(bench.as_window(w), truth) for w in ws]
    return out


def shape_statistics(windows: dict) -> dict:
    """Per shape (the bench's noise), p10 / median / p90 over the windows of :func:`aslm_core.disturbance.log_curvature`
    of the P residual at the output-error optimum: what :data:`aslm_core.disturbance.EXPONENTIAL_CURVATURE_MAX` was set
    from (development windows: synthetic seed 243 and ANDES own seed 1, the first 20 per shape)."""
    out = {}
    for (shape, noise), ws in windows.items():
        if noise not in ("bench's noise", "22 dB"):
            continue
        vals = []
        for w, _ in ws:
            oe = identify(w, config=replace(IV["2sls"], disturbance="none"))
            pb = Problem(prepare(w, floors=True), w.f0, IV["2sls"])
            r = pb.residuals(pb.into_feasible(np.asarray(oe.d)), jacobian=False)[0]
            vals.append(disturbance.log_curvature(disturbance.autocovariance(r, 3)))
        out[shape] = np.percentile(vals, [10, 50, 90]).tolist()
        print(f"{shape}: log-curvature p10 / median / p90 " + " / ".join(f"{v:+.2f}" for v in out[shape]), flush=True)
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--andes", action="store_true", help="the ANDES own bench (own seed --own-seed) instead")
    ap.add_argument("--seed", type=int, default=243, help="synthetic bench's seed (243: development)")
    ap.add_argument("--own-seed", type=int, default=1, help="ANDES own seed (1: development)")
    ap.add_argument("--n", type=int, default=30)
    ap.add_argument("--shapes", nargs="+", default=["switching", "lowpass"])
    ap.add_argument("--ratio", type=float, default=0.9)
    ap.add_argument("--coherence", type=float, default=0.7)
    ap.add_argument("--noise-scale", type=float, default=0.1, help="synthetic: the P/Q noise's reduced scale")
    ap.add_argument("--snr-db", type=float, default=50.0, help="ANDES: the P/Q noise's reduced level [dB]")
    ap.add_argument("--whitening", nargs="+", default=["bic", "myw"], choices=["bic", "myw", "deconvolved", "whittle", "gated"],
                    help="bic: the identifier's; myw: modified Yule–Walker; deconvolved: the identifier's order, "
                         "the white variance γ(0) − γ(1)²/γ(2) taken off γ(0)")
    ap.add_argument("--tag", default="", help="name suffix of the JSON")
    ap.add_argument("--myw-order", type=int, default=1, help="order of the modified Yule–Walker whitening")
    ap.add_argument("--myw-equations", type=int, default=4, help="its equations (lags p + 1 … p + m)")
    ap.add_argument("--shape-statistics", action="store_true",
                    help="print the P residual's log-curvature per shape (what the own whitening's gate was set from) "
                         "and identify nothing else")
    args = ap.parse_args(argv)
    windows = andes_rows(args) if args.andes else synthetic_rows(args)
    if args.shape_statistics:
        return shape_statistics(windows)
    out = {"machine": common.machine(), "bench": "andes" if args.andes else "synthetic",
           "seed": None if args.andes else args.seed, "own_seed": args.own_seed if args.andes else None,
           "n": args.n, "ratio": args.ratio, "coherence": args.coherence, "myw_order": args.myw_order,
           "myw_equations": args.myw_equations, "rows": []}
    table = []
    for (shape, noise), ws in windows.items():
        for kind in args.whitening:
            for est in ("2sls", "liml"):
                with whitening(kind, args.myw_order, args.myw_equations):
                    fits = [fit(w, truth, est, kind) for w, truth in ws]
                e = 100 * np.array([f[0] for f in fits])
                cover = 100 * np.mean([f[1] for f in fits], axis=0)
                name = f"{est.upper()}, " + {"bic": "AR by BIC (the identifier's)",
                                             "myw": f"modified Yule–Walker AR({args.myw_order})",
                                             "deconvolved": "AR by BIC, white variance off γ(0)",
                                             "whittle": "AR by BIC + white noise, Whittle",
                                             "gated": "deconvolved where the autocovariance is exponential"}[kind]
                out["rows"].append({"shape": shape, "noise": noise, "fit": name, "errors_pct": e.tolist(),
                                    "cover_pct": cover.tolist()})
                table.append([shape, noise, name, " / ".join(f"{v:+.1f}" for v in np.nanmedian(e, axis=0)),
                              " / ".join(f"{v:+.1f}" for v in np.nanmean(e, axis=0)),
                              " / ".join(f"{v:.1f}" for v in np.nanmedian(np.abs(e), axis=0)),
                              " / ".join(f"{v:.0f}" for v in cover)])
        print(f"{shape}, {noise}: done", flush=True)
    print(common.md_table(["shape", "P/Q noise", "fit", "median error a / b / H2 / Tm [%]",
                           "bias μ−1 [%]", "median |err| [%]", "±1.96 SE cover [%]"], table))
    if not args.no_write:
        name = f"andes_own{args.own_seed}" if args.andes else f"synthetic_seed{args.seed}"
        common.write_json(f"own_iv_noise_{name}_coh{args.coherence:g}" + (f"_{args.tag}" if args.tag else ""), out)
    return out


if __name__ == "__main__":
    main()
