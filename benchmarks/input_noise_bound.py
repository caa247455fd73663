"""The Cramér–Rao bound with noisy V and θ on the Table I supplement's windows, next to the default's spread.

Per window (the supplement's: seed 43, the first ``--n``; the same clean record at every level), from the
truth: ∂[P; Q]/∂D and the static regressors (:func:`aslm_core.information.model_jacobian`), ∂[P; Q]/∂[V; θ]
(:func:`~aslm_core.information.input_jacobian`), and the prior of (V, θ) from one long clean realisation of
the same load and network (``--long-s`` seconds, another excitation draw;
:func:`~aslm_core.information.stationary_input_covariance`).  Per level and PMU class the bound with the
disturbance covariance S = Σ_v + A·P_x·Aᵀ, Σ_v the white P and Q noise actually injected: **structural**
(P_x what a perfect Wiener smoother leaves) and **functional** (P_x = Σ_n, no prior); and the exact-input
bound (S = Σ_v).  Reported: RMS over the windows of the relative bound of a, b, H2, Tm, i.e.
√(mean of var/D²), next to the σ of D_opt/D_real on the same windows and noise draws (those of
``benchmarks.input_noise --supplement``) of the default identifier (3 starts) and of an **oracle GLS**:
Gauss–Newton from the default's D on the residuals whitened by the true S (structural), with V and θ
replaced by their conditional mean under the true prior — the efficient estimator when S is known, i.e.
how much of the gap between the default and the bound an S-weighted estimator could close (exact
inputs: S = Σ_v, the inputs as measured).  The JSON is written every 50 windows (a checkpoint).

    .venv/bin/python -m benchmarks.input_noise_bound [--n 100] [--long-s 300] [--gls-inputs oracle|wiener]
    .venv/bin/python -m benchmarks.input_noise_bound --report    # the tables of the JSON written before

``--gls-inputs wiener``: the GLS on the default's own Wiener-smoothed V and θ instead of the oracle's
(JSON ``input_noise_bound_wiener_inputs``).

``--weighting``: the S-weighted estimator (``input_weighting="spectral"``, the default since issue 11's follow-up;
:mod:`aslm_core.input_weighting`) against ``input_weighting="none"`` on the same windows and draws (``--n``, default 300
per level), both run on each window in turn (interleaved), each ``--reps`` times on one thread (time: the
minimum per window, median over windows); per level and class μ, σ, coverage of ±1.96 SE, and, on the windows
whose bound ``input_noise_bound.json`` holds (the first 100), σ over the RMS structural bound and the
standardised spread (JSON ``input_noise_weighting``).

    .venv/bin/python -m benchmarks.input_noise_bound --weighting [--n 300] [--reps 2] [--seed 41] [--pooled 6]

``--pooled K`` adds the row ``spectral_pooled``: the default given the inputs' spectrum pooled over K previous noisy
windows of the bus, as the service's history gives it (:func:`history_spectrum`; JSON name suffix ``_pooled{K}``;
docs/numerics.md, stop 32 and stop 41).

The default's re-measurement runs ``--weighting --seed 45`` (:data:`FLIP_SEED`, fixed before that run; the stored
bounds are seed 43's, so its table has no σ / bound column); the service history's confirmation ``--weighting
--pooled 6 --seed 51`` (:data:`HISTORY_SEED`); ``--tail`` adds the row ``spectral_tail``, the default with
``input_spectrum_tail=True``, confirmed with ``--weighting --tail --seed 52`` (:data:`TAIL_SEED`); ``--temporal`` the
row ``temporal``, the default with the refinement whitening in the time domain (``input_weighting="temporal"``, stop 43).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, identify, noise  # noqa: E402
from aslm_core.information import (  # noqa: E402
    input_jacobian,
    input_noise_covariance,
    input_posterior_covariance,
    model_jacobian,
    model_response,
    stationary_input_covariance,
)
from aslm_core.input_history import InputHistory  # noqa: E402
from aslm_core.noise import InputPeriodogram, InputSpectrum  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_sim.cases import make_cases  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import CONFIRM_SEED, INPUT_NOISE, TARGETS, with_input_noise  # noqa: E402

#: The data-generating model: the inputs as given (no smoother, no low-pass), as the identifier's model.
MODEL = IdentifyConfig(input_smoother="none")
LEVELS = (1, 2, 3)
#: Seed of the long realisations (another excitation draw of each window's load and network).
LONG_SEED = 4343
KINDS = ("structural", "functional")


def static_coefficients(truth) -> tuple[np.ndarray, np.ndarray]:
    """The truth's static coefficients on [1, V, V²] as the identifier splits them (Qz + 1/X') [pu]."""
    st = truth.static_identifiable
    return np.array([st["Pp"], st["Pi"], st["Pz"]]), np.array([st["Qp"], st["Qi"], st["Qz"]])


def long_inputs(case, long_s: float) -> tuple[np.ndarray, np.ndarray]:
    """V [pu], θ [rad] of a long clean realisation of the case's load and network."""
    net = {k: complex(*v) if isinstance(v, list) else v for k, v in case.clean.meta["network"].items()}
    seed = (LONG_SEED * 1_000_000 + int(case.clean.meta["seed"])) * 1000 + int(case.clean.meta["case"])
    lc = make_cases(1, seed=seed, truths=[case.truth], networks=[net], duration_s=long_s, input_noise=False,
                    fs=1.0 / float(np.median(np.diff(case.clean.t))), f0=case.clean.f0)[0]
    return lc.clean.V, lc.clean.theta


def oracle_inputs(w, prior: np.ndarray, noise_var: tuple[float, float]):
    """The window with V, θ replaced by E[x | x_m] under the true prior (the perfect Wiener smoother)."""
    n = w.V.size
    xm = np.r_[w.V - w.V.mean(), w.theta - w.theta.mean()]
    sn = np.repeat(np.asarray(noise_var, dtype=np.float64), n)
    xhat = xm - sn * linalg.cho_solve(linalg.cho_factor(prior + np.diag(sn), lower=True), xm)
    return dataclasses.replace(w, V=xhat[:n] + w.V.mean(), theta=xhat[n:] + w.theta.mean())


def bound(jac: np.ndarray, nuis: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """:func:`aslm_core.information.cramer_rao` from S's Cholesky factor (shared with :func:`gls` here)."""
    jw = linalg.solve_triangular(chol, jac, lower=True)
    q, _ = np.linalg.qr(linalg.solve_triangular(chol, nuis, lower=True))
    jw -= q @ (q.T @ jw)
    return np.linalg.inv(jw.T @ jw)


def gls(w, d0: np.ndarray, chol: np.ndarray, iters: int = 20) -> np.ndarray:
    """Gauss–Newton on D of the residuals whitened by S = chol·cholᵀ (the static part projected out after
    whitening), from d0 (> 0): the estimator the bound describes when S is known.  NaN when it diverges."""
    d = np.array(d0, dtype=np.float64)
    for _ in range(iters):
        model, jac, nuis, meas = model_response(w, d, MODEL)
        white = linalg.solve_triangular(chol, np.column_stack([meas - model, jac, nuis]), lower=True)
        q, _ = np.linalg.qr(white[:, 5:])
        white -= q @ (q.T @ white)
        step = np.linalg.lstsq(white[:, 1:5], white[:, 0], rcond=None)[0]
        if not np.all(np.isfinite(step)):
            return np.full(4, np.nan)
        # Keep D positive: a long step is halved until each parameter moves by less than half of itself.
        shrink = np.max(np.abs(step) / (0.5 * np.abs(d)))
        if not np.isfinite(shrink):
            return np.full(4, np.nan)
        if shrink >= 1.0:
            step /= 2.0 ** math.ceil(math.log2(shrink) + 1e-9)
        d += step
        if np.all(np.abs(step) < 1e-7 * np.abs(d)):
            break
    return d


def wiener_inputs(w):
    """The window with V, θ replaced by the default's own Wiener smoother's (from the window's spectra)."""
    prep = prepare(w, input_smoother="wiener")
    return dataclasses.replace(w, V=prep.V, theta=prep.theta)


def window_bounds(by_level: dict, rngs: dict, long_s: float, gls_inputs: str = "oracle") -> tuple[dict, dict]:
    """One window: relative bound variances (var/D²) per level, class and kind (module docstring), and
    D/D_real per level and class of the default identifier and of the oracle GLS (S known; V, θ by
    ``gls_inputs``: "oracle", E[x | x_m] under the true prior, or "wiener", the default's own smoother)."""
    case = by_level[LEVELS[0]]
    clean, d = case.clean, case.truth.d
    jac, nuis = model_jacobian(clean, d, MODEL)
    a = input_jacobian(clean, d, *static_coefficients(case.truth), config=MODEL)
    n = clean.V.size
    prior = stationary_input_covariance(*long_inputs(case, long_s), n)
    # Functional: A·Σ_n·Aᵀ = σ_V²·A_V·A_Vᵀ + σ_θ²·A_θ·A_θᵀ, the two products shared by the classes.
    per_input = (a[:, :n] @ a[:, :n].T, a[:, n:] @ a[:, n:].T)
    added, var = {}, {}
    for cls, v_rel, th in INPUT_NOISE[1:]:
        var[cls] = ((v_rel * float(np.mean(clean.V))) ** 2, th**2)
        added[cls, "functional"] = var[cls][0] * per_input[0] + var[cls][1] * per_input[1]
        added[cls, "structural"] = input_noise_covariance((0.0, 0.0), a, input_posterior_covariance(var[cls], n, prior))
    l = jac.shape[0] // 2
    out, est = {}, {}
    for level, c in by_level.items():
        sv = np.repeat([float(np.var(c.window.P - clean.P)), float(np.var(c.window.Q - clean.Q))], l)
        chol = {"none": np.diag(np.sqrt(sv))}
        rel = {"exact": np.diag(bound(jac, nuis, chol["none"])) / d**2}
        for (cls, kind), s in added.items():
            s = s + np.diag(sv)
            c_s = linalg.cholesky(s, lower=True)
            rel[f"{cls}|{kind}"] = np.diag(bound(jac, nuis, c_s)) / d**2
            if kind == "structural":
                chol[cls] = c_s
        out[level] = rel
        est[level] = {}
        for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
            w = with_input_noise(c.window, c.clean, v_rel, th, rngs[level, k])
            try:
                d0 = identify(w, config=IdentifyConfig()).d
            except WindowError:
                est[level][cls] = (np.full(4, np.nan), np.full(4, np.nan))
                continue
            try:
                # From the default's D; a parameter it put at 0 (its box's edge) starts at the truth.
                if cls == "none":
                    wx = w
                else:
                    wx = oracle_inputs(w, prior, var[cls]) if gls_inputs == "oracle" else wiener_inputs(w)
                d1 = gls(wx, np.where(d0 > 0, d0, d), chol[cls])
            except ValueError:  # the model left its equilibrium set on a wild step
                d1 = np.full(4, np.nan)
            est[level][cls] = (d0 / d, d1 / d)
    return out, est


def summary(bounds: list[dict], ests: list[dict], supplement: dict | None) -> dict:
    """Per level and class: RMS relative bounds, the default's and the oracle GLS's σ on these windows, the
    default's σ in the supplement (300 windows), and σ / bound."""
    out = {}
    for level in LEVELS:
        out[level] = {}
        for cls, _, _ in INPUT_NOISE:
            keys = ["exact"] if cls == "none" else [f"{cls}|{k}" for k in KINDS]
            row = {}
            for j, name in enumerate(("default", "gls")):
                r = np.array([e[level][cls][j] for e in ests])
                ok = np.all(np.isfinite(r), axis=1)
                row[f"n_{name}"] = int(ok.sum())
                row[f"mu_{name}"] = dict(zip(common.PARAMS, np.mean(r[ok], axis=0).tolist(), strict=True))
                row[f"sigma_{name}"] = dict(zip(common.PARAMS, np.std(r[ok], axis=0, ddof=1).tolist(), strict=True))
                row[f"sigma_{name}_ci"] = common.bootstrap_mu_sigma(r[ok])["sigma"]
                # A few windows far off (local optima, the box's edge) dominate σ, and a few poorly excited ones
                # the RMS bound: each error over its own window's bound, robustly (1.4826·MAD; 1 if efficient).
                z = (r[ok] - 1.0) / np.sqrt([b[level][keys[0]] for b, good in zip(bounds, ok, strict=True) if good])
                mad = 1.4826 * np.median(np.abs(z - np.median(z, axis=0)), axis=0)
                row[f"z_mad_{name}"] = dict(zip(common.PARAMS, mad.tolist(), strict=True))
            for key in keys:
                rms = np.sqrt(np.mean([b[level][key] for b in bounds], axis=0))
                row[f"bound_{key.split('|')[-1]}"] = dict(zip(common.PARAMS, rms.tolist(), strict=True))
            if supplement is not None:
                row["sigma_supplement_300"] = supplement["levels"][str(level)][cls]["default"]["sigma"]
            out[level][cls] = row
    return out


def _f(d: dict, fmt: str = "{:.3f}") -> str:
    return " / ".join(fmt.format(d[p]) for p in common.PARAMS)


HEAD = ["DL", "input noise", "n", "bound exact a / b / H2 / Tm", "bound structural", "bound functional",
        "σ default", "σ default / bound", "σ default, supplement (300)", "its / bound", "σ oracle GLS",
        "σ oracle GLS / bound"]


def table(summ: dict) -> list[list]:
    """One row per level and class; "bound" is the structural one (the exact-input one for exact inputs)."""
    rows = []
    for level, per in summ.items():
        for cls, row in per.items():
            b = row["bound_structural" if cls != "none" else "bound_exact"]

            def over(sig: dict, b: dict = b) -> str:
                return " / ".join(f"{sig[p] / b[p]:.2f}" for p in common.PARAMS)

            sup = row.get("sigma_supplement_300")
            rows.append([level, cls, row["n_default"], _f(per["none"]["bound_exact"]),
                         _f(row["bound_structural"]) if cls != "none" else "–",
                         _f(row["bound_functional"]) if cls != "none" else "–", _f(row["sigma_default"]),
                         over(row["sigma_default"]), _f(sup) if sup else "–", over(sup) if sup else "–",
                         _f(row["sigma_gls"]), over(row["sigma_gls"])])
    return rows


ROBUST_HEAD = ["DL", "input noise", "z spread default a / b / H2 / Tm", "z spread oracle GLS"]


def robust_rows(summ: dict) -> list[list]:
    """Per window error over that window's bound (structural; exact for exact inputs), 1.4826·MAD."""
    return [[level, cls, _f(row["z_mad_default"], "{:.2f}"), _f(row["z_mad_gls"], "{:.2f}")]
            for level, per in summ.items() for cls, row in per.items()]


def target_rows(summ: dict) -> list[list]:
    """Is each of issue 11's σ targets within the structural bound (bound ≤ target)?

    The 1.3× target is taken, as the issue defines it, on the default's exact-input σ: the supplement's
    (300 windows) when its JSON is there, else these windows'.
    """
    rows = []
    for level, per in summ.items():
        exact = per["none"]["bound_exact"]
        sig_exact = per["none"].get("sigma_supplement_300", per["none"]["sigma_default"])
        for cls, (_, sig) in TARGETS.items():
            b = per[cls]["bound_structural"]
            cells = []
            for p in common.PARAMS:
                target = 1.3 * sig_exact[p] if sig == "1.3x" else sig
                cells.append(f"{'possible' if b[p] <= target else 'IMPOSSIBLE'} (bound {b[p]:.3f} vs {target:.3f}; "
                             f"{b[p] / exact[p]:.1f}× exact bound)")
            rows.append([level, cls] + cells)
    return rows


def report(summ: dict, n: int) -> None:
    """Print the tables."""
    print(f"**Bound and spread** ({n} windows, seed {CONFIRM_SEED}):\n\n" + common.md_table(HEAD, table(summ)))
    print("\n**Robust spreads**:\n\n" + common.md_table(ROBUST_HEAD, robust_rows(summ)))
    print("\n**Targets against the structural bound**:\n\n"
          + common.md_table(["DL", "input noise"] + list(common.PARAMS), target_rows(summ)))


def record(bounds: list[dict], ests: list[dict], args, t_all: float) -> dict:
    """The JSON of the windows done so far."""
    path = common.RESULTS / "input_noise_supplement.json"
    supplement = json.loads(path.read_text()) if path.exists() else None
    return {"machine": common.machine(), "n": len(bounds), "seed": CONFIRM_SEED, "long_s": args.long_s,
            "long_seed": LONG_SEED, "quick": args.quick, "gls_inputs": args.gls_inputs,
            "summary": summary(bounds, ests, supplement),
            "per_window_relative_variance": bounds, "per_window_ratio": ests,
            "total_s": time.perf_counter() - t_all, "load_avg_at_end": list(os.getloadavg())}


#: ``--weighting``: the output-error fit alone against the S-weighted refinement (the default since issue 11's
#: follow-up).
#: ``spectral`` is the refinement without the spectrum's tail (the default until stop 41), so that the runs recorded
#: before the tail became the default reproduce and ``--tail`` compares against it.
WEIGHTING = {"none": IdentifyConfig(**common.OUTPUT_ERROR),
             "spectral": dataclasses.replace(IdentifyConfig(), input_spectrum_tail=False)}
#: ``--tail``: the S-weighted refinement with its smoother's spectrum continued above the cut-off (the default since
#: stop 41).
TAIL = dataclasses.replace(IdentifyConfig(), input_spectrum_tail=True)
#: ``--temporal``: the default with the S-weighted refinement whitening in the time domain (stop 43).
TEMPORAL = dataclasses.replace(IdentifyConfig(), input_weighting="temporal")
#: ``--weighting``'s seed for the re-measurement with the S-weighted default, fixed before its run (2026-11-24).
FLIP_SEED = 45


#: ``--weighting --pooled 6``'s seed for the confirmation of the service's input history (stop 41), fixed before its
#: run (2026-12-03), the decision rule with it (docs/numerics.md, "Stop 41: the service keeps the inputs' spectrum").
HISTORY_SEED = 51
#: ``--weighting --tail``'s seed for the confirmation of the spectrum's tail (stop 41), fixed before its run
#: (2026-12-03), the decision rule with it (docs/numerics.md, "Stop 41: the signal above the smoother's cut-off").
TAIL_SEED = 52


def history_periodograms(case, k: int, v_rel: float, th: float, rng: np.random.Generator) -> list[InputPeriodogram]:
    """The periodograms (:func:`aslm_core.noise.input_periodogram`) of k consecutive noisy 10 s windows of a long clean
    realisation of the case's load and network (:func:`long_inputs`, k·10 s; the bus's minute before the window), with
    the class's white noise on V and θ."""
    n = case.clean.V.size
    fs = 1.0 / float(np.median(np.diff(case.clean.t)))
    lv, lth = long_inputs(case, k * n / fs)
    std = np.array([v_rel * float(np.mean(case.clean.V)), th])[:, None]
    out = []
    for j in range(k):
        x = np.stack([lv[j * n:(j + 1) * n], lth[j * n:(j + 1) * n]])
        out.append(noise.input_periodogram(x + std * rng.standard_normal(x.shape), fs))
    return out


def pooled_history(periodograms: list[InputPeriodogram]) -> InputSpectrum | None:
    """The spectrum an :class:`~aslm_core.input_history.InputHistory` of all these consecutive windows' periodograms
    gives the window after them (as the service's worker pools a task's history), in the core's current form."""
    held = InputHistory(k=len(periodograms))
    for j, g in enumerate(periodograms):
        held.add(j * g.n / g.fs, ((j + 1) * g.n - 1) / g.fs, g)
    return held.spectrum(len(periodograms) * periodograms[-1].n / periodograms[-1].fs)


def history_spectrum(case, k: int, v_rel: float, th: float, rng: np.random.Generator) -> InputSpectrum:
    """The inputs' spectrum a service's history of k noisy 10 s windows gives (:func:`pooled_history` of
    :func:`history_periodograms`)."""
    return pooled_history(history_periodograms(case, k, v_rel, th, rng))


def weighting_run(n: int, reps: int, seed: int = CONFIRM_SEED, pooled_k: int = 0, history_of: int = 0,
                  tail: bool = False, temporal: bool = False) -> dict:
    """``--weighting`` (module docstring): per level, class and estimator the per-window D/D_real, SE/D_real
    and the minimum time [s], on the windows and draws of ``seed``; with ``pooled_k`` also the default given the
    inputs' spectrum pooled over that many previous windows (:func:`history_spectrum`, ``spectral_pooled``), of the
    window's own load and network, or with ``history_of`` = j of case i + j's (a stale history: another network)."""
    cases = {level: common.cases(n, level=level, seed=seed) for level in LEVELS}
    rngs = {(level, k): np.random.default_rng([seed, level, k])  # as window_bounds
            for level in LEVELS for k in range(len(INPUT_NOISE))}
    identify(cases[2][0].window, config=WEIGHTING["spectral"])  # numba compilation outside the timings
    names = (list(WEIGHTING) + (["spectral_pooled"] if pooled_k else []) + (["spectral_tail"] if tail else [])
             + (["temporal"] if temporal else []))
    rows = {"spectral_tail": TAIL, "temporal": TEMPORAL}
    per = {(level, cls, name): {"ratio": [], "se": [], "t": []} for level in LEVELS for cls, _, _ in INPUT_NOISE
           for name in names}
    t_all = time.perf_counter()
    for i in range(n):
        # One history per window and class, shared by the levels (the long realisation is the level-1 case's, as in
        # benchmarks.input_noise_decompose); its own draws, apart from the windows'.
        spectra = ({cls: history_spectrum(cases[LEVELS[0]][(i + history_of) % n], pooled_k, v_rel, th,
                                         np.random.default_rng([seed, 7, i, k]))
                    for k, (cls, v_rel, th) in enumerate(INPUT_NOISE)} if pooled_k else {})
        for level in LEVELS:
            c = cases[level][i]
            for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
                w = with_input_noise(c.window, c.clean, v_rel, th, rngs[level, k])
                for name in names:
                    cfg = rows.get(name) or WEIGHTING.get(name, WEIGHTING["spectral"])
                    best, r = math.inf, None
                    for _ in range(reps):
                        t0 = time.perf_counter()
                        try:
                            r = identify(w, config=cfg, input_spectrum=spectra.get(cls) if name == "spectral_pooled"
                                         else None)
                        except WindowError:
                            r = None
                        best = min(best, time.perf_counter() - t0)
                    rec = per[level, cls, name]
                    rec["t"].append(best)
                    rec["ratio"].append((r.d / c.truth.d).tolist() if r else [math.nan] * 4)
                    rec["se"].append(([r.stderr[p] for p in common.PARAMS] / c.truth.d).tolist() if r else [math.nan] * 4)
        if (i + 1) % 50 == 0:
            print(f"{i + 1} windows ({time.perf_counter() - t_all:.0f} s)", flush=True)
    return {"|".join(map(str, k)): v for k, v in per.items()}


def weighting_summary(per: dict, bounds: list[dict]) -> dict:
    """Per level, class and estimator: μ, σ, coverage, time; σ / RMS bound and the standardised spread on the
    windows with a stored bound (structural; exact for exact inputs)."""
    out = {}
    for key, rec in per.items():
        level, cls, _ = key.split("|")
        r, se = np.array(rec["ratio"]), np.array(rec["se"])
        ok = np.all(np.isfinite(r), axis=1)
        row = {"n": int(ok.sum()), "mu": r[ok].mean(axis=0).tolist(), "sigma": r[ok].std(axis=0, ddof=1).tolist(),
               "coverage_95": np.mean(np.abs(r[ok] - 1.0) < 1.96 * se[ok], axis=0).tolist(),
               "n_off_20pct": int(np.sum(np.any(np.abs(r[ok] - 1.0) > 0.2, axis=1))),
               "median_time_ms": float(np.median(rec["t"]) * 1e3),
               "sigma_ci": common.bootstrap_mu_sigma(r[ok])["sigma"]}
        nb = min(len(bounds), r.shape[0])
        if nb:
            bkey = "exact" if cls == "none" else f"{cls}|structural"
            var = np.array([b[level][bkey] for b in bounds[:nb]])
            okb = ok[:nb]
            row["n_bound"] = int(okb.sum())
            row["sigma_first_bound_n"] = r[:nb][okb].std(axis=0, ddof=1).tolist()
            row["bound_rms"] = np.sqrt(var[okb].mean(axis=0)).tolist()
            row["sigma_over_bound"] = (np.array(row["sigma_first_bound_n"]) / np.array(row["bound_rms"])).tolist()
            z = (r[:nb][okb] - 1.0) / np.sqrt(var[okb])
            row["z_mad"] = (1.4826 * np.median(np.abs(z - np.median(z, axis=0)), axis=0)).tolist()
        out[key] = row
    return out


W_HEAD = ["DL", "input noise", "estimator", "n", "μ a / b / H2 / Tm", "σ a / b / H2 / Tm", "±1.96 SE cover [%]",
          "off > 20 %", "σ / bound (first 100)", "z spread (first 100)", "ms"]


def weighting_rows(summ: dict) -> list[list]:
    """The ``--weighting`` table."""
    def f(x, fmt="{:.3f}"):
        return " / ".join(fmt.format(v) for v in x)

    return [[*key.split("|"), row["n"], f(row["mu"]), f(row["sigma"]), f([100 * c for c in row["coverage_95"]], "{:.0f}"),
             row["n_off_20pct"], f(row["sigma_over_bound"], "{:.2f}") if "sigma_over_bound" in row else "–",
             f(row["z_mad"], "{:.2f}") if "z_mad" in row else "–", f"{row['median_time_ms']:.1f}"]
            for key, row in summ.items()]


def weighting_targets(summ: dict) -> list[list]:
    """Issue 11's targets per level, noisy class and estimator: bias, σ (0.05, or 1.3 × the exact-input σ of
    the level), and the honest version σ ≤ 1.3 × the structural bound (on the windows with a bound)."""
    rows = []
    for key, row in summ.items():
        level, cls, name = key.split("|")
        if cls not in TARGETS:
            continue
        mu_tol, sig = TARGETS[cls]
        exact = summ[f"{level}|none|{name}"]["sigma"]
        cells = []
        for j in range(len(common.PARAMS)):
            target = 1.3 * exact[j] if sig == "1.3x" else sig
            bias_ok = abs(row["mu"][j] - 1.0) <= mu_tol
            cell = (f"{'met' if bias_ok else 'NOT'} / {'met' if row['sigma'][j] <= target else 'NOT'} "
                    f"(σ {row['sigma'][j]:.3f} vs {target:.3f})")
            if "sigma_over_bound" in row:
                ratio = row["sigma_over_bound"][j]
                cell += f" / {'met' if ratio <= 1.3 else 'NOT'} ({ratio:.2f}× bound)"
            cells.append(cell)
        rows.append([level, cls, name] + cells)
    return rows


def weighting_main(args) -> dict:
    """``--weighting``: run (or ``--report``), summarise against the stored bounds, print, write."""
    name = ("input_noise_weighting" + ("" if args.seed == CONFIRM_SEED else f"_seed{args.seed}")
            + (f"_pooled{args.pooled}" if args.pooled else "") + (f"_of{args.history_of}" if args.history_of else "")
            + ("_tail" if args.tail else "") + ("_temporal" if args.temporal else "")
            + ("_quick" if args.quick else ""))
    bpath = common.RESULTS / "input_noise_bound.json"
    # The stored bounds are those of the confirmation seed's windows.
    bounds = ([{int(k): v for k, v in w.items()} for w in json.loads(bpath.read_text())["per_window_relative_variance"]]
              if bpath.exists() and args.seed == CONFIRM_SEED else [])
    bounds = [{str(k): v for k, v in b.items()} for b in bounds]
    if args.report:
        out = json.loads((common.RESULTS / f"{name}.json").read_text())
    else:
        n = args.n or (6 if args.quick else 300)
        t_all = time.perf_counter()
        load0 = list(os.getloadavg())
        out = {"machine": common.machine(), "n": n, "seed": args.seed, "reps": args.reps,
               "configs": {k: v.to_dict() for k, v in {**WEIGHTING, "spectral_tail": TAIL, "temporal": TEMPORAL}.items()},
               "load_avg_at_start": load0,
               "pooled_k": args.pooled, "history_of": args.history_of,
               "tail": args.tail, "temporal": args.temporal,
               "per_window": weighting_run(n, args.reps, args.seed, args.pooled, args.history_of, args.tail,
                                           args.temporal)}
        out["total_s"] = time.perf_counter() - t_all
        out["load_avg_at_end"] = list(os.getloadavg())
    out["summary"] = weighting_summary(out["per_window"], bounds)
    print(f"**S-weighted estimator against the default** ({out['n']} windows per level, seed {out['seed']}):\n\n"
          + common.md_table(W_HEAD, weighting_rows(out["summary"])))
    print("\n**Targets** (bias / σ / σ ≤ 1.3 × bound):\n\n"
          + common.md_table(["DL", "input noise", "estimator"] + list(common.PARAMS), weighting_targets(out["summary"])))
    if not args.no_write:
        common.write_json(name, out)
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows (default 100; --quick 4)")
    ap.add_argument("--long-s", type=float, default=300.0, help="length of each long clean realisation [s]")
    ap.add_argument("--gls-inputs", choices=("oracle", "wiener"), default="oracle",
                    help="V, θ of the GLS: the true prior's conditional mean, or the default's Wiener smoother")
    ap.add_argument("--report", action="store_true", help="print the tables of the JSON written before; no run")
    ap.add_argument("--weighting", action="store_true", help="the S-weighted estimator against the default")
    ap.add_argument("--reps", type=int, default=2, help="--weighting: runs per identification (time: minimum)")
    ap.add_argument("--pooled", type=int, default=0,
                    help="--weighting: also the default given the inputs' spectrum pooled over this many previous windows")
    ap.add_argument("--tail", action="store_true",
                    help="--weighting: also the default with input_spectrum_tail=True (row spectral_tail)")
    ap.add_argument("--temporal", action="store_true",
                    help="--weighting: also the default with input_weighting='temporal' (row temporal)")
    ap.add_argument("--history-of", type=int, default=0, metavar="J",
                    help="--pooled: the history of case i + J's load and network for case i (a stale one; 0: its own)")
    ap.add_argument("--seed", type=int, default=CONFIRM_SEED,
                    help="--weighting: seed of the windows (41 development, 43 confirmation; no bounds but for 43)")
    args = ap.parse_args(argv)
    if args.weighting:
        return weighting_main(args)
    n = args.n or (4 if args.quick else 100)
    # The run of record holds 100 windows; other counts are written beside it (the weighting rows read that one).
    name = ("input_noise_bound" + ("_wiener_inputs" if args.gls_inputs == "wiener" else "")
            + (f"_n{n}" if n != 100 and not args.quick else "") + ("_quick" if args.quick else ""))
    if args.report:  # the summary recomputed from the per-window figures (JSON keys are strings)
        out = json.loads((common.RESULTS / f"{name}.json").read_text())
        bounds = [{int(k): {key: np.array(v) for key, v in b.items()} for k, b in w.items()}
                  for w in out["per_window_relative_variance"]]
        ests = [{int(k): {cls: tuple(np.array(x, dtype=float) for x in v) for cls, v in e.items()}
                 for k, e in w.items()} for w in out["per_window_ratio"]]
        path = common.RESULTS / "input_noise_supplement.json"
        out["summary"] = summary(bounds, ests, json.loads(path.read_text()) if path.exists() else None)
        report(out["summary"], out["n"])
        if not args.no_write:
            common.write_json(name, out)
        return out
    t_all = time.perf_counter()
    cases = {level: common.cases(n, level=level, seed=CONFIRM_SEED) for level in LEVELS}
    rngs = {(level, k): np.random.default_rng([CONFIRM_SEED, level, k])  # as benchmarks.input_noise.run_level
            for level in LEVELS for k in range(len(INPUT_NOISE))}
    identify(cases[2][0].window)  # numba compilation outside the loop
    bounds, ests = [], []
    for i in range(n):
        b, e = window_bounds({level: cases[level][i] for level in LEVELS}, rngs, args.long_s, args.gls_inputs)
        bounds.append(b)
        ests.append(e)
        if (i + 1) % 10 == 0:
            print(f"{i + 1} windows ({time.perf_counter() - t_all:.0f} s)", flush=True)
        if (i + 1) % 50 == 0 and i + 1 < n and not args.no_write:  # a checkpoint: long runs on a shared machine
            common.write_json(name, record(bounds, ests, args, t_all))
    out = record(bounds, ests, args, t_all)
    report(out["summary"], n)
    if not args.no_write:
        common.write_json(name, out)
    return out


if __name__ == "__main__":
    main()
