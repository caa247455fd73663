"""How far is the default from the bound because it learns the own fluctuation's spectrum from one window?

Below full P–Q coherence (ρ < 1) the default stays above the Cramér–Rao bound of the synthetic own bench even on the
smooth own processes, where the loop through the network costs nothing measurable (docs/numerics.md, "Stop 35: what
the loop costs" and "Stop 36: the own benches' bound, corrected").  The bound takes the disturbance covariance as
known; the prediction-error fit estimates an AR model per channel from the window.  Here the same windows are fitted
by an **oracle GLS**: Gauss–Newton on the residuals whitened by the true covariance of the bench's disturbance,
Σ = G ⊗ σ_own²·C + diag(σ_P², σ_Q²) ⊗ I (the bound's own Σ, :func:`benchmarks.own_fluctuation_bound.window_bound`:
C the own shape's Toeplitz covariance, σ_own² the window's own ΔP variance, G with the bench's ρ; the static part
projected out as in the identifier), started from the default's D.  It is an estimator that cannot be run (it knows
Σ); what it shows is how much of the gap a perfect noise model would close.  Beside it, the prediction-error fit
with the AR models of the true Σ (order 90, by Levinson on its autocovariance, the second channel Q − k·P with the true
k; no re-estimation), and the default and the prediction-error fit with the AR order fixed at 30 instead of BIC's
choice (the harness swaps :func:`aslm_core.disturbance.ar_whitener` for these rows).  Windows with the loop closed (as
simulated) and cut (:func:`benchmarks.own_loop.open_loop_window`).

    .venv/bin/python -m benchmarks.own_oracle [--seed 243] [--n 30] [--shapes lowpass pink switching]
        [--ratio 0.9] [--coherence 0.7] [--andes [--own-seed 1] --n 50]

Per row: median |error| a / b / H2 / Tm [%], bias of a, and each window's |error| over its own bound (median ÷ 0.674,
1 for an efficient unbiased estimator).  With ``--andes`` the same on the independent bench
(:mod:`benchmarks.own_fluctuation_andes`, own seed ``--own-seed``; its bound and Σ as that bench computes them).
Results: ``docs/results/own_oracle_seed<seed>_coh<ρ>.json``, ``own_oracle_andes_own<own seed>_coh<ρ>.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import contextlib  # noqa: E402

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, disturbance, identify, instrumental  # noqa: E402
from aslm_core.information import disturbance_covariance  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from aslm_sim.own import OWN_Q_PER_P, window_covariance  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.own_fluctuation import LEVEL, own_cases  # noqa: E402
from benchmarks.own_fluctuation_bound import COV_SEED, COV_WINDOWS, window_bound  # noqa: E402
from benchmarks.own_loop import open_loop_window  # noqa: E402

CANDIDATES = {"default": IdentifyConfig(), "PEM": IdentifyConfig(disturbance="ar", input_weighting="none")}
#: The order of the rows with the AR order fixed, and of the true Σ's AR models.
FIXED_ORDER = 30
ORACLE_AR_ORDER = 90


@contextlib.contextmanager
def fixed_ar_order(order: int):
    """The identifier's AR noise models at a fixed order instead of BIC's choice, inside the block."""
    chosen = disturbance.ar_whitener

    def whitener(r, max_order=disturbance.AR_MAX_ORDER):
        polys, _ = disturbance.levinson_orders(r, min(order, r.size // 10))
        return polys[-1]

    disturbance.ar_whitener = whitener
    try:
        yield
    finally:
        disturbance.ar_whitener = chosen


def true_ar_models(sigma: np.ndarray, order: int) -> tuple[tuple[np.ndarray, np.ndarray], float]:
    """The AR models (order ``order``) of the true Σ's P channel and of Q − k·P, k = cov(Q, P)/var(P), and k."""
    l = sigma.shape[0] // 2
    spp, sqp, sqq = sigma[:l, :l], sigma[l:, :l], sigma[l:, l:]
    k = float(np.trace(sqp) / np.trace(spp))
    s2 = sqq - k * (sqp + sqp.T) + k * k * spp
    acf = [np.array([np.mean(np.diag(m, j)) for j in range(order + 1)]) for m in (spp, s2)]
    return tuple(disturbance.levinson(x)[0][-1] for x in acf), k


def oracle_ar(window, d0: np.ndarray, sigma: np.ndarray, order: int = ORACLE_AR_ORDER) -> np.ndarray:
    """The prediction-error fit with the AR models of the true Σ (P, and Q − k·P with k = cov(Q, P)/var(P))."""
    pb = Problem(prepare(window, floors=True), window.f0, CANDIDATES["PEM"])
    polys, k = true_ar_models(sigma, order)
    wp = disturbance.Whitened(pb, polys, k)
    return disturbance.constrained_lm(wp, pb.into_feasible(d0), 40, 1e-7, 1e-3)["d"]


def oracle_iv(window, d0: np.ndarray, sigma: np.ndarray, estimator: str, order: int = ORACLE_AR_ORDER,
              passes: int = 2) -> np.ndarray:
    """The IV fit (``estimator``: 2SLS or LIML) whitened by the AR models of the true Σ (as :func:`oracle_ar`), its
    instruments renewed at each pass's D."""
    pb = Problem(prepare(window, floors=True), window.f0, CANDIDATES["PEM"])
    polys, k = true_ar_models(sigma, order)
    d = pb.into_feasible(d0)
    for _ in range(passes):
        wp = instrumental._ESTIMATORS[estimator](pb, polys, d, mix=k)
        d = disturbance.constrained_lm(wp, d, 40, 1e-7, 1e-3)["d"]
    return d


def true_covariance(case, cov: np.ndarray, coherence: float, white: tuple[float, float]) -> np.ndarray:
    """The bench's disturbance covariance of [P; Q] over the window's regression samples [pu²]."""
    own = float(np.var(case.states["P_own"][-cov.shape[0]:])) * cov
    return disturbance_covariance(own, (1.0, OWN_Q_PER_P), white, cross=True, coherence=coherence)


def oracle_gls(window, d0: np.ndarray, sigma: np.ndarray, iters: int = 15) -> np.ndarray:
    """Gauss–Newton on the residuals whitened by Σ, the static part projected out, from d0 (box-clipped)."""
    pb = Problem(prepare(window, floors=True), window.f0, CANDIDATES["PEM"])
    chol = linalg.cholesky(sigma, lower=True)

    def whitened(d):
        zs = disturbance.whitened_columns(pb, (np.array([1.0]), np.array([1.0])), d, 0)
        if zs is None:
            return None
        nb = zs[0].shape[1] - 5
        top = np.hstack([zs[0][:, :5], zs[0][:, 5:], np.zeros((zs[0].shape[0], nb))])
        bot = np.hstack([zs[1][:, :5], np.zeros((zs[1].shape[0], nb)), zs[1][:, 5:]])
        z = linalg.solve_triangular(chol, np.vstack([top, bot]), lower=True)
        q, _ = np.linalg.qr(z[:, 5:])
        proj = z[:, :5] - q @ (q.T @ z[:, :5])
        return proj[:, 0], proj[:, 1:]

    d = np.clip(np.asarray(d0, dtype=np.float64), pb.lower, pb.upper)
    out = whitened(d)
    if out is None:
        return d
    r, j = out
    cost = float(r @ r)
    for _ in range(iters):
        step = -np.linalg.lstsq(j, r, rcond=None)[0]
        for _ in range(8):
            trial = np.clip(d + step, pb.lower, pb.upper)
            o = whitened(trial) if pb.feasible(trial) else None
            if o is not None and float(o[0] @ o[0]) < cost:
                d, (r, j), cost = trial, o, float(o[0] @ o[0])
                break
            step *= 0.5
        else:
            break
    return d


def fit_all(window, truth: np.ndarray, sigma: np.ndarray) -> dict[str, np.ndarray]:
    """Every row's relative error D/D_real − 1 on one window (NaN where the identifier refused it)."""
    def run(cfg):
        try:
            return identify(window, config=cfg).d / truth - 1.0
        except WindowError:
            return np.full(4, np.nan)

    out = {name: run(cfg) for name, cfg in CANDIDATES.items()}
    with fixed_ar_order(FIXED_ORDER):
        out.update({f"{name}, AR order {FIXED_ORDER}": run(cfg) for name, cfg in CANDIDATES.items()})
    d_default = (out["default"] + 1.0) * truth
    start = d_default if np.isfinite(d_default).all() else truth
    out[f"oracle AR({ORACLE_AR_ORDER})"] = oracle_ar(window, start, sigma) / truth - 1.0
    out["oracle GLS"] = oracle_gls(window, start, sigma) / truth - 1.0
    for est in ("2sls", "liml"):
        out[f"oracle AR({ORACLE_AR_ORDER}) IV, {est.upper()}"] = oracle_iv(window, start, sigma, est) / truth - 1.0
    return out


def summarise(shape: str, loop: str, per_window: list[dict], bounds: np.ndarray, out: dict, table: list) -> None:
    """Per row: median |error|, bias and each window's error over its own bound (median ÷ 0.674)."""
    for name in per_window[0]:
        e = np.array([w[name] for w in per_window])
        z = np.abs(e) / np.sqrt(bounds)
        med, bias = 100 * np.nanmedian(np.abs(e), axis=0), 100 * np.nanmean(e, axis=0)
        zmed = np.nanmedian(z, axis=0) / 0.6745
        out["rows"].append({"shape": shape, "loop": loop, "candidate": name, "errors": e.tolist(),
                            "median_abs_pct": med.tolist(), "bias_pct": bias.tolist(), "z": zmed.tolist()})
        table.append([shape, loop, name, " / ".join(f"{x:.1f}" for x in med), f"{bias[0]:+.1f}",
                      " / ".join(f"{x:.2f}" for x in zmed)])
    print(f"{shape}, loop {loop}: done", flush=True)


def synthetic(args, out: dict, table: list) -> None:
    """The synthetic own bench's windows (seed ``args.seed``)."""
    base = make_cases(args.n, level=LEVEL, seed=args.seed, input_noise=False)
    for shape in args.shapes:
        cs = own_cases(args.n, args.ratio, shape, base, args.seed, args.coherence)
        cov = window_covariance(shape, 900, 100.0, COV_WINDOWS, COV_SEED)
        bounds = np.array([window_bound(c, cov, args.coherence)[0] for c in cs])  # (n, 4) relative variances
        for loop in ("closed", "cut"):
            per_window = []
            for b, c in zip(base, cs, strict=True):
                w = c.window if loop == "closed" else open_loop_window(b, c)
                white = (float(np.var(b.window.P - b.clean.P)), float(np.var(b.window.Q - b.clean.Q)))
                sigma = true_covariance(c, cov, args.coherence, white)
                per_window.append(fit_all(w, np.asarray(c.truth.d, dtype=np.float64), sigma))
            summarise(shape, loop, per_window, bounds, out, table)
        allowed = 100 * np.sqrt(np.median(bounds, axis=0)) * 0.6745
        table.append([shape, "–", "bound (median window's σ × 0.674)", " / ".join(f"{x:.1f}" for x in allowed), "", ""])


def andes(args, out: dict, table: list) -> None:
    """The ANDES own bench's windows (own seed ``args.own_seed``; cut: :func:`aslm_sim.andes.own_fluctuation.cut_windows`)."""
    from aslm_sim.andes import own_fluctuation as andes_own
    from benchmarks import own_fluctuation_andes as bench

    grid = andes_own.grid_recording(tf=bench.TF, tstep=bench.TSTEP, seed=bench.SEED, fs=bench.FS)
    truth = np.asarray(grid["truth"], dtype=np.float64)
    l_reg = int(round(bench.LENGTH_S * bench.FS)) + 1 - int(round(bench.FS))
    for shape in args.shapes:
        own = andes_own.own_recording(shape, tf=bench.TF, tstep=bench.TSTEP, seed=args.own_seed,
                                      coherence=args.coherence)
        cov = window_covariance(shape, l_reg, bench.FS, 600, seed=bench.SEED + 100)
        cut = {loop: bench.row_windows(grid, own, args.ratio, shape, args.n, args.own_seed, loop) for loop in (True, False)}
        bounds = np.array([bench._bound(w, truth, cov, args.coherence)[0] for w in cut[True]])
        for loop, ws in (("closed", cut[True]), ("cut", cut[False])):
            per_window = []
            for w in ws:
                sigma = disturbance_covariance(w["own_var"] * cov, (1.0, OWN_Q_PER_P),
                                               (w["noise_std_p"] ** 2, w["noise_std_q"] ** 2), cross=True,
                                               coherence=args.coherence)
                per_window.append(fit_all(bench.as_window(w), truth, sigma))
            summarise(shape, loop, per_window, bounds, out, table)
        allowed = 100 * np.sqrt(np.median(bounds, axis=0)) * 0.6745
        table.append([shape, "–", "bound (median window's σ × 0.674)", " / ".join(f"{x:.1f}" for x in allowed), "", ""])


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=243, help="seed of the bench's cases (243: development)")
    ap.add_argument("--n", type=int, default=30)
    ap.add_argument("--shapes", nargs="+", default=["lowpass", "pink", "switching"])
    ap.add_argument("--ratio", type=float, default=0.9)
    ap.add_argument("--coherence", type=float, default=0.7)
    ap.add_argument("--andes", action="store_true", help="the ANDES own bench's windows instead (--n 50 for a whole row)")
    ap.add_argument("--own-seed", type=int, default=1, help="with --andes: the own process's seed (1: development)")
    ap.add_argument("--tag", default="", help="name suffix of the JSON")
    args = ap.parse_args(argv)
    out = {"machine": common.machine(), "bench": "andes" if args.andes else "synthetic", "seed": args.seed,
           "own_seed": args.own_seed if args.andes else None, "n": args.n, "ratio": args.ratio,
           "coherence": args.coherence, "candidates": {k: v.to_dict() for k, v in CANDIDATES.items()}, "rows": []}
    table: list = []
    (andes if args.andes else synthetic)(args, out, table)
    print(common.md_table(["shape", "loop", "fit", "median |err| a / b / H2 / Tm [%]", "bias a [%]",
                           "error / bound (median ÷ 0.674)"], table))
    if not args.no_write:
        name = (f"own_oracle_andes_own{args.own_seed}" if args.andes else f"own_oracle_seed{args.seed}")
        common.write_json(f"{name}_coh{args.coherence:g}" + (f"_{args.tag}" if args.tag else ""), out)
    return out


if __name__ == "__main__":
    main()
