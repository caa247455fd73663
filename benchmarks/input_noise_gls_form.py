"""The oracle GLS of issue 11 with one of its exact ingredients replaced by the refinement's form of it, one at a time.

Stop 32 found the S-weighted refinement, given every oracle ingredient, still above the time-domain oracle GLS, and put
the rest on the refinement's form.  This benchmark asks which part of that form costs, from the GLS's side: on the
supplement's windows and draws (seed 43, ``--first`` to ``--n``, one level and PMU class), the oracle GLS of
``benchmarks.input_noise_bound`` (S = Σ_v + A·P_x·Aᵀ with the exact input Jacobian A and the exact posterior covariance
P_x of the inputs under the 300 s realisation's prior; V and θ the posterior mean) against the same GLS with:

* ``lti_A``: A built from the model's impulse response at mid-window (``input_weighting.impulse_response``, the
  refinement's H) as a Toeplitz matrix, instead of the sample-by-sample central differences;
* ``stationary_px``: P_x the Toeplitz matrix of the exact posterior's middle rows (the same spectrum, no edges: the
  stationary error a frequency-domain or Toeplitz weighting assumes), negative eigenvalues clipped;
* ``welch_px``: P_x stationary and formed per frequency, R − R·(S_x + R)⁻¹·R, from the Welch spectrum of the same 300 s
  realisation (``input_noise_bound_spectrum.signal_spectrum``, Hann segments of four windows) instead of its raw
  autocovariance.

Printed: σ of D/D_real per row and the windows off by more than 20 %; JSON
``docs/results/input_noise_gls_form_dl<level>_<class>.json`` (per window).

    .venv/bin/python -m benchmarks.input_noise_gls_form [--n 40] [--level 3] [--cls 2]

Measurements: docs/numerics.md, "Stop 45: the bound with the inputs' spectrum learnt from the window".
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy import linalg  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, identify, input_weighting, motor  # noqa: E402
from aslm_core.information import (  # noqa: E402
    input_jacobian,
    input_noise_covariance,
    input_posterior_covariance,
    stationary_input_covariance,
)
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import CONFIRM_SEED, INPUT_NOISE, with_input_noise  # noqa: E402
from benchmarks.input_noise_bound import MODEL, gls, long_inputs, oracle_inputs, static_coefficients  # noqa: E402
from benchmarks.input_noise_bound_spectrum import signal_spectrum  # noqa: E402

ROWS = ("default", "oracle_gls", "lti_A", "stationary_px", "welch_px")


def lti_jacobian(case, shape: tuple[int, int]) -> np.ndarray:
    """∂[P; Q]/∂[V; θ] (2l × 2n) as the Toeplitz matrix of the model's impulse response at mid-window, at the truth."""
    clean, d = case.clean, np.asarray(case.truth.d, dtype=np.float64)
    prep = prepare(clean, max_gap_samples=MODEL.max_gap_samples, min_duration_s=MODEL.min_duration_s)
    pb = Problem(prep, clean.f0, MODEL)
    n, k0, l = prep.V.size, pb.k0, pb.l
    h = input_weighting.impulse_response(pb, d, *static_coefficients(case.truth))
    if h is None or shape != (2 * l, 2 * n):
        raise ValueError("the impulse response cannot be formed on this window")
    lead = motor.input_reach(pb.substeps) + 1
    lag = np.arange(l)[:, None] + k0 + lead - np.arange(n)[None, :]  # h[k]: k − lead samples after the impulse
    inside = (lag >= 0) & (lag < l)
    a = np.zeros(shape)
    for i in range(2):
        for j in range(2):
            a[i * l:(i + 1) * l, j * n:(j + 1) * n] = np.where(inside, h[np.clip(lag, 0, l - 1), i, j], 0.0)
    return a


def _psd_clipped(m: np.ndarray) -> np.ndarray:
    lam, vec = np.linalg.eigh(0.5 * (m + m.T))
    return (vec * np.maximum(lam, 0.0)) @ vec.T


def stationary_posterior(px: np.ndarray, n: int) -> np.ndarray:
    """The Toeplitz (per 2 × 2 block) matrix of the middle rows of a 2n × 2n posterior covariance, clipped to PSD."""
    mid = n // 2
    idx = mid + np.subtract.outer(np.arange(n), np.arange(n)) * -1  # (i, j) → column mid + (j − i) of row mid
    inside = (idx >= 0) & (idx < n)
    out = np.zeros_like(px)
    for i in range(2):
        for j in range(2):
            row = px[i * n + mid, j * n:(j + 1) * n]
            out[i * n:(i + 1) * n, j * n:(j + 1) * n] = np.where(inside, row[np.clip(idx, 0, n - 1)], 0.0)
    return _psd_clipped(out)


def welch_posterior(v: np.ndarray, theta: np.ndarray, n: int, noise_var: tuple[float, float]) -> np.ndarray:
    """The stationary P_x (2n × 2n) from the Welch spectrum of a long realisation: R − R·(S_x + R)⁻¹·R per frequency
    (= S_x − S_x·(S_x + R)⁻¹·S_x), its autocovariance by the inverse FFT on a 4n grid, clipped to PSD."""
    sx = signal_spectrum(v, theta, 4 * n)
    r = np.diag(np.asarray(noise_var, dtype=np.float64))
    pxf = sx - sx @ np.linalg.inv(sx + r) @ sx
    cov = np.fft.irfft(pxf, n=4 * n, axis=0)
    lag = np.subtract.outer(np.arange(n), np.arange(n)) % (4 * n)
    out = np.zeros((2 * n, 2 * n))
    for i in range(2):
        for j in range(2):
            out[i * n:(i + 1) * n, j * n:(j + 1) * n] = cov[lag, i, j]
    return _psd_clipped(out)


def window_rows(case, w, v_rel: float, th: float, long_s: float = 300.0) -> dict[str, list[float]]:
    """D/D_real of the default and of the oracle GLS with each ingredient (module docstring) on one noisy window."""
    clean, d = case.clean, np.asarray(case.truth.d, dtype=np.float64)
    n = clean.V.size
    a = input_jacobian(clean, d, *static_coefficients(case.truth), config=MODEL)
    v_long, th_long = long_inputs(case, long_s)
    prior = stationary_input_covariance(v_long, th_long, n)
    var = ((v_rel * float(np.mean(clean.V))) ** 2, th**2)
    px = input_posterior_covariance(var, n, prior)
    sv = (float(np.var(case.window.P - clean.P)), float(np.var(case.window.Q - clean.Q)))
    try:
        d0 = identify(w, config=IdentifyConfig()).d
    except WindowError:
        return {name: [np.nan] * 4 for name in ROWS}
    wx = oracle_inputs(w, prior, var)
    ingredients = {"oracle_gls": (a, px), "lti_A": (lti_jacobian(case, a.shape), px),
                   "stationary_px": (a, stationary_posterior(px, n)),
                   "welch_px": (a, welch_posterior(v_long, th_long, n, var))}
    out = {"default": (d0 / d).tolist()}
    for name, (aa, pp) in ingredients.items():
        try:
            chol = linalg.cholesky(input_noise_covariance(sv, aa, pp), lower=True)
            out[name] = (gls(wx, np.where(d0 > 0, d0, d), chol) / d).tolist()
        except (ValueError, linalg.LinAlgError):
            out[name] = [np.nan] * 4
    return out


def summary(per: dict[str, list]) -> dict[str, dict]:
    """Per row: windows answered, σ of D/D_real, windows off by more than 20 %."""
    out = {}
    for name, rows in per.items():
        r = np.array(rows)
        ok = np.all(np.isfinite(r), axis=1)
        out[name] = {"n": int(ok.sum()), "sigma": r[ok].std(axis=0, ddof=1).tolist(),
                     "off_20pct": int(np.sum(np.any(np.abs(r[ok] - 1.0) > 0.2, axis=1)))}
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="last window (default 40; --quick 2)")
    ap.add_argument("--first", type=int, default=0, help="first window")
    ap.add_argument("--level", type=int, default=3, choices=(1, 2, 3))
    ap.add_argument("--cls", type=int, default=2, choices=(1, 2), help="input noise class (1: 0.03 %%, 2: 0.1 %%)")
    args = ap.parse_args(argv)
    n = args.n or (2 if args.quick else 40)
    cls, v_rel, th = INPUT_NOISE[args.cls]
    cases = common.cases(n, level=args.level, seed=CONFIRM_SEED)
    # The draws of input_noise_bound: one generator per (level, class), drawn for every class of every window.
    rngs = [np.random.default_rng([CONFIRM_SEED, args.level, k]) for k in range(len(INPUT_NOISE))]
    per: dict[str, list] = {name: [] for name in ROWS}
    t0 = time.perf_counter()
    for i, case in enumerate(cases):
        ws = [with_input_noise(case.window, case.clean, vr, t, rngs[k]) for k, (_, vr, t) in enumerate(INPUT_NOISE)]
        if i < args.first:
            continue
        for name, r in window_rows(case, ws[args.cls], v_rel, th).items():
            per[name].append(r)
        if (i + 1) % 10 == 0:
            print(f"{i + 1} windows ({time.perf_counter() - t0:.0f} s)", flush=True)
    summ = summary(per)
    rows = [[name, s["n"], " / ".join(f"{x:.4f}" for x in s["sigma"]), s["off_20pct"]] for name, s in summ.items()]
    print(f"DL {args.level}, {cls}, windows {args.first}–{n - 1} of seed {CONFIRM_SEED}:\n")
    print(common.md_table(["row", "n", "σ a / b / H2 / Tm", "off > 20 %"], rows))
    out = {"machine": common.machine(), "seed": CONFIRM_SEED, "level": args.level, "class": cls, "first": args.first,
           "n": n, "summary": summ, "per_window": per, "total_s": time.perf_counter() - t0,
           "load_avg_at_end": list(os.getloadavg())}
    if not args.no_write:
        tag = f"_dl{args.level}_{'003' if args.cls == 1 else '01'}" + ("_quick" if args.quick else "")
        common.write_json("input_noise_gls_form" + tag, out)
    return out


if __name__ == "__main__":
    main()
