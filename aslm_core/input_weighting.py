"""S-weighted refinement of D for windows whose inputs V and θ are noisy (``input_weighting="spectral"``).

With noisy inputs the model's output carries the smoothed inputs' error x − x̂ through the model: the
disturbance of [P; Q] is S = Σ_v + A·P_x·Aᵀ, not white (:mod:`aslm_core.information`), and the efficient
estimator weights the residuals by S⁻¹.  Over a window the load model is nearly time-invariant, so per
frequency f that covariance is the 2×2 spectrum

    S(f) = diag(σ_P², σ_Q²) + H(f)·P_x(f)·H(f)ᴴ,

H(f) the model's response of (P, Q) to (V, θ) at the current D (the Fourier transform of its impulse
responses, by finite differences through the compiled simulator, the static part's slope added), P_x(f) the
Wiener smoother's error spectrum (:func:`aslm_core.noise.wiener_smooth`) and σ_P, σ_Q the floors of P and Q
(their white level under the floor band's own falling content, :func:`aslm_core.noise.output_floors`, and at most what the
residual reads inside the fitted band, :func:`white_at_most_residual`); its diagonal is floored by the output-error
residual's smoothed periodogram (the true inputs' content beyond the smoother's cut-off, which P_x leaves out, still
drives P and Q).  The residuals, their D-Jacobian and the static regressors are tapered (against the DFT's leakage into bins
where S is small) and taken to the frequency domain (an orthonormal DFT), whitened per frequency by S(f)^(−1/2) (the inverse of its Cholesky factor), the static part is
projected out after whitening, and D is refined by Levenberg–Marquardt steps under the box and equilibrium
constraint (:func:`aslm_core.optimize.qp_step`) on the Wiener-smoothed V, θ and the measured P, Q (no
low-pass: the weighting takes its place), over the bins up to a tenth of the reporting rate (above it the
simulator's cubic interpolation of the inputs departs from their content and biased D at coarse rates).  Standard errors from the whitened problem's information, scaled
by the whitened residual's variance.  Given the inputs' spectrum of the bus's history, whose P_x is good enough to
drop the floor, the fit whitens in the time domain below 5 Hz without it, and is redone with it where the whitened
residual's χ² says S understates the residual (:data:`HISTORY_BAND_HZ`, :data:`HISTORY_CHI2_MAX`).  Measurements:
docs/numerics.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy import signal

from aslm_core import input_history, levinson, motor, optimize, static
from aslm_core.noise import FLOOR_FROM_HZ, OUTPUT_FLOOR_KEYS, InputSpectrum, input_periodogram, reflected_mean
from aslm_core.preprocess import Prepared, prepare, white_floor
from aslm_core.problem import Problem
from aslm_core.window import Window

#: Size of the single-sample perturbation whose response gives H [pu for V, rad for θ].
IMPULSE_STEP = 1e-4
#: Levenberg–Marquardt iterations of the refinement (per estimate of H).
MAX_ITER = 12
#: Estimates of H (at the output-error D; a second one at the refined D changed σ by under 5 % on development windows).
ROUNDS = 1
#: Tukey taper of the regression samples before the DFT (fraction of the window tapered) [-].
TAPER = 0.1
#: Width of the moving average over the residual's periodogram that floors S's diagonal [Hz].
RESIDUAL_SMOOTH_HZ = 1.0
#: Highest frequency the fit uses, as a fraction of the reporting rate [-]: where the simulator's cubic
#: interpolation of the inputs between samples is within ~0.5 % of a sinusoid's amplitude (5 % at 0.2).
BAND_FRACTION = 0.1
#: Above 0: the band reaches at least this frequency [Hz] where :data:`MAX_BAND_FRACTION` of the rate allows it (4 Hz
#: at 25 and 30 frames/s, where the smoothed inputs' signal reaches 3.4–4 Hz: docs/numerics.md, "Stop 42").  Tried at
#: 4 Hz at stop 49 with ``noise.GAIN_WITHOUT_OWN_BIN`` and not adopted ("Stop 49"); 0: a tenth of the rate everywhere.
MIN_BAND_HZ = 0.0
#: The band's top at most this fraction of the rate when :data:`MIN_BAND_HZ` raises it (the interpolation's limit) [-].
MAX_BAND_FRACTION = 0.16
#: The window's own S-weighted fit (the ``spectral`` form without a history) uses the bins up to this frequency at most
#: [Hz]: above the smoother's cut-off (3.4–4 Hz at every rate, "Stop 42") the smoothed V is no longer the conditional
#: mean (at 50 frames/s / 0.1 %: 0.87 of it at 3–3.5 Hz, 0.62 at 3.5–4, 0.48 at 4–5), and those bins pulled a and Tm
#: low (without them 0.3–0.8 % higher at 50–120 frames/s / 0.1 %).  Adopted at stop 49 on its confirmation
#: (docs/numerics.md, "Stop 49: the band at most 4 Hz"); 25 and 30 frames/s fit 2.5 and 3 Hz, as before.  inf: a
#: tenth of the rate, as before stop 49.
MAX_BAND_HZ = 4.0
#: Candidate of stop 50 (off): the window's own ``spectral`` fit reaches past :data:`MAX_BAND_HZ` up to V's signal
#: cut-off in the window's own spectrum (before the tail; ``Prepared.signal_cutoffs``), still at most a tenth of the
#: rate: the band follows where each recording's V carries signal (medians 4.0 and 5.6 Hz on the project's generator
#: at 0.1 % and 0.03 %, 5.2 and 7.4 Hz on ANDES's records).
BAND_AT_CUTOFF = False
#: With the inputs' spectrum of the bus's history (``identify(..., input_spectrum=)``, pooled unsmoothed by
#: :class:`aslm_core.input_history.InputHistory`), the refinement whitens in the time domain on the bins below this
#: frequency (where that spectrum is known: it is zero from the floor band up) or a tenth of the rate, the lower,
#: without the residual floor: the history's smoother error P_x is good enough for S to stand without it
#: (docs/numerics.md, "Stop 47") [Hz].  None: the window's own form, with a history too.
HISTORY_BAND_HZ: float | None = FLOOR_FROM_HZ
#: That form's guard: where its whitened residual's mean square χ² exceeds this, S without the floor understates the
#: window's residual (the history misses input error the window has) and the fit is redone with the floor.  About
#: 5 standard deviations of χ² at 100 frames/s; it refits ~8 % of noisy windows [-].  None: no guard.
HISTORY_CHI2_MAX: float | None = 1.5
#: S's white P and Q variances at most what the residual's periodogram reads inside the fitted band (its median over
#: ln 2, per sample): the residual there is the white noise plus the inputs' propagated error, so it bounds the white
#: part from above.  It bites where the floor band misreads P's noise by several times, as with an M-class PMU at
#: 25 frames/s, whose raised floor holds the motor's own content (docs/numerics.md, "Stop 58").  False: as before stop 58.
WHITE_AT_MOST_RESIDUAL = True
#: The fewest bins of the band below which :data:`WHITE_AT_MOST_RESIDUAL` leaves the white levels as they are.
WHITE_AT_MOST_RESIDUAL_BINS = 8
#: ``temporal`` form: S above the band is multiplied by this, so the whitened fit all but ignores those frequencies
#: (the spectral form gives them weight zero, which a covariance cannot) [-].
BAND_DOWNWEIGHT = 1e4


@dataclass
class Weighting:
    """The per-frequency whitening of one window's [P; Q] residuals.

    ``w``: per rfft bin of the regression samples, the lower-triangular W = L⁻¹ with S = L·Lᴴ, as its
    entries (w00, w10, w11) [1/pu], zero above the band the fit uses; ``nuisance``: the whitened static
    regressors in the stacked real representation (:func:`_stack`) and ``gram_inv`` the inverse of their Gram
    matrix (the projection off them); ``samples``: the real degrees of freedom per channel the kept bins
    hold (the regression length when every bin is kept).  ``whitener``: the ``temporal`` form's square root of the
    inverse of the time-major [P; Q] disturbance covariance over the regression samples (2l × 2l, lower-triangular,
    :func:`aslm_core.levinson.whitening_matrix`) [1/pu], which then whitens in place of ``w``; None for the spectral
    form.
    """

    w: tuple[np.ndarray, np.ndarray, np.ndarray]
    nuisance: np.ndarray
    gram_inv: np.ndarray
    samples: float
    whitener: np.ndarray | None = None

    def whiten(self, xp: np.ndarray, xq: np.ndarray) -> np.ndarray:
        """The columns xp (P's rows) and xq (Q's rows), time along axis 0, whitened: a sum of squares over the
        rows of the result is the quadratic form in S⁻¹."""
        if self.whitener is not None:
            return levinson.whitened(self.whitener, levinson.interleaved(xp, xq))
        return _stack(self.w, xp, xq, bin_weights(xp.shape[0]))

    def project(self, z: np.ndarray) -> np.ndarray:
        """z with its component in the whitened static regressors' span removed."""
        return z - self.nuisance @ (self.gram_inv @ (self.nuisance.T @ z))


def fitted_band_hz(dt: float, capped: bool = True) -> float:
    """Highest frequency the S-weighted refinement fits at the sample step ``dt`` [Hz]: :data:`BAND_FRACTION` of the
    rate (2.5 Hz at 25 frames/s, 10 Hz at 100), raised to :data:`MIN_BAND_HZ` where :data:`MAX_BAND_FRACTION` of the
    rate allows it, and with ``capped`` at most :data:`MAX_BAND_HZ` (4 Hz from 40 frames/s up).

    Parameters
    ----------
    dt : float
        Sample step of the window [s] (the reciprocal of the reporting rate).
    capped : bool
        The window's own ``spectral`` form (the default); False for the ``temporal`` form and a history's, whose bands
        were set without the cap.

    Returns
    -------
    float
        The band's top [Hz].
    """
    band = max(BAND_FRACTION / dt, min(MIN_BAND_HZ, MAX_BAND_FRACTION / dt))
    return min(band, MAX_BAND_HZ) if capped else band


def bin_weights(l: int) -> np.ndarray:
    """√(multiplicity) of each rfft bin of l samples: the real stacking of the one-sided DFT then keeps the
    sum of squares of the time series (Parseval with ``norm="ortho"``)."""
    m = np.full(l // 2 + 1, math.sqrt(2.0))
    m[0] = 1.0
    if l % 2 == 0:
        m[-1] = 1.0
    return m


def impulse_response(problem, d: np.ndarray, beta_p: np.ndarray, beta_q: np.ndarray) -> np.ndarray | None:
    """The model's [P; Q] response to a unit impulse of V and of θ at one sample, on the regression grid.

    Parameters
    ----------
    problem : aslm_core.problem.Problem
        The window (its inputs, integrator and regression samples).
    d : ndarray
        D = [a, b, H2, Tm].
    beta_p, beta_q : ndarray
        Static coefficients of P and Q on the configured regressors [pu].

    Returns
    -------
    ndarray, shape (l, 2, 2), or None
        h[k, i, j]: output i (P, Q) k − r − 1 samples after an impulse of input j (V [pu], θ [rad]) in the middle
        of the regression samples, r the inputs' interpolation's reach back (:func:`aslm_core.motor.input_reach`)
        [pu/pu, pu/rad]; zero-padded to the regression length.  None when the model cannot be simulated.
    """
    pb = problem
    n, k0, l = pb.prep.V.size, pb.k0, pb.l
    lead = motor.input_reach(pb.substeps) + 1
    j = k0 + l // 2  # mid-window: the operating point the response is taken at is the typical one
    p, q = np.empty(n), np.empty(n)
    dp, dq, xs = np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 3))

    def output(v: np.ndarray, th: np.ndarray) -> np.ndarray | None:
        vd, vq, vdm, vqm = motor.dq_inputs(v, th, pb.substeps)
        if not motor.simulate_kernel(vd, vq, vdm, vqm, d, pb.dt, pb.omega0, pb.rk4, False, p, q, dp, dq, xs, True,
                                     k0, pb.p_meas, pb.q_meas, dp):
            return None
        return np.stack([p[j - lead:], q[j - lead:]], axis=1)

    h = np.zeros((l, 2, 2))
    base = (pb.prep.V, pb.prep.theta)
    for c in range(2):
        up, down = base[c].copy(), base[c].copy()
        up[j] += IMPULSE_STEP
        down[j] -= IMPULSE_STEP
        hi = output(up, base[1]) if c == 0 else output(base[0], up)
        lo = output(down, base[1]) if c == 0 else output(base[0], down)
        if hi is None or lo is None:
            return None
        h[: n - j + lead, :, c] = (hi - lo) / (2.0 * IMPULSE_STEP)
    # The static part responds to V in the same sample only, with its slope at the window's mean V (it moves
    # with V; the motor's response is taken at sample j).
    vj = np.array([float(np.mean(pb.prep.V[k0:]))])
    model = pb.config.static
    dphi = (static.regressors(vj + IMPULSE_STEP, model) - static.regressors(vj - IMPULSE_STEP, model))[0]
    dphi /= 2.0 * IMPULSE_STEP
    h[lead, 0, 0] += float(dphi @ beta_p)
    h[lead, 1, 0] += float(dphi @ beta_q)
    return h


def disturbance_spectrum(h: np.ndarray, freqs: np.ndarray, px_freqs: np.ndarray, px: np.ndarray,
                         white_var: tuple[float, float]) -> np.ndarray:
    """S(f) = diag(σ_P², σ_Q²) + H(f)·P_x(f)·H(f)ᴴ at the rfft bins of the regression samples.

    Parameters
    ----------
    h : ndarray, shape (l, 2, 2)
        Impulse responses (:func:`impulse_response`).
    freqs : ndarray
        Frequencies of the bins [Hz].
    px_freqs, px : ndarray
        The input error's spectrum (:func:`aslm_core.noise.wiener_smooth`, per-sample units), interpolated
        linearly onto ``freqs``.
    white_var : (float, float)
        White noise variance of P and Q [pu²].

    Returns
    -------
    ndarray, shape (m, 2, 2), complex
        Per bin the Hermitian covariance spectrum of the [P; Q] disturbance, per-sample units [pu²].
    """
    hf = np.fft.rfft(h, axis=0)  # (m, 2, 2)

    def at(a: int, b: int) -> np.ndarray:
        return np.interp(freqs, px_freqs, px[:, a, b].real) + 1j * np.interp(freqs, px_freqs, px[:, a, b].imag)

    p00, p01, p11 = at(0, 0).real, at(0, 1), at(1, 1).real
    s = np.empty((freqs.size, 2, 2), dtype=complex)
    # Row i of H·P_x·Hᴴ against row k, P_x Hermitian: Σ_ab H_ia·P_ab·conj(H_kb).
    for i in range(2):
        for k in range(i, 2):
            hi0, hi1, hk0, hk1 = hf[:, i, 0], hf[:, i, 1], hf[:, k, 0], hf[:, k, 1]
            s[:, i, k] = (hi0 * p00 * hk0.conj() + hi0 * p01 * hk1.conj() + hi1 * p01.conj() * hk0.conj()
                          + hi1 * p11 * hk1.conj())
    s[:, 1, 0] = s[:, 0, 1].conj()
    s[:, 0, 0] = s[:, 0, 0].real + white_var[0]
    s[:, 1, 1] = s[:, 1, 1].real + white_var[1]
    return s


def whitening(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entries (w00, w10, w11) of W = L⁻¹ per bin, S = L·Lᴴ its Cholesky factor (W·S·Wᴴ = I)."""
    l00 = np.sqrt(np.maximum(s[:, 0, 0].real, 1e-300))
    l10 = s[:, 1, 0] / l00
    l11 = np.sqrt(np.maximum(s[:, 1, 1].real - np.abs(l10) ** 2, 1e-12 * s[:, 1, 1].real + 1e-300))
    return 1.0 / l00, -l10 / (l00 * l11), 1.0 / l11


def temporal_lags(s: np.ndarray, l: int) -> np.ndarray:
    """The autocovariance of the [P; Q] disturbance from its spectrum S on the rfft bins of 2l samples
    (:func:`temporal_covariance`'s ``s``): c[τ, i, k] = E[x_i(t + τ)·x_k(t)] at lags 0 … 2l − 1, the negative lags
    wrapped to 2l − |τ| [pu²], shape (2l, 2, 2)."""
    return np.fft.irfft(s, n=2 * l, axis=0)


def temporal_covariance(s: np.ndarray, l: int) -> np.ndarray:
    """The stacked [P; Q] covariance over l consecutive samples that the disturbance spectrum S implies.

    Parameters
    ----------
    s : ndarray, shape (l + 1, 2, 2), complex
        S at the rfft bins of 2l samples (:func:`disturbance_spectrum` on the doubled grid), per-sample units
        [pu²]: its lags then reach the window's whole length without wrapping onto each other.
    l : int
        Regression samples.

    Returns
    -------
    ndarray, shape (2l, 2l)
        Block-Toeplitz: entry (i·l + a, k·l + b) is E[x_i(a)·x_k(b)] = c_ik(a − b), c_ik the inverse transform
        of S_ik [pu²].
    """
    c = temporal_lags(s, l)
    lag = np.subtract.outer(np.arange(l), np.arange(l)) % (2 * l)
    return np.block([[c[lag, 0, 0], c[lag, 0, 1]], [c[lag, 1, 0], c[lag, 1, 1]]])


@lru_cache(maxsize=32)
def _taper_of(l: int, fraction: float) -> np.ndarray:
    """The symmetric Tukey taper of l samples, as a column (ones without a taper)."""
    return (signal.get_window(("tukey", fraction), l, fftbins=False) if fraction > 0 else np.ones(l))[:, None]


def _taper(l: int) -> np.ndarray:
    """:data:`TAPER`'s taper of l samples, shape (l, 1)."""
    return _taper_of(l, TAPER)


def _stack(w: tuple[np.ndarray, np.ndarray, np.ndarray], xp: np.ndarray, xq: np.ndarray,
           mult: np.ndarray) -> np.ndarray:
    """Whitened real representation of the columns xp (P's rows) and xq (Q's rows), time along axis 0.

    Each column pair goes to the frequency domain (orthonormal DFT), is multiplied per bin by W, and the real
    and imaginary parts of both whitened channels are stacked (bins weighted by ``mult``), so that a sum of
    squares over the rows is the whitened quadratic form of the time series.
    """
    f = np.fft.rfft(np.hstack([xp, xq]) * _taper(xp.shape[0]), axis=0, norm="ortho") * mult[:, None]
    fp, fq = f[:, : xp.shape[1]], f[:, xp.shape[1]:]
    zp = w[0][:, None] * fp
    zq = w[1][:, None] * fp + w[2][:, None] * fq
    return np.concatenate([zp.real, zp.imag, zq.real, zq.imag], axis=0)


def build_weighting(problem, d: np.ndarray, input_error: tuple[np.ndarray, np.ndarray],
                    white_var: tuple[float, float], band_hz: float = math.inf,
                    form: str = "spectral", residual_floor: bool = True) -> Weighting | None:
    """The window's whitening at D: H at D and the static coefficients of the plain fit there, the bins
    above ``band_hz`` [Hz] given zero weight (``form="temporal"``: S there multiplied by
    :data:`BAND_DOWNWEIGHT`).  ``form``: ``spectral`` whitens per rfft bin of the tapered samples, ``temporal``
    by a square root of the inverse covariance S implies over the samples (:func:`temporal_covariance`; no taper,
    no circular wrap).  ``residual_floor``: S's diagonal floored by the residual's periodogram smoothed over
    :data:`RESIDUAL_SMOOTH_HZ` (if positive).  None when the model cannot be simulated at D or that covariance is
    not positive definite."""
    pb = problem
    if not _simulate(pb, d):
        return None
    k0 = pb.k0
    resid = np.column_stack([pb.p_meas - pb._p[k0:], pb.q_meas - pb._q[k0:]])
    beta = np.linalg.solve(pb.r_factor, pb.basis.T @ resid)
    h = impulse_response(pb, d, beta[:, 0], beta[:, 1])
    if h is None:
        return None
    freqs = np.fft.rfftfreq(pb.l, pb.dt)
    temporal = form == "temporal"
    floored = residual_floor and RESIDUAL_SMOOTH_HZ > 0
    if floored or WHITE_AT_MOST_RESIDUAL:
        resid -= pb.basis @ (pb.basis.T @ resid)
        fr = np.fft.rfft(resid * _taper(pb.l), axis=0, norm="ortho")
        if WHITE_AT_MOST_RESIDUAL:
            white_var = white_at_most_residual(white_var, fr, freqs, band_hz, pb.l)
    # The temporal form reads S on the doubled grid: its covariance's lags then span the window unwrapped.
    grid = np.fft.rfftfreq(2 * pb.l, pb.dt) if temporal else freqs
    hz = np.concatenate([h, np.zeros_like(h)]) if temporal else h
    s = disturbance_spectrum(hz, grid, *input_error, white_var)
    if floored:
        width = max(1, int(round(RESIDUAL_SMOOTH_HZ * pb.l * pb.dt)))
        kernel = np.ones(2 * (width // 2) + 1) / (2 * (width // 2) + 1)
        for c in range(2):
            pr = reflected_mean(fr[:, c].real ** 2 + fr[:, c].imag ** 2, kernel)
            if temporal:
                pr = np.interp(grid, freqs, pr)
            s[:, c, c] += np.maximum(pr - s[:, c, c].real, 0.0)
    # Above the band the model's interpolated inputs depart from the smoothed samples' content (the
    # interpolation's error grows as a power of f·dt) and the error correlates with the inputs: it biased D
    # at 25–30 frames/s, the unweighted fit on the same inputs as much (docs/numerics.md).
    keep = freqs <= band_hz
    mult = bin_weights(pb.l)
    samples = float(np.sum(mult[keep] ** 2))
    phi = pb.basis
    zero = np.zeros_like(phi)
    if temporal:
        s[grid > band_hz] *= BAND_DOWNWEIGHT
        # The covariance over the window is block-Toeplitz: the Levinson recursion factors it in O(l²), where a
        # dense Cholesky factor takes O(l³).
        whitener = levinson.whitening_matrix(temporal_lags(s, pb.l)[:pb.l])
        if whitener is None:
            return None
        nuis = levinson.whitened(whitener, levinson.interleaved(np.hstack([phi, zero]), np.hstack([zero, phi])))
        return Weighting((), nuis, np.linalg.inv(nuis.T @ nuis), samples, whitener)
    w = tuple(x * keep for x in whitening(s))
    nuis = _stack(w, np.hstack([phi, zero]), np.hstack([zero, phi]), mult)
    return Weighting(w, nuis, np.linalg.inv(nuis.T @ nuis), samples)


def white_at_most_residual(white_var: tuple[float, float], resid_f: np.ndarray, freqs: np.ndarray,
                           band_hz: float, samples: int) -> tuple[float, float]:
    """P's and Q's white variances for S, each at most the level the residual reads inside the fitted band.

    Inside the band the residual of P (Q) is its white noise plus the inputs' error propagated through H, so its
    periodogram's median over ln 2 (a χ²₂ ordinate's median is ln 2 × its mean) bounds the white part from above.  The
    floor band's reading can exceed that bound several times where the band holds the channel's own content (an
    M-class PMU at 25 frames/s; docs/numerics.md, "Stop 58").

    Parameters
    ----------
    white_var : (float, float)
        P's and Q's white variances from the floors [pu², per sample].
    resid_f : ndarray, shape (m, 2), complex
        The orthonormal DFT of the tapered residual of P and Q, the static part projected out.
    freqs : ndarray, shape (m,)
        The bins' frequencies [Hz].
    band_hz : float
        The fitted band's top [Hz].
    samples : int
        The residual's length, tapered by :func:`_taper` before its DFT.

    Returns
    -------
    (float, float)
        The variances, each the smaller of its floor's and the band's reading [pu², per sample]; unchanged where the
        band has fewer than :data:`WHITE_AT_MOST_RESIDUAL_BINS` bins.
    """
    inside = (freqs > 0.0) & (freqs <= band_hz)
    if int(inside.sum()) < WHITE_AT_MOST_RESIDUAL_BINS:
        return white_var
    gain = float(np.mean(_taper(samples) ** 2))  # the taper's loss of power
    level = np.median(resid_f[inside].real ** 2 + resid_f[inside].imag ** 2, axis=0) / (math.log(2.0) * gain)
    return tuple(min(w, float(x)) for w, x in zip(white_var, level, strict=True))


def _simulate(pb, d: np.ndarray) -> bool:
    """The motor with its D-sensitivities at d into the problem's buffers."""
    return bool(motor.simulate_kernel(pb.vd, pb.vq, pb.vdm, pb.vqm, d, pb.dt, pb.omega0, pb.rk4, True, pb._p, pb._q,
                                      pb._dp, pb._dq, pb._x, True, pb.k0, pb.p_meas, pb.q_meas, pb._dp))


def whitened_residuals(problem, d: np.ndarray, weighting: Weighting) -> tuple[np.ndarray, np.ndarray] | None:
    """Whitened residual ẽ = P⊥·W·(y − m(D)) and Jacobian J̃ = P⊥·W·∂m/∂D, the static part projected out
    after whitening (stacked real form).  None when the model cannot be simulated at d."""
    pb = problem
    pb.evaluations += 1
    if not _simulate(pb, d):
        return None
    k0 = pb.k0
    xp = np.column_stack([pb.p_meas - pb._p[k0:], pb._dp[k0:]])
    xq = np.column_stack([pb.q_meas - pb._q[k0:], pb._dq[k0:]])
    z = weighting.project(weighting.whiten(xp, xq))
    if not np.all(np.isfinite(z)):
        return None
    return z[:, 0], z[:, 1:]


def _descend(problem, d0: np.ndarray, weighting: Weighting, margin: float) -> dict:
    """Levenberg–Marquardt on ½‖ẽ‖² from d0 under the box and the linearised equilibrium constraint."""
    pb = problem
    d = np.array(d0, dtype=np.float64)
    ev = whitened_residuals(pb, d, weighting)
    if ev is None:
        return {"d": d, "cost": math.inf, "iterations": 0}
    e, jac = ev
    cost = 0.5 * float(e @ e)
    lam, nu = 1e-3, 2.0
    work, vec, ivec = np.empty((4, 4)), np.empty((3, 4)), np.empty((3, 4), dtype=np.int64)
    step, gc = np.empty(4), np.empty(4)
    it = 0
    for it in range(1, MAX_ITER + 1):
        a = jac.T @ jac
        g = -(jac.T @ e)
        gc[:] = (pb.v_min**2 * (1.0 - margin), -2.0 * d[3], 0.0, -2.0 * d[1])
        c_d = gc[0] * d[0] - 2.0 * d[1] * d[3]
        dmax = float(np.max(np.diag(a)))
        improved = False
        for _ in range(10):
            m = a + lam * np.diag(np.maximum(np.diag(a), 1e-12 * dmax + 1e-300))
            if not optimize.qp_step(m, g, d, pb.lower, pb.upper, gc, c_d, step, work, vec, ivec):
                lam *= nu
                nu *= 2.0
                continue
            pred = -float(g @ step) - 0.5 * float(step @ a @ step)
            if pred <= 1e-10 * cost:
                return {"d": d, "cost": cost, "iterations": it, "e": e, "jac": jac}
            trial = np.minimum(np.maximum(d + step, pb.lower), pb.upper)
            if not pb.feasible(trial):
                # The constraint is bilinear: back onto it along Tm (as the kernel does).
                trial[3] = min(trial[3], (1.0 - margin) * trial[0] * pb.v_min**2 / (2.0 * trial[1]) * (1.0 - 1e-9))
            if not pb.feasible(trial):
                lam *= nu
                nu *= 2.0
                continue
            ev = whitened_residuals(pb, trial, weighting)
            cost_t = 0.5 * float(ev[0] @ ev[0]) if ev is not None else math.inf
            if cost_t < cost:
                # Nielsen's damping update from the gain ratio, as the output-error kernel.
                gain = min(1.0, (cost - cost_t) / pred)
                d, (e, jac), cost = trial, ev, cost_t
                lam, nu = lam * max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3), 2.0
                improved = True
                break
            lam *= nu
            nu *= 2.0
        if not improved:
            break
        if np.all(np.abs(step) <= 1e-7 * (np.abs(d) + 1e-3)):
            break
    return {"d": d, "cost": cost, "iterations": it, "e": e, "jac": jac}


def refine(prep: Prepared, f0: float, config, d0: np.ndarray, skip_s: float, margin: float,
           history: bool = False) -> dict | None:
    """D refined by the S-weighted fit from the output-error D (module docstring).

    Parameters
    ----------
    prep : Prepared
        The window with Wiener-smoothed V, θ, measured P, Q (no low-pass) and the smoother's error spectrum
        (``input_error``) and floors (``noise``).
    f0 : float
        Nominal frequency [Hz].
    config : IdentifyConfig
    d0 : ndarray
        The output-error D (feasible).
    skip_s : float
        Samples skipped at the start [s] (the output-error fit's).
    margin : float
        Equilibrium margin of the feasible set (``identify.EQUILIBRIUM_MARGIN``).
    history : bool
        The smoother used the inputs' spectrum of the bus's history: the fit then takes :data:`HISTORY_BAND_HZ`'s
        form (time domain, the bins below it, no residual floor) instead of the configured one, redone with the
        floor where its χ² exceeds :data:`HISTORY_CHI2_MAX`.

    Returns
    -------
    dict or None
        ``d``, ``cost`` (½‖ẽ‖²), ``iterations``, ``cov`` (4×4 covariance of D), ``chi2`` (the whitened
        residual's mean square, ~1 when S is right), ``problem`` (the refinement's
        :class:`~aslm_core.problem.Problem`, its buffers at D); None when H cannot be formed or the
        whitened information is singular.
    """

    pb = Problem(prep, f0, replace(config, skip_s=skip_s))
    own = not (history and HISTORY_BAND_HZ)
    band = fitted_band_hz(pb.dt, capped=own and config.input_weighting == "spectral")
    if own and config.input_weighting == "spectral" and prep.signal_cutoffs is not None:
        band = min(fitted_band_hz(pb.dt, capped=False), max(band, float(prep.signal_cutoffs[0])))
    form, floor = config.input_weighting, True
    if not own:
        band, form, floor = min(band, math.nextafter(HISTORY_BAND_HZ, 0.0)), "temporal", False
    out = _weighted_descent(pb, prep, d0, margin, band, form, floor)
    if out is not None and not floor and HISTORY_CHI2_MAX and out["chi2"] > HISTORY_CHI2_MAX:
        again = _weighted_descent(pb, prep, d0, margin, band, form, True)
        if again is not None:
            again["iterations"] += out["iterations"]
            out = again
    return out


def _weighted_descent(pb: Problem, prep: Prepared, d0: np.ndarray, margin: float, band: float, form: str,
                      floor: bool) -> dict | None:
    """:func:`refine`'s fit in one form (:func:`build_weighting`'s ``band_hz``, ``form``, ``residual_floor``) from d0;
    its dict, or None."""
    white = tuple(prep.noise[f"noise_{c}"] ** 2 for c in ("p", "q"))
    d = np.array(d0, dtype=np.float64)
    iters = 0
    out = None
    for _ in range(ROUNDS):
        weighting = build_weighting(pb, d, prep.input_error, white, band, form, floor)
        if weighting is None:
            return None
        out = _descend(pb, d, weighting, margin)
        if not math.isfinite(out["cost"]):
            return None
        iters += out["iterations"]
        d = out["d"]
    e, jac = out["e"], out["jac"]
    dof = max(2 * weighting.samples - 4 - 2 * pb.basis.shape[1], 1)
    chi2 = float(e @ e) / dof
    try:
        cov = np.linalg.inv(jac.T @ jac) * chi2
    except np.linalg.LinAlgError:
        return None
    return {"d": d, "cost": out["cost"], "iterations": iters, "cov": cov, "chi2": chi2, "problem": pb}


def noisy_inputs(floors: dict[str, float]) -> bool:
    """Whether V or θ carries white PMU noise by the smoother's rule (:func:`aslm_core.preprocess.white_floor`,
    and a positive floor); exact inputs are left to the output-error fit."""
    return any(f"floor_tilt_{c}" in floors and white_floor(floors, c) and floors.get(f"noise_{c}", 0.0) > 0.0
               for c in ("v", "theta"))


def weighted_fit(window: Window, config, d0: np.ndarray, skip_s: float, floors: dict[str, float],
                 margin: float, input_spectrum: InputSpectrum | None = None) -> dict | None:
    """The S-weighted refinement of an identification, or None where it does not apply or fails.

    Parameters
    ----------
    window : Window
        The measured window.
    config : IdentifyConfig
    d0 : ndarray
        The output-error D.
    skip_s : float
        Samples skipped at the start by the output-error fit [s].
    floors : dict
        The window's noise floors (``Prepared.noise``): the refinement runs only with noisy inputs
        (:func:`noisy_inputs`), and weighs P and Q by their levels here (:func:`aslm_core.noise.output_floors`).
    margin : float
        Equilibrium margin of the feasible set.
    input_spectrum : aslm_core.noise.InputSpectrum, optional
        The inputs' signal spectrum from the bus's previous windows (:func:`aslm_core.noise.pooled_spectrum`)
        for the refinement's Wiener smoother instead of the window's own estimate; not used where the window's
        :func:`aslm_core.input_history.staleness` against it exceeds
        :data:`aslm_core.input_history.HISTORY_STALE_MAX`.

    Returns
    -------
    dict or None
        :func:`refine`'s dict plus ``objective``, the configured objective at the refined D on the
        refinement's data, ``spectrum_windows``, the windows ``input_spectrum`` was pooled from where the
        smoother used it (both inputs noisy: an exact input passes whole), else 0, and ``history_staleness``, the
        window's staleness against ``input_spectrum`` (None without one).
    """
    if not noisy_inputs(floors):
        return None
    stale = None
    if input_spectrum is not None:
        # A history that does not describe this window's inputs (another load or network) is worse than none.
        # θ unwrapped, as the history's windows were (:func:`aslm_core.preprocess.input_periodogram`).
        fs = 1.0 / float(np.median(np.diff(window.t)))
        stale = input_history.staleness(input_periodogram(np.stack([window.V, np.unwrap(window.theta)]), fs),
                                        input_spectrum)
        if not stale <= input_history.HISTORY_STALE_MAX:
            input_spectrum = None
    prep = prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=config.min_duration_s,
                   floors=True, input_smoother="wiener", input_spectrum=input_spectrum,
                   input_tail=config.input_spectrum_tail, signal_cutoffs=BAND_AT_CUTOFF, input_noise=config.input_noise,
                   output_white=False)
    if prep.input_error is None:
        return None
    # P's and Q's white levels from the same raw channels: the output-error fit's, not fitted again.
    prep.noise.update({k: floors[k] for k in OUTPUT_FLOOR_KEYS if k in floors})
    used = input_spectrum is not None and all(white_floor(prep.noise, c) and prep.noise.get(f"noise_{c}", 0.0) > 0.0
                                              for c in ("v", "theta"))
    out = refine(prep, window.f0, config, d0, skip_s, margin, history=used)
    if out is None:
        return None
    res = out["problem"].residuals(out["d"], jacobian=False)
    if res is None:
        return None
    out["objective"] = out["problem"].cost(res[0], res[1])
    out["spectrum_windows"] = input_spectrum.n_windows if used else 0
    out["history_staleness"] = stale
    return out
