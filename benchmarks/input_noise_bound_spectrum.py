"""Issue 11's bound with the inputs' spectrum known, and with it learnt from the window: the frequency-domain form.

``benchmarks.input_noise_bound`` holds the Cramér–Rao bound of D with noisy V and θ when the inputs' signal spectrum is
known (the *structural* bound, in the time domain).  No estimator that runs on a window knows that spectrum: it learns
it from the same 10 s.  This benchmark computes, on the same windows (seed 43, the first ``--n``; the same clean
records, P and Q noise per level, PMU classes), the bound in the frequency domain, where the spectrum can be made a
nuisance parameter:

Per window, linearised about the truth (mid-window operating point, as the S-weighted refinement forms it), each rfft
bin k = 1 … l/2 − 1 of the regression samples holds z = (V, θ, P, Q), complex Gaussian with

    Σ(f) = [[S_x + R_u,  S_x·Hᴴ], [H·S_x,  H·S_x·Hᴴ + R_y]]

H(f; D, g) the model's [P; Q] response to [V; θ] (the motor by the compiled simulator's impulse response and its
forward sensitivities ∂/∂D; the static part its slope g on V, a nuisance), S_x the inputs' true signal cross-spectrum
(Welch, Hann segments of the regression length, over a 300 s clean realisation of the same load and network:
``input_noise_bound.long_inputs``), R_u the PMU class's white noise, R_y the P and Q noise injected at the level.
The Fisher information Σ_k tr(Σ⁻¹ ∂_iΣ Σ⁻¹ ∂_jΣ) (Whittle) gives

* ``known``: the bound with S_x known (the joint likelihood of V, θ, P, Q);
* ``known_mean``: its part through the conditional mean of P, Q given V, θ only — what the time-domain structural
  bound counts (it leaves out the information in S's own dependence on D), the check of this form against it;
* ``learnt_<w>``: the bound with S_x unknown in bands of w Hz: per band a Hermitian 2×2 relative deviation
  S_x^{1/2}·(I + E_b)·S_x^{1/2} (four real nuisance parameters a band) estimated from the same data.  An estimator that
  assumes of the spectrum only that it is smooth over w Hz cannot beat it; one that assumes more (a parametric shape)
  could.  **0.5 Hz is the reference** (the width the default's smoother averages the window's spectrum over,
  ``noise.WIENER_SMOOTH_HZ``), fixed with this docstring before any figure of it was seen (2026-12-03); 0.25, 1 and
  2 Hz are shown as the sensitivity to that choice;
* ``learnt_0.5_band``, ``learnt_0.5_below_5hz``: the reference over the bins up to a tenth of the rate (the S-weighted
  refinement's band) and below 5 Hz only (added after the first runs, as a sensitivity: how much information lies where
  the identifier's model departs from the data).

Reported per level and class: RMS relative bound (√ mean var/D²) of each kind and, on seed 43, the time-domain structural
bound of the same windows (``input_noise_bound_n300.json``); σ of the default and of the oracle GLS (that file's
per-window D) over each bound, and per estimator and kind the noisy cells × parameters within 1.3 × (issue 11's honest
version); JSON ``docs/results/input_noise_bound_spectrum.json``.  ``--seed`` other than 43 runs the default here on
``input_noise_bound``'s draws for that seed (no oracle, no time-domain bound; JSON ``…_seed<seed>.json``).

    .venv/bin/python -m benchmarks.input_noise_bound_spectrum [--n 300] [--long-s 300] [--seed 43]

``--efficiency`` (stop 46): window by window instead of over the cell.  From the JSON of an earlier run of the same seed
(its per-window reference bounds), the default is run again with its standard errors, and per level and class are
printed: the RMS over the windows of z = (D/D_real − 1) / (the window's own reference bound), over all of them and over
the 90 % with the smallest largest |z|; the median standard error over the bound; and the share of the cell's summed
squared error that the other 10 % carry.  An efficient estimator has z of unit spread in every window; σ over the RMS
bound also weighs the windows by their bound.  JSON ``…_efficiency_seed<seed>.json``.

    .venv/bin/python -m benchmarks.input_noise_bound_spectrum --efficiency --seed 53
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from aslm_core import IdentifyConfig, WindowError, identify, input_weighting, motor, noise, static  # noqa: E402
from aslm_core.preprocess import prepare  # noqa: E402
from aslm_core.problem import Problem  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import CONFIRM_SEED, INPUT_NOISE, noisy_draws, with_input_noise  # noqa: E402
from benchmarks.input_noise_bound import LEVELS, MODEL, long_inputs, static_coefficients  # noqa: E402

#: Nuisance band widths of the learnt spectrum [Hz]; the first is the reference (module docstring).
WIDTHS_HZ = (0.5, 0.25, 1.0, 2.0)
#: The reference the honest count is taken against, and its band width [Hz].
REFERENCE = "learnt_0.5"
REFERENCE_HZ = 0.5


def transfer(case, d: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float]:
    """H(f) of the model on the case's clean window at D (default the truth's) and its derivatives.

    Returns
    -------
    freqs : ndarray, shape (m,)
        rfft bin frequencies of the regression samples [Hz].
    h : ndarray, shape (m, 2, 2)
        [P; Q] per [V; θ] (the static part's slope included) [pu/pu, pu/rad].
    dh : ndarray, shape (6, m, 2, 2)
        ∂H/∂(a, b, H2, Tm, g_P, g_Q), g the static slopes of P and Q on V (nuisance).
    l : int
        Regression samples.
    fs : float
        Sample rate [Hz].
    """
    clean = case.clean
    d = np.asarray(case.truth.d if d is None else d, dtype=np.float64)
    prep = prepare(clean, max_gap_samples=MODEL.max_gap_samples, min_duration_s=MODEL.min_duration_s)
    pb = Problem(prep, clean.f0, MODEL)
    n, k0, l = prep.V.size, pb.k0, pb.l
    j = k0 + l // 2
    p, q, xs = np.empty(n), np.empty(n), np.empty((n, 3))
    dp, dq = np.empty((n, 4)), np.empty((n, 4))

    def run(v: np.ndarray, th: np.ndarray) -> np.ndarray:
        vd, vq, vdm, vqm = motor.dq_inputs(v, th, pb.substeps)
        if not motor.simulate_kernel(vd, vq, vdm, vqm, d, pb.dt, pb.omega0, pb.rk4, True, p, q, dp, dq, xs, True,
                                     k0, pb.p_meas, pb.q_meas, dp):
            raise ValueError("the model cannot be simulated at this D on this window")
        # (samples from j − 2, [P, Q, ∂P/∂D…, ∂Q/∂D…])
        return np.column_stack([p[j - 2:], q[j - 2:], dp[j - 2:], dq[j - 2:]])

    resp = np.zeros((l, 10, 2))
    base = (prep.V, prep.theta)
    step = input_weighting.IMPULSE_STEP
    for c in range(2):
        up, down = base[c].copy(), base[c].copy()
        up[j] += step
        down[j] -= step
        hi = run(up, base[1]) if c == 0 else run(base[0], up)
        lo = run(down, base[1]) if c == 0 else run(base[0], down)
        resp[: n - j + 2, :, c] = (hi - lo) / (2.0 * step)
    bp, bq = static_coefficients(case.truth)
    vj = np.array([float(np.mean(prep.V[k0:]))])
    dphi = (static.regressors(vj + step, MODEL.static) - static.regressors(vj - step, MODEL.static))[0]
    dphi /= 2.0 * step
    resp[2, 0, 0] += float(dphi @ bp)
    resp[2, 1, 0] += float(dphi @ bq)
    f = np.fft.rfft(resp, axis=0)  # (m, 10, 2)
    h = f[:, 0:2, :]
    dh = np.zeros((6,) + h.shape, dtype=complex)
    dh[:4, :, 0, :] = np.moveaxis(f[:, 2:6, :], 1, 0)
    dh[:4, :, 1, :] = np.moveaxis(f[:, 6:10, :], 1, 0)
    unit = np.fft.rfft(np.eye(l)[2])  # the static slope acts in the impulse's sample
    dh[4, :, 0, 0] = unit
    dh[5, :, 1, 0] = unit
    return np.fft.rfftfreq(l, prep.dt), h, dh, l, 1.0 / prep.dt


def signal_spectrum(v: np.ndarray, theta: np.ndarray, l: int) -> np.ndarray:
    """The inputs' cross-spectral matrix on the rfft bins of l samples, per-sample units (white noise of variance σ²
    is flat at σ²): Welch, Hann segments of l, half overlap, each detrended linearly [pu², pu·rad, rad²]."""
    x = np.stack([v, theta])
    w = np.hanning(l)
    t = np.arange(l) - 0.5 * (l - 1)
    acc, count = 0.0, 0
    for s in range(0, x.shape[1] - l + 1, l // 2):
        seg = x[:, s:s + l]
        seg = seg - seg.mean(axis=1, keepdims=True)
        seg = seg - np.outer(seg @ t / (t @ t), t)
        spec = np.fft.rfft(seg * w, axis=1)
        acc = acc + np.einsum("if,jf->fij", spec, spec.conj())
        count += 1
    return acc / (count * float(w @ w))


def _sqrtm(s: np.ndarray) -> np.ndarray:
    """Hermitian square root per bin (negative eigenvalues clipped)."""
    lam, vec = np.linalg.eigh(s)
    return (vec * np.sqrt(np.maximum(lam, 0.0))[:, None, :]) @ vec.conj().transpose(0, 2, 1)


_E = np.array([[[1, 0], [0, 0]], [[0, 0], [0, 1]], [[0, 1], [1, 0]], [[0, 1j], [-1j, 0]]], dtype=complex)


def fisher_per_bin(h: np.ndarray, dh: np.ndarray, sx: np.ndarray, r_u: tuple[float, float],
                   r_y: tuple[float, float]) -> np.ndarray:
    """Per bin the Fisher information tr(Σ⁻¹ ∂_iΣ Σ⁻¹ ∂_jΣ) of z = (V, θ, P, Q) ~ CN(0, Σ) (module docstring) in the
    parameters (a, b, H2, Tm, g_P, g_Q) and the four relative-deviation directions of S_x at that bin.

    Parameters
    ----------
    h : ndarray, shape (m, 2, 2)
        [P; Q] per [V; θ].
    dh : ndarray, shape (6, m, 2, 2)
        ∂H per parameter.
    sx : ndarray, shape (m, 2, 2)
        The inputs' signal cross-spectrum, per-sample units.
    r_u, r_y : (float, float)
        White noise variances of V, θ and of P, Q, per sample.

    Returns
    -------
    ndarray, shape (m, 10, 10)
    """
    m = h.shape[0]
    ru, ry = np.diag(r_u).astype(complex), np.diag(r_y).astype(complex)
    hh = h.conj().transpose(0, 2, 1)
    sig = np.empty((m, 4, 4), dtype=complex)
    sig[:, :2, :2] = sx + ru
    sig[:, :2, 2:] = sx @ hh
    sig[:, 2:, :2] = h @ sx
    sig[:, 2:, 2:] = h @ sx @ hh + ry
    inv = np.linalg.inv(sig)
    ders = []
    for a in range(dh.shape[0]):
        da = np.zeros((m, 4, 4), dtype=complex)
        dha = dh[a]
        da[:, :2, 2:] = sx @ dha.conj().transpose(0, 2, 1)
        da[:, 2:, :2] = dha @ sx
        da[:, 2:, 2:] = dha @ sx @ hh + h @ sx @ dha.conj().transpose(0, 2, 1)
        ders.append(inv @ da)
    root = _sqrtm(sx)
    for e in _E:
        ds = root @ e @ root
        da = np.zeros((m, 4, 4), dtype=complex)
        da[:, :2, :2] = ds
        da[:, :2, 2:] = ds @ hh
        da[:, 2:, :2] = h @ ds
        da[:, 2:, 2:] = h @ ds @ hh
        ders.append(inv @ da)
    q = len(ders)
    per_bin = np.empty((m, q, q))
    for a in range(q):
        for b in range(a, q):
            per_bin[:, a, b] = per_bin[:, b, a] = np.einsum("kij,kji->k", ders[a], ders[b]).real
    return per_bin


def bounds(freqs: np.ndarray, h: np.ndarray, dh: np.ndarray, sx: np.ndarray, r_u: tuple[float, float],
           r_y: tuple[float, float], d: np.ndarray, widths: tuple[float, ...] = WIDTHS_HZ) -> dict[str, np.ndarray]:
    """Relative bound variances var/D² of (a, b, H2, Tm) by kind (module docstring) from one window's H, ∂H, S_x on
    the rfft bins ``freqs`` [Hz] (DC and Nyquist left out)."""
    k = np.arange(1, freqs.size - 1)
    f, h, dh, sx = freqs[k], h[k], dh[:, k], sx[k]
    per_bin = fisher_per_bin(h, dh, sx, r_u, r_y)
    theta = slice(0, 6)
    full = per_bin[:, theta, theta].sum(axis=0)
    out = {"known": _d_block(full) / d**2}
    # Through the conditional mean of P, Q given V, θ only: 2·Re tr(Q⁻¹·∂H·C·∂Hᴴ), C = S_x·(S_x + R_u)⁻¹·S_x,
    # Q = H·P_x·Hᴴ + R_y, P_x = S_x − C.
    ru, ry = np.diag(r_u).astype(complex), np.diag(r_y).astype(complex)
    c = sx @ np.linalg.inv(sx + ru) @ sx
    qinv = np.linalg.inv(h @ (sx - c) @ h.conj().transpose(0, 2, 1) + ry)
    mean = np.empty((6, 6))
    for a in range(6):
        for b in range(a, 6):
            v = 2.0 * np.einsum("kij,kjl,kli->k", qinv, dh[a] @ c, dh[b].conj().transpose(0, 2, 1)).real.sum()
            mean[a, b] = mean[b, a] = v
    out["known_mean"] = _d_block(mean) / d**2
    for w in widths:
        out[f"learnt_{w:g}"] = _d_block(full - band_loss(per_bin, f, w)) / d**2
    # The reference counting only the bins the S-weighted refinement fits (up to a tenth of the rate), and only those
    # below the floor band (5 Hz): how much of the information lies where the identifier's model departs from the data.
    fs = 2.0 * freqs[-1]
    for name, top in (("band", input_weighting.BAND_FRACTION * fs), ("below_5hz", noise.FLOOR_FROM_HZ)):
        sel = f <= top
        part = per_bin[sel]
        out[f"{REFERENCE}_{name}"] = _d_block(part[:, theta, theta].sum(axis=0)
                                              - band_loss(part, f[sel], REFERENCE_HZ)) / d**2
    return out


def band_loss(per_bin: np.ndarray, freqs: np.ndarray, width_hz: float) -> np.ndarray:
    """The information on (a, b, H2, Tm, g_P, g_Q) lost when S_x's relative deviation is unknown per band of
    ``width_hz`` [Hz] (bands from the first bin): Σ_b I_θψ·I_ψψ⁻¹·I_ψθ over the bands' summed per-bin information."""
    band = np.floor((freqs - freqs[0]) / width_hz + 1e-9).astype(int)
    loss = np.zeros((6, 6))
    for b in np.unique(band):
        blk = per_bin[band == b].sum(axis=0)
        cross = blk[:6, 6:]
        loss += cross @ np.linalg.pinv(blk[6:, 6:], rcond=1e-12, hermitian=True) @ cross.T
    return loss


def _d_block(info: np.ndarray) -> np.ndarray:
    """diag of the (a, b, H2, Tm) block of the inverse information (the static slopes a nuisance)."""
    return np.diag(np.linalg.inv(info))[:4].copy()


def window_bounds(by_level: dict, long_s: float) -> dict:
    """One window's relative bound variances per level, class and kind."""
    case = by_level[LEVELS[0]]
    clean, d = case.clean, np.asarray(case.truth.d, dtype=np.float64)
    freqs, h, dh, l, fs = transfer(case)
    sx = signal_spectrum(*long_inputs(case, long_s), l)
    out = {}
    for level, c in by_level.items():
        r_y = (float(np.var(c.window.P - clean.P)), float(np.var(c.window.Q - clean.Q)))
        out[level] = {}
        for cls, v_rel, th in INPUT_NOISE[1:]:
            r_u = ((v_rel * float(np.mean(clean.V))) ** 2, th**2)
            for kind, var in bounds(freqs, h, dh, sx, r_u, r_y, d).items():
                out[level][f"{cls}|{kind}"] = var.tolist()
    return out


def summary(per_window: list[dict], time_domain: dict | None, own: list[dict] | None = None) -> dict:
    """Per level and class: RMS relative bound of each kind, and σ over each bound of the estimators whose per-window
    D/D_real are at hand: the default and the oracle GLS of ``input_noise_bound --n 300`` (seed 43's windows, with its
    time-domain structural bound), else the default run here (``own``: per window {level: {class: D/D_real}})."""
    n = len(per_window)
    td = time_domain["per_window_relative_variance"][:n] if time_domain else None
    if time_domain:
        est = {name: [{lv: {c: r[j] for c, r in e[str(lv)].items()} for lv in LEVELS}
                      for e in time_domain["per_window_ratio"][:n]] for j, name in enumerate(ESTIMATORS)}
    else:
        est = {"default": own} if own else {}
    out = {}
    for level in LEVELS:
        for cls, _, _ in INPUT_NOISE[1:]:
            kinds = [k.split("|", 1)[1] for k in per_window[0][level] if k.startswith(cls + "|")]
            row = {kind: np.sqrt(np.mean([w[level][f"{cls}|{kind}"] for w in per_window], axis=0)).tolist()
                   for kind in kinds}
            if td is not None:
                row["time_domain_structural"] = np.sqrt(np.mean([w[str(level)][f"{cls}|structural"] for w in td],
                                                                axis=0)).tolist()
            for name, per in est.items():
                r = np.array([e[level][cls] for e in per])
                ok = np.all(np.isfinite(r), axis=1)
                sigma = r[ok].std(axis=0, ddof=1)
                row[f"sigma_{name}"] = sigma.tolist()
                for kind in (["time_domain_structural"] if td is not None else []) + kinds:
                    row[f"sigma_{name}_over_{kind}"] = (sigma / np.array(row[kind])).tolist()
            out[f"{level}|{cls}"] = row
    return out


#: The estimators whose per-window D ``input_noise_bound --n 300`` stores, in its order.
ESTIMATORS = ("default", "oracle_gls")


def default_ratios(cases: dict, seed: int, n: int) -> list[dict]:
    """Per window {level: {class: D/D_real}} of the default (``IdentifyConfig()``) on the noise draws of
    ``input_noise_bound`` for ``seed`` (one generator per level and class, drawn for every class of every window);
    NaN where it refuses the window."""
    rngs = {(level, k): np.random.default_rng([seed, level, k]) for level in LEVELS for k in range(len(INPUT_NOISE))}
    out = []
    for i in range(n):
        row: dict = {}
        for level in LEVELS:
            c = cases[level][i]
            row[level] = {}
            for k, (cls, v_rel, th) in enumerate(INPUT_NOISE):
                w = with_input_noise(c.window, c.clean, v_rel, th, rngs[level, k])
                if cls == "none":
                    continue
                try:
                    row[level][cls] = (identify(w, config=IdentifyConfig()).d / c.truth.d).tolist()
                except WindowError:
                    row[level][cls] = [math.nan] * 4
        out.append(row)
    return out


def honest_counts(summ: dict) -> dict[str, dict[str, int]]:
    """Per estimator and bound kind: the noisy cells × parameters (of 24) with σ ≤ 1.3 × that bound."""
    first = next(iter(summ.values()))
    names = [k[len("sigma_"):] for k in first if k.startswith("sigma_") and "_over_" not in k]
    out = {}
    for name in names:
        kinds = [k.split("_over_", 1)[1] for k in first if k.startswith(f"sigma_{name}_over_")]
        out[name] = {kind: sum(int(np.sum(np.array(r[f"sigma_{name}_over_{kind}"]) <= 1.3)) for r in summ.values())
                     for kind in kinds}
    return out


def _cells(row: dict, key: str, fmt: str = "{:.3f}") -> str:
    return " / ".join(fmt.format(x) for x in row[key])


def report(summ: dict) -> dict | None:
    """Print the bound table, the σ over the bounds and the honest count against each kind; the counts."""
    first = next(iter(summ.values()))
    kinds = [k for k in ["time_domain_structural", "known_mean", "known"] + [f"learnt_{w:g}" for w in WIDTHS_HZ]
             if k in first]
    head = ["DL", "input noise"] + [f"{k} a / b / H2 / Tm" for k in kinds]
    rows = [[*key.split("|")] + [_cells(row, k) for k in kinds] for key, row in summ.items()]
    print(common.md_table(head, rows))
    names = [k[len("sigma_"):] for k in first if k.startswith("sigma_") and "_over_" not in k]
    if not names:
        return None
    cols = [k for k in ("time_domain_structural", "known", REFERENCE) if k in first]
    head = ["DL", "input noise"] + [f"σ {e}" for e in names] + [f"{e} / {k}" for e in names for k in cols]
    rows = [[*key.split("|")] + [_cells(r, f"sigma_{e}") for e in names]
            + [_cells(r, f"sigma_{e}_over_{k}", "{:.2f}") for e in names for k in cols] for key, r in summ.items()]
    print("\n" + common.md_table(head, rows))
    counts = honest_counts(summ)
    for name, per in counts.items():
        print(f"{name}: σ ≤ 1.3 × bound in " + ", ".join(f"{k} {v}" for k, v in per.items()) + " of 24")
    return counts


#: ``--efficiency``: the share of windows counted as the tail [-].
TAIL_SHARE = 0.1


def efficiency(per_window_bounds: list[dict], cases: dict, seed: int) -> dict:
    """``--efficiency`` (module docstring): per level and class, from the windows' reference bounds and the default's D
    and standard errors on ``input_noise_bound``'s draws for ``seed``, the figures the module docstring lists."""
    z: dict[str, list] = {}
    se: dict[str, list] = {}
    var: dict[str, list] = {}
    for i, level, cls, c, w in noisy_draws(cases, seed, len(per_window_bounds), LEVELS):
        bvar = np.array(per_window_bounds[i][str(level)][f"{cls}|{REFERENCE}"])
        bound = np.sqrt(bvar)
        try:
            r = identify(w, config=IdentifyConfig())
        except WindowError:
            continue
        truth = np.asarray(c.truth.d, dtype=np.float64)
        z.setdefault(f"{level}|{cls}", []).append(((r.d / truth - 1.0) / bound).tolist())
        var.setdefault(f"{level}|{cls}", []).append(bvar.tolist())
        se.setdefault(f"{level}|{cls}", []).append((np.array([r.stderr[p] for p in common.PARAMS]) / truth / bound).tolist())
    out = {}
    for cell, zs in z.items():
        zs = np.array(zs)
        worst = np.abs(zs).max(axis=1)
        keep = worst <= np.quantile(worst, 1.0 - TAIL_SHARE)
        sq = zs**2 * np.array(var[cell])  # the squared relative errors
        out[cell] = {"n": int(len(zs)), "rms_z": np.sqrt(np.mean(zs**2, axis=0)).tolist(),
                     "rms_z_best": np.sqrt(np.mean(zs[keep] ** 2, axis=0)).tolist(),
                     "median_se_over_bound": np.median(np.array(se[cell]), axis=0).tolist(),
                     "tail_share_of_squared_error": (sq[~keep].sum(axis=0) / sq.sum(axis=0)).tolist()}
    return out


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="windows (default 300; --quick 3)")
    ap.add_argument("--long-s", type=float, default=300.0, help="length of the clean realisation [s]")
    ap.add_argument("--seed", type=int, default=CONFIRM_SEED,
                    help=f"windows and draws (default {CONFIRM_SEED}: the default's and the oracle GLS's D from "
                         "input_noise_bound --n 300; another seed runs the default here, without the oracle)")
    ap.add_argument("--efficiency", action="store_true",
                    help="window by window, from the stored JSON of the same seed (module docstring)")
    args = ap.parse_args(argv)
    n = args.n or (3 if args.quick else 300)
    if args.efficiency:
        stored = json.loads((common.RESULTS / ("input_noise_bound_spectrum"
                                               + ("" if args.seed == CONFIRM_SEED else f"_seed{args.seed}")
                                               + ".json")).read_text())
        n = min(n, len(stored["per_window_relative_variance"]))
        t0 = time.perf_counter()
        eff = efficiency(stored["per_window_relative_variance"][:n],
                         {level: common.cases(n, level=level, seed=args.seed) for level in LEVELS}, args.seed)
        keys = ("rms_z", "rms_z_best", "median_se_over_bound", "tail_share_of_squared_error")
        print(common.md_table(["DL", "input noise", "n"] + [f"{k} a / b / H2 / Tm" for k in keys],
                              [[*cell.split("|"), str(r["n"])] + [_cells(r, k, "{:.2f}") for k in keys]
                               for cell, r in eff.items()]))
        out = {"machine": common.machine(), "n": n, "seed": args.seed, "reference": REFERENCE,
               "tail_share": TAIL_SHARE, "cells": eff, "total_s": time.perf_counter() - t0,
               "load_avg_at_end": list(os.getloadavg())}
        if not args.no_write:
            common.write_json(f"input_noise_bound_spectrum_efficiency_seed{args.seed}", out)
        return out
    td_path = common.RESULTS / "input_noise_bound_n300.json"
    time_domain = json.loads(td_path.read_text()) if td_path.exists() and args.seed == CONFIRM_SEED else None
    if time_domain is not None and len(time_domain["per_window_relative_variance"]) < n:
        time_domain = None
    cases = {level: common.cases(n, level=level, seed=args.seed) for level in LEVELS}
    own = default_ratios(cases, args.seed, n) if time_domain is None else None
    t0 = time.perf_counter()
    per_window = []
    for i in range(n):
        per_window.append(window_bounds({level: cases[level][i] for level in LEVELS}, args.long_s))
        if (i + 1) % 25 == 0:
            print(f"{i + 1} windows ({time.perf_counter() - t0:.0f} s)", flush=True)
    summ = summary(per_window, time_domain, own)
    counts = report(summ)
    out = {"machine": common.machine(), "n": n, "seed": args.seed, "long_s": args.long_s,
           "widths_hz": list(WIDTHS_HZ), "reference": REFERENCE, "summary": summ, "honest_counts": counts,
           "per_window_relative_variance": per_window, "per_window_default": own,
           "total_s": time.perf_counter() - t0, "load_avg_at_end": list(os.getloadavg())}
    if not args.no_write:
        common.write_json("input_noise_bound_spectrum" + ("" if args.seed == CONFIRM_SEED else f"_seed{args.seed}")
                          + ("_quick" if args.quick else ""), out)
    return out


if __name__ == "__main__":
    main()
