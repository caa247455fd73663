"""Can any estimator reach issue 11's learnt-spectrum bound on one 10 s window?  Maximum likelihood in the bound's own model.

``benchmarks.input_noise_bound_spectrum`` gives, per window, the Cramér–Rao bound of D when the inputs' signal spectrum
S_x is learnt from the same window (a Hermitian 2×2 relative deviation per band of 0.5 Hz, four real nuisance parameters
a band).  A Cramér–Rao bound is a large-sample statement: with ~5 rfft bins per band of a 10 s window, the nuisance
parameters are many for the data that estimate them, and the bound need not be reached by any estimator.  This benchmark
asks it of the bound's own model, where nothing else can go wrong: per window the frequency-domain model linearised about
the truth (``transfer``, ``signal_spectrum`` of that module: H(f) and ∂H/∂(a, b, H2, Tm, g_P, g_Q), the 300 s clean
realisation's S_x, the PMU class's R_u and the level's R_y), ``--draws`` draws of z = (V, θ, P, Q) per bin from
CN(0, Σ) at the truth, and on each draw the maximum-likelihood estimate (Whittle; Fisher scoring with a step search, from
the truth) of

* ``known``: the six parameters (a, b, H2, Tm and the static slopes) with S_x known;
* ``learnt``: the same with S_x's relative deviation unknown per band of :data:`WIDTH_HZ` (0.5 Hz, the reference of
  ``input_noise_bound_spectrum``).

Only the bins from the first up to :data:`TOP_HZ` (5 Hz, below the floor band) are used, by the estimates and by the
bounds they are compared with (computed here on those bins and bands, as ``input_noise_bound_spectrum``'s
``learnt_0.5_below_5hz`` kind, and the known bound on the same bins): above it the signal is orders of magnitude under the PMU floor and its spectrum's maximum likelihood sits
on the boundary, where no regular bound applies.  Reported per level and class: √(mean over windows of the estimate's
variance over the draws) over √(mean of the bound) for a / b / H2 / Tm, relative to D, for both kinds; a ratio near 1
for ``known`` checks the machinery (Monte Carlo error ~ 1/√(2·draws·windows)), and ``learnt``'s ratio is how far above the
learnt bound the best estimator of the spectrum-learning model stays on a window this long.  JSON
``docs/results/input_noise_bound_attain.json``.

``--windows``: the same maximum likelihood on the simulated windows themselves instead of draws from the model — the
joint likelihood over latent V and θ done in the frequency domain (issue 11's last candidate): per noisy window, H and
∂H at the default's D (its impulse responses through the compiled simulator, the static slopes from the plain fit
there, as the S-weighted refinement forms H), z the tapered DFT of the measured V, θ, P, Q over the regression samples
(``--taper tukey``: the 10 % Tukey taper of :mod:`aslm_core.noise`; ``hann``), R_u and R_y the window's floors, S_x
started from the window's own estimate, bins up to :data:`TOP_HZ`; D/D_real next to the default's on the same windows
and draws (``input_noise_bound``'s, ``--seed``), and per window how far the DFTs depart from the model's Y = H·X on the
clean record (the relative power of Y − H·X per band) against the time-domain linear model's departure.  JSON
``…_windows_<taper>.json``.

    .venv/bin/python -m benchmarks.input_noise_bound_attain [--n 20] [--draws 200] [--seed 53]
    .venv/bin/python -m benchmarks.input_noise_bound_attain --windows --n 100 --seed 41 [--taper tukey|hann]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import identify, input_weighting, noise, preprocess  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE, noisy_draws  # noqa: E402
from benchmarks.input_noise_bound import LEVELS, TAIL, long_inputs  # noqa: E402
from benchmarks.input_noise_bound_spectrum import _E, _sqrtm, signal_spectrum, transfer  # noqa: E402
from benchmarks.input_noise_variants import response_at  # noqa: E402

#: Band width of the learnt spectrum's nuisance [Hz] (the reference of ``input_noise_bound_spectrum``).
WIDTH_HZ = 0.5
#: Highest bin frequency used [Hz] (module docstring).
TOP_HZ = 5.0
#: Fisher-scoring iterations at most, and the step below which it stops (in units of each parameter's bound).
MAX_ITER = 60
TOL = 1e-4
#: Largest change of a band's relative spectrum in one step, as the magnitude of a log-eigenvalue [-].
STEP_LOG = 2.0
#: Seed of the windows; 53 was seen by ``input_noise_bound_spectrum`` (its bounds), not by any estimator choice.
SEED = 53


def sigma(h: np.ndarray, sx: np.ndarray, ru: np.ndarray, ry: np.ndarray) -> np.ndarray:
    """Per bin the covariance of z = (V, θ, P, Q): [[S_x + R_u, S_x·Hᴴ], [H·S_x, H·S_x·Hᴴ + R_y]], shape (m, 4, 4)."""
    hh = h.conj().transpose(0, 2, 1)
    s = np.empty((h.shape[0], 4, 4), dtype=complex)
    s[:, :2, :2] = sx + ru
    s[:, :2, 2:] = sx @ hh
    s[:, 2:, :2] = h @ sx
    s[:, 2:, 2:] = h @ sx @ hh + ry
    return s


def derivatives(h: np.ndarray, dh: np.ndarray, sx: np.ndarray, learnt: bool) -> list[np.ndarray]:
    """∂Σ per bin in the six parameters and (``learnt``) the four local directions root·E·root of S_x, root = S_x^½."""
    hh = h.conj().transpose(0, 2, 1)
    out = []
    for dha in dh:
        da = np.zeros(h.shape[:1] + (4, 4), dtype=complex)
        dah = dha.conj().transpose(0, 2, 1)
        da[:, :2, 2:] = sx @ dah
        da[:, 2:, :2] = dha @ sx
        da[:, 2:, 2:] = dha @ sx @ hh + h @ sx @ dah
        out.append(da)
    if learnt:
        root = _sqrtm(sx)
        for e in _E:
            ds = root @ e @ root
            da = np.zeros_like(out[0])
            da[:, :2, :2] = ds
            da[:, :2, 2:] = ds @ hh
            da[:, 2:, :2] = h @ ds
            da[:, 2:, 2:] = h @ ds @ hh
            out.append(da)
    return out


def loglik(z: np.ndarray, s: np.ndarray) -> float:
    """Σ_k −log det Σ_k − z_kᴴ·Σ_k⁻¹·z_k (complex Gaussian, constants dropped); −inf if some Σ_k is not positive."""
    try:
        c = np.linalg.cholesky(s)
    except np.linalg.LinAlgError:
        return -math.inf
    w = np.linalg.solve(c, z[:, :, None])[:, :, 0]
    return float(-2.0 * np.log(np.abs(np.diagonal(c, axis1=1, axis2=2))).sum() - (np.abs(w) ** 2).sum())


def score_and_fisher(z: np.ndarray, s: np.ndarray, ders: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Per bin the score ∂ℓ/∂θ (m, q) and the Fisher information tr(Σ⁻¹∂_iΣ·Σ⁻¹∂_jΣ) (m, q, q)."""
    inv = np.linalg.inv(s)
    a = [inv @ d for d in ders]
    iz = (inv @ z[:, :, None])[:, :, 0]
    q = len(ders)
    score = np.empty((s.shape[0], q))
    fisher = np.empty((s.shape[0], q, q))
    for i in range(q):
        score[:, i] = (-np.trace(a[i], axis1=1, axis2=2)
                       + np.einsum("ki,kij,kj->k", iz.conj(), ders[i], iz)).real
        for j in range(i, q):
            fisher[:, i, j] = fisher[:, j, i] = np.einsum("kij,kji->k", a[i], a[j]).real
    return score, fisher


def bands_of(freqs: np.ndarray, width_hz: float) -> np.ndarray:
    """Band index of each bin, bands of ``width_hz`` from the first bin (as ``band_loss``)."""
    return np.floor((freqs - freqs[0]) / width_hz + 1e-9).astype(int)


def reduced(score: np.ndarray, fisher: np.ndarray, band: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, dict]:
    """The six parameters' Schur-reduced score and information, the nuisance (per band, four each) profiled out; and
    per band what its nuisance step needs (its summed information, cross term and score)."""
    g, f = score[:, :6].sum(axis=0), fisher[:, :6, :6].sum(axis=0)
    parts = {}
    if band is not None:
        for b in np.unique(band):
            sel = band == b
            fpp = fisher[sel][:, 6:, 6:].sum(axis=0)
            ftp = fisher[sel][:, :6, 6:].sum(axis=0)
            sp = score[sel][:, 6:].sum(axis=0)
            inv = np.linalg.pinv(fpp, rcond=1e-12, hermitian=True)
            g = g - ftp @ inv @ sp
            f = f - ftp @ inv @ ftp.T
            parts[int(b)] = (inv, ftp, sp)
    return g, f, parts


def _trial(z: np.ndarray, h: np.ndarray, sx: np.ndarray, step: np.ndarray, alpha: float, dh: np.ndarray, eig: dict,
           band: np.ndarray | None, root: np.ndarray | None, ru: np.ndarray, ry: np.ndarray) -> tuple:
    """(log-likelihood, H, S_x, Σ) after α times the step: H moved along ∂H, each band's S_x by exp(α·ΔE) in its
    eigenbasis with the exponents clipped at ±STEP_LOG (``eig``: per band the eigenpairs of ΔE)."""
    h_t = h + np.tensordot(alpha * step, dh, axes=1)
    sx_t = sx
    if band is not None:
        rel = np.empty_like(sx)
        for b, (lam, vec) in eig.items():
            rel[band == b] = (vec * np.exp(np.clip(alpha * lam, -STEP_LOG, STEP_LOG))) @ vec.conj().T
        sx_t = root @ rel @ root
        sx_t = 0.5 * (sx_t + sx_t.conj().transpose(0, 2, 1))
    s_t = sigma(h_t, sx_t, ru, ry)
    return loglik(z, s_t), h_t, sx_t, s_t


def ml_fit(z: np.ndarray, freqs: np.ndarray, h0: np.ndarray, dh: np.ndarray, sx0: np.ndarray, ru: np.ndarray,
           ry: np.ndarray, learnt: bool) -> tuple[np.ndarray, bool]:
    """Maximum-likelihood deviation δ of the six parameters from where H0 was formed, on one draw (or window) z (m, 4):
    Fisher scoring from (H0, S_x0) with a step search (the comments in the loop); (δ, converged)."""
    band = bands_of(freqs, WIDTH_HZ) if learnt else None
    delta = np.zeros(6)
    h, sx = h0.copy(), sx0.copy()
    s = sigma(h, sx, ru, ry)
    ll = loglik(z, s)
    for _ in range(MAX_ITER):
        ders = derivatives(h, dh, sx, learnt)
        score, fisher = score_and_fisher(z, s, ders)
        g, f, parts = reduced(score, fisher, band)
        step = np.linalg.solve(f, g)
        sd = np.sqrt(np.maximum(np.diag(np.linalg.inv(f)), 1e-300))
        psi = {b: inv @ (sp - ftp.T @ step) for b, (inv, ftp, sp) in parts.items()}
        root = _sqrtm(sx) if learnt else None
        # Each band's relative update exp(α·ΔE) in its eigenbasis, the exponents clipped at ±STEP_LOG: always a
        # positive spectrum, and a band whose likelihood peaks on the boundary (a singular S_x) approaches it
        # geometrically instead of holding every other step back.
        eig = {b: np.linalg.eigh(np.tensordot(p, _E, axes=1)) for b, p in psi.items()}
        # The better of the full and the half step (scoring's expected information can overshoot the observed
        # curvature and alternate about the optimum), quartered while neither raises the likelihood.
        alpha, accepted = 1.0, False
        for _ in range(30):
            full, half = (_trial(z, h, sx, step, a, dh, eig, band, root, ru, ry) for a in (alpha, 0.5 * alpha))
            if max(full[0], half[0]) >= ll:
                if half[0] > full[0]:
                    alpha, full = 0.5 * alpha, half
                ll_t, h_t, sx_t, s_t = full
                accepted = True
                break
            alpha *= 0.25
        if not accepted:
            return delta, bool(np.all(np.abs(step) <= 1e3 * TOL * sd))
        delta = delta + alpha * step
        h, sx, s, ll = h_t, sx_t, s_t, ll_t
        if np.all(np.abs(alpha * step) <= TOL * sd):
            return delta, True
    return delta, False


def bound(h: np.ndarray, dh: np.ndarray, sx: np.ndarray, ru: np.ndarray, ry: np.ndarray, freqs: np.ndarray,
          learnt: bool) -> np.ndarray:
    """Cramér–Rao variances of the six parameters on these bins (the nuisance profiled out when ``learnt``)."""
    ders = derivatives(h, dh, sx, learnt)
    s = sigma(h, sx, ru, ry)
    inv = np.linalg.inv(s)
    a = [inv @ d for d in ders]
    q = len(ders)
    fisher = np.empty((s.shape[0], q, q))
    for i in range(q):
        for j in range(i, q):
            fisher[:, i, j] = fisher[:, j, i] = np.einsum("kij,kji->k", a[i], a[j]).real
    _, f, _ = reduced(np.zeros((s.shape[0], q)), fisher, bands_of(freqs, WIDTH_HZ) if learnt else None)
    return np.diag(np.linalg.inv(f))


def draws_of(s: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` draws of z ~ CN(0, Σ) per bin, shape (count, m, 4)."""
    c = np.linalg.cholesky(s)
    xi = (rng.standard_normal((count,) + s.shape[:2]) + 1j * rng.standard_normal((count,) + s.shape[:2])) / math.sqrt(2)
    return np.einsum("kij,nkj->nki", c, xi)


def window_cells(by_level: dict, draws: int, rng: np.random.Generator, long_s: float = 300.0) -> dict:
    """Per level and noisy class of one window: the bounds and the ML estimates' variance over the draws (relative to
    D², a / b / H2 / Tm) for both kinds, and how many fits did not converge."""
    case = by_level[LEVELS[0]]
    clean, d = case.clean, np.asarray(case.truth.d, dtype=np.float64)
    freqs, h, dh, l, _ = transfer(case)
    sx = signal_spectrum(*long_inputs(case, long_s), l)
    k = np.flatnonzero((freqs > 0) & (freqs <= TOP_HZ))
    freqs, h, dh, sx = freqs[k], h[k], dh[:, k], sx[k]
    out = {}
    for level, c in by_level.items():
        ry = np.diag([float(np.var(c.window.P - clean.P)), float(np.var(c.window.Q - clean.Q))]).astype(complex)
        for cls, v_rel, th in INPUT_NOISE[1:]:
            ru = np.diag([(v_rel * float(np.mean(clean.V))) ** 2, th**2]).astype(complex)
            zs = draws_of(sigma(h, sx, ru, ry), draws, rng)
            cell = {}
            for kind, learnt in (("known", False), ("learnt", True)):
                est, bad = [], 0
                for z in zs:
                    delta, conv = ml_fit(z, freqs, h, dh, sx, ru, ry, learnt)
                    bad += not conv
                    est.append(delta[:4])
                est = np.array(est)
                cell[kind] = {"bound": (bound(h, dh, sx, ru, ry, freqs, learnt)[:4] / d**2).tolist(),
                              "variance": (est.var(axis=0, ddof=1) / d**2).tolist(),
                              "mean": (est.mean(axis=0) / d).tolist(), "not_converged": bad}
            out[f"{level}|{cls}"] = cell
    return out


def summary(per_window: list[dict]) -> dict:
    """Per cell and kind: √(mean variance) / √(mean bound) per parameter, and the fits that did not converge."""
    out = {}
    for cell in per_window[0]:
        out[cell] = {}
        for kind in ("known", "learnt"):
            var = np.mean([w[cell][kind]["variance"] for w in per_window], axis=0)
            bnd = np.mean([w[cell][kind]["bound"] for w in per_window], axis=0)
            out[cell][kind] = {"ratio": np.sqrt(var / bnd).tolist(), "rms_bound": np.sqrt(bnd).tolist(),
                               "not_converged": int(sum(w[cell][kind]["not_converged"] for w in per_window))}
    return out


#: Bands over which ``--windows`` compares the DFTs with Y = H·X [Hz].
MISFIT_BANDS = ((0.0, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 5.0))


def taper_of(l: int, kind: str) -> np.ndarray:
    """The taper of l samples: ``tukey`` (:mod:`aslm_core.noise`'s 10 % Tukey) or ``hann``."""
    return noise._taper(l)[0] if kind == "tukey" else np.hanning(l)


def window_model(window, d: np.ndarray, skip_s: float, taper: str) -> tuple | None:
    """The frequency-domain model of a window at D: (freqs, z (m, 4), H, ∂H (6, m, 2, 2), R_u, R_y, S_x start), the
    DFTs normalised so that E|z|² is the per-sample spectrum; None where H cannot be formed (``--windows``)."""
    at = response_at(window, TAIL, d, skip_s)
    if at is None:
        return None
    _, pb, h = at
    resid = np.column_stack([pb.p_meas - pb._p[pb.k0:], pb.q_meas - pb._q[pb.k0:]])
    beta = np.linalg.solve(pb.r_factor, pb.basis.T @ resid)
    dh = np.zeros((6,) + h.shape)
    for j in range(4):
        e = np.zeros(4)
        e[j] = 1e-4 * max(abs(d[j]), 1e-3)
        hp = input_weighting.impulse_response(pb, d + e, beta[:, 0], beta[:, 1])
        hm = input_weighting.impulse_response(pb, d - e, beta[:, 0], beta[:, 1])
        if hp is None or hm is None:
            return None
        dh[j] = (hp - hm) / (2.0 * e[j])
    dh[4, 2, 0, 0] = dh[5, 2, 1, 0] = 1.0  # the static slopes act in the impulse's sample (h[k]: k − 2 after it)
    l, k0 = pb.l, pb.k0
    raw = preprocess.prepare(window, floors=True)
    x = np.stack([raw.V[k0:], raw.theta[k0:], raw.P[k0:], raw.Q[k0:]])
    tp = taper_of(l, taper)
    z = np.fft.rfft(noise._detrend(x) * tp, axis=1).T / math.sqrt(float(tp @ tp))
    freqs = np.fft.rfftfreq(l, pb.dt)
    delay = np.exp(2j * np.pi * 2.0 * np.arange(freqs.size) / l)  # undo h's two-sample lead
    hf = np.fft.rfft(h, axis=0) * delay[:, None, None]
    dhf = np.fft.rfft(dh, axis=1) * delay[None, :, None, None]
    fl = raw.noise
    ru = np.diag([fl["noise_v"] ** 2, fl["noise_theta"] ** 2]).astype(complex)
    ry = np.diag([fl["noise_p"] ** 2, fl["noise_q"] ** 2]).astype(complex)
    own = noise.pooled_spectrum([noise.input_periodogram(x[:2], 1.0 / pb.dt)], top_hz=TOP_HZ + noise.WIENER_SMOOTH_HZ)
    sx0 = noise.spectrum_at(own, freqs) + 0.1 * ru  # positive where the window's estimate is not
    return freqs, z, hf, dhf, ru, ry, sx0


def misfit(case, taper: str) -> tuple[list[float], float]:
    """On the clean record at the truth: the relative power of P's Y − H·X per :data:`MISFIT_BANDS` band of the tapered
    DFTs, and the time-domain linear model's relative error power (the convolution of h with the inputs' deviations,
    the window's samples before the regression its history)."""
    d = np.asarray(case.truth.d, dtype=np.float64)
    freqs, z, hf, _, _, _, _ = window_model(case.clean, d, 1.0, taper)
    y = np.einsum("kij,kj->ki", hf, z[:, :2])[:, 0]
    out = []
    for lo, hi in MISFIT_BANDS:
        sel = (freqs > lo) & (freqs <= hi)
        out.append(float(np.sum(np.abs(z[sel, 2] - y[sel]) ** 2) / np.sum(np.abs(z[sel, 2]) ** 2)))
    _, pb, h = response_at(case.clean, TAIL, d, 1.0)
    raw = preprocess.prepare(case.clean)
    n, k0 = raw.V.size, pb.k0
    dv, dth = raw.V - raw.V.mean(), raw.theta - raw.theta.mean()
    lin = np.zeros(n)
    for k in range(pb.l):  # y[t] = Σ_k h[k]·x[t − k + 2]
        s = k - 2
        src = slice(0, n - s) if s >= 0 else slice(-s, n)
        dst = slice(s, n) if s >= 0 else slice(0, n + s)
        lin[dst] += h[k, 0, 0] * dv[src] + h[k, 0, 1] * dth[src]
    a, b = noise._detrend(raw.P[k0:]), noise._detrend(lin[k0:])
    return out, float(np.sum((a - b) ** 2) / np.sum(a**2))


def windows_run(n: int, seed: int, taper: str) -> dict:
    """``--windows`` (module docstring): per level and noisy class the per-window D/D_real of the default and of the
    maximum likelihood on the window's DFTs, and per window the model's misfit on the clean record."""
    cases = {level: common.cases(n, level=level, seed=seed) for level in LEVELS}
    per: dict[str, dict[str, list]] = {}
    mis = [misfit(cases[LEVELS[-1]][i], taper) for i in range(n)]
    for _, level, cls, c, w in noisy_draws(cases, seed, n, LEVELS):
        r = identify(w, config=TAIL)
        cell = per.setdefault(f"{level}|{cls}", {"default": [], "window_ml": []})
        cell["default"].append((r.d / c.truth.d).tolist())
        model = window_model(w, r.d, float(r.quality.get("skip_s", 1.0)), taper)
        if model is None:
            cell["window_ml"].append([math.nan] * 4)
            continue
        freqs, z, hf, dhf, ru, ry, sx0 = model
        sel = (freqs > 0) & (freqs <= TOP_HZ)
        delta, _ = ml_fit(z[sel], freqs[sel], hf[sel], dhf[:, sel], sx0[sel], ru, ry, True)
        cell["window_ml"].append(((r.d + delta[:4]) / c.truth.d).tolist())
    return {"per_window": per, "misfit": mis}


def windows_report(run: dict) -> None:
    """Print σ and μ of D/D_real per cell and estimator, and the misfit's medians and ranges."""
    rows = []
    for cell, est in run["per_window"].items():
        for name, r in est.items():
            r = np.array(r)
            ok = np.all(np.isfinite(r), axis=1)
            rows.append([*cell.split("|"), name, " / ".join(f"{x:.3f}" for x in r[ok].std(axis=0, ddof=1)),
                         " / ".join(f"{x:.3f}" for x in r[ok].mean(axis=0)), str(int((~ok).sum()))])
    print(common.md_table(["DL", "input noise", "estimator", "σ a / b / H2 / Tm", "μ", "refused"], rows))
    bands = np.array([m[0] for m in run["misfit"]])
    td = np.array([m[1] for m in run["misfit"]])
    print("P's |Y − H·X|² / |Y|² on the clean records, median [min, max]: "
          + ", ".join(f"{lo:g}–{hi:g} Hz {np.median(bands[:, j]):.2g} [{bands[:, j].min():.2g}, {bands[:, j].max():.2g}]"
                      for j, (lo, hi) in enumerate(MISFIT_BANDS))
          + f"; time-domain linear model {np.median(td):.2g} [{td.min():.2g}, {td.max():.2g}]")


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows (default 20; --quick 1)")
    ap.add_argument("--draws", type=int, default=None, help="draws per window and cell (default 200; --quick 20)")
    ap.add_argument("--seed", type=int, default=SEED, help=f"windows (default {SEED})")
    ap.add_argument("--windows", action="store_true", help="the maximum likelihood on the windows' own DFTs")
    ap.add_argument("--taper", choices=("tukey", "hann"), default="tukey", help="--windows: the DFTs' taper")
    args = ap.parse_args(argv)
    if args.windows:
        n = args.n or (2 if args.quick else 100)
        t0 = time.perf_counter()
        run = windows_run(n, args.seed, args.taper)
        windows_report(run)
        out = {"machine": common.machine(), "n": n, "seed": args.seed, "taper": args.taper, "top_hz": TOP_HZ, **run,
               "total_s": time.perf_counter() - t0, "load_avg_at_end": list(os.getloadavg())}
        if not args.no_write:
            common.write_json(f"input_noise_bound_attain_windows_{args.taper}" + ("_quick" if args.quick else ""), out)
        return out
    n = args.n or (1 if args.quick else 20)
    draws = args.draws or (20 if args.quick else 200)
    cases = {level: common.cases(n, level=level, seed=args.seed) for level in LEVELS}
    rng = np.random.default_rng([args.seed, 11])
    t0 = time.perf_counter()
    per_window = []
    for i in range(n):
        per_window.append(window_cells({level: cases[level][i] for level in LEVELS}, draws, rng))
        print(f"{i + 1} windows ({time.perf_counter() - t0:.0f} s)", flush=True)
    summ = summary(per_window)
    head = ["DL", "input noise", "RMS bound known", "σ ML / bound known", "RMS bound learnt", "σ ML / bound learnt",
            "not converged"]
    rows = [[*cell.split("|"), " / ".join(f"{x:.4f}" for x in r["known"]["rms_bound"]),
             " / ".join(f"{x:.2f}" for x in r["known"]["ratio"]),
             " / ".join(f"{x:.4f}" for x in r["learnt"]["rms_bound"]),
             " / ".join(f"{x:.2f}" for x in r["learnt"]["ratio"]),
             f"{r['known']['not_converged']} / {r['learnt']['not_converged']}"] for cell, r in summ.items()]
    print(common.md_table(head, rows))
    out = {"machine": common.machine(), "n": n, "draws": draws, "seed": args.seed, "width_hz": WIDTH_HZ,
           "top_hz": TOP_HZ, "summary": summ, "per_window": per_window, "total_s": time.perf_counter() - t0,
           "load_avg_at_end": list(os.getloadavg())}
    if not args.no_write:
        common.write_json("input_noise_bound_attain" + ("_quick" if args.quick else ""), out)
    return out


if __name__ == "__main__":
    main()
