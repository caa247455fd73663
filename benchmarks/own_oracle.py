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
        [--ratio 0.9] [--coherence 0.7]

Per row: median |error| a / b / H2 / Tm [%], bias of a, and each window's |error| over its own bound (median ÷ 0.674,
1 for an efficient unbiased estimator).  Results: ``docs/results/own_oracle_seed<seed>_coh<ρ>.json``.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import contextlib  # noqa: E402

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, disturbance, identify  # noqa: E402
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


def _levinson(acf: np.ndarray) -> np.ndarray:
    """AR polynomial [1, a1, …, ap] of order len(acf) − 1 from an autocovariance (Levinson–Durbin)."""
    a, e = np.array([1.0]), float(acf[0])
    for p in range(1, acf.size):
        k = -(acf[p] + a[1:] @ acf[p - 1:0:-1]) / e
        a = np.concatenate([a, [0.0]])
        a = a + k * a[::-1]
        e *= 1.0 - k * k
    return a


def oracle_ar(window, d0: np.ndarray, sigma: np.ndarray, order: int = ORACLE_AR_ORDER) -> np.ndarray:
    """The prediction-error fit with the AR models of the true Σ (P, and Q − k·P with k = cov(Q, P)/var(P))."""
    pb = Problem(prepare(window, floors=True), window.f0, CANDIDATES["PEM"])
    l = sigma.shape[0] // 2
    spp, sqp, sqq = sigma[:l, :l], sigma[l:, :l], sigma[l:, l:]
    k = float(np.trace(sqp) / np.trace(spp))
    s2 = sqq - k * (sqp + sqp.T) + k * k * spp
    acf = [np.array([np.mean(np.diag(m, j)) for j in range(order + 1)]) for m in (spp, s2)]
    wp = disturbance.Whitened(pb, (_levinson(acf[0]), _levinson(acf[1])), k)
    return disturbance.constrained_lm(wp, pb.into_feasible(d0), 40, 1e-7, 1e-3)["d"]


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


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=243, help="seed of the bench's cases (243: development)")
    ap.add_argument("--n", type=int, default=30)
    ap.add_argument("--shapes", nargs="+", default=["lowpass", "pink", "switching"])
    ap.add_argument("--ratio", type=float, default=0.9)
    ap.add_argument("--coherence", type=float, default=0.7)
    args = ap.parse_args(argv)
    base = make_cases(args.n, level=LEVEL, seed=args.seed, input_noise=False)
    out = {"machine": common.machine(), "seed": args.seed, "n": args.n, "ratio": args.ratio,
           "coherence": args.coherence, "candidates": {k: v.to_dict() for k, v in CANDIDATES.items()}, "rows": []}
    table = []
    for shape in args.shapes:
        cs = own_cases(args.n, args.ratio, shape, base, args.seed, args.coherence)
        cov = window_covariance(shape, 900, 100.0, COV_WINDOWS, COV_SEED)
        bounds = np.array([window_bound(c, cov, args.coherence)[0] for c in cs])  # (n, 4) relative variances
        for loop in ("closed", "cut"):
            fixed = [f"{k}, AR order {FIXED_ORDER}" for k in CANDIDATES]
            errs: dict[str, list] = {k: [] for k in (*CANDIDATES, *fixed, f"oracle AR({ORACLE_AR_ORDER})",
                                                     "oracle GLS")}
            for b, c in zip(base, cs, strict=True):
                w = c.window if loop == "closed" else open_loop_window(b, c)
                white = (float(np.var(b.window.P - b.clean.P)), float(np.var(b.window.Q - b.clean.Q)))
                truth = np.asarray(c.truth.d, dtype=np.float64)
                d_default = None
                for name, cfg in CANDIDATES.items():
                    try:
                        d = identify(w, config=cfg).d
                    except WindowError:
                        d = np.full(4, np.nan)
                    errs[name].append(d / truth - 1.0)
                    if name == "default":
                        d_default = d
                with fixed_ar_order(FIXED_ORDER):
                    for name, cfg in CANDIDATES.items():
                        try:
                            d = identify(w, config=cfg).d
                        except WindowError:
                            d = np.full(4, np.nan)
                        errs[f"{name}, AR order {FIXED_ORDER}"].append(d / truth - 1.0)
                sigma = true_covariance(c, cov, args.coherence, white)
                start = d_default if np.isfinite(d_default).all() else truth
                errs[f"oracle AR({ORACLE_AR_ORDER})"].append(oracle_ar(w, start, sigma) / truth - 1.0)
                errs["oracle GLS"].append(oracle_gls(w, start, sigma) / truth - 1.0)
            for name, e in errs.items():
                e = np.array(e)
                z = np.abs(e) / np.sqrt(bounds)
                med, bias = 100 * np.nanmedian(np.abs(e), axis=0), 100 * np.nanmean(e, axis=0)
                zmed = np.nanmedian(z, axis=0) / 0.6745
                out["rows"].append({"shape": shape, "loop": loop, "candidate": name, "errors": e.tolist(),
                                    "median_abs_pct": med.tolist(), "bias_pct": bias.tolist(), "z": zmed.tolist()})
                table.append([shape, loop, name, " / ".join(f"{x:.1f}" for x in med), f"{bias[0]:+.1f}",
                              " / ".join(f"{x:.2f}" for x in zmed)])
            print(f"{shape}, loop {loop}: done", flush=True)
        allowed = 100 * np.sqrt(np.median(bounds, axis=0)) * 0.6745
        table.append([shape, "–", "bound (median window's σ × 0.674)", " / ".join(f"{x:.1f}" for x in allowed), "", ""])
    print(common.md_table(["shape", "loop", "fit", "median |err| a / b / H2 / Tm [%]", "bias a [%]",
                           "error / bound (median ÷ 0.674)"], table))
    if not args.no_write:
        common.write_json(f"own_oracle_seed{args.seed}_coh{args.coherence:g}", out)
    return out


if __name__ == "__main__":
    main()
