"""White measurement-noise floors of a window's channels, and a smoother of the noisy inputs V and θ.

The measurement noise of a PMU is broadband while ambient load dynamics live below ~2 Hz (paper §III.A),
so a channel's spectrum above a few hertz is its noise floor.  The identifier reports the floors of V, θ,
P and Q, and can replace the measured V and θ by their conditional mean given the window (a Wiener
smoother, :func:`wiener_smooth`) before playing the model back on them: the model is driven by its
inputs, so input noise passes through it into the fit (errors in variables) unless it is removed first.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numba as nb
import numpy as np
from scipy import signal

#: Lower edge of the band the noise floor is measured in [Hz].
FLOOR_FROM_HZ = 5.0
#: Width of the smoothing of the power spectrum the Wiener gain is formed from [Hz].
WIENER_SMOOTH_HZ = 0.5
#: The smoother passes the signal at least up to this frequency [Hz] (its gain still weighs the noise).
MIN_CUTOFF_HZ = 0.5
#: A channel's signal ends where its smoothed power sinks to this multiple of its noise floor [-].
CUTOFF_FACTOR = 1.0
#: The band an input's noise is read in as the part of it the other channels do not explain (:func:`incoherent_level`,
#: ``IdentifyConfig.input_noise="measured"``): inside a reporting filter's flat band at 25 frames/s and up [Hz].
INCOHERENT_BAND_HZ = (FLOOR_FROM_HZ - 1.0, FLOOR_FROM_HZ + 1.0)
#: The exponents k of the falling content :func:`white_level` separates from the white floor (PSD ∝ f^−k) [-].
WHITE_LEVEL_EXPONENTS = tuple(float(k) for k in range(1, 11))
#: :func:`white_level`'s fit has failed where its level is below this fraction of the white std the top third of the band
#: reads (its median), and that reading is returned instead: a band whose own content peaks inside it (a mode at 7–9 Hz
#: at 30 frames/s) rather than falling lets the power law take the top bins too and the fitted level fall to nothing:
#: below 0.01 of the top's level in 2.7 % of development seed 45's P and Q bands at 25 frames/s and 4.8 % of ANDES's
#: (seeds 21–25), none between 0.01 and 0.1, the rest above (docs/numerics.md, "Stop 57") [-].
WHITE_LEVEL_TOP_FRACTION = 0.1
#: :func:`white_level`'s iterations of reweighted least squares at most, and their stop: every exponent's w moved by
#: less than this fraction [-].
WHITE_LEVEL_ITER = 40
WHITE_LEVEL_RTOL = 1e-4
#: P's and Q's white noise is read under the floor band's own falling content (:func:`output_floors`) where
#: :func:`white_level`'s likelihood ratio against a white band exceeds this [-]: the ratio is about χ² with 2 degrees
#: of freedom on a white band (at most 8.1 in 600 draws of white noise), 91–1,900 on ANDES's records at 25–100 frames/s
#: (docs/numerics.md, "Stop 57").  inf: the floor band's median, as before stop 57.
WHITE_LEVEL_LR_MIN = 20.0
#: The floors' keys :func:`output_floors` sets.
OUTPUT_FLOOR_KEYS = ("noise_p", "noise_q", "floor_p", "floor_q")
#: Length of the local line whose value at a window's end is the centre of the point reflection [s].
EDGE_FIT_S = 0.1
#: Windows pooled into one input spectrum may differ in length (bin spacing) by this fraction: a window missing frames
#: at its ends is shorter (the service accepts 10 % missing), and its smoothed periodogram interpolates well [-].
POOL_SPACING_TOL = 0.25
#: True: the smoother's gain at a frequency formed from its neighbours' periodogram without that bin's own (so that a bin
#: whose noise happened to be large does not open the gain on that noise).  Tried at stop 49 with the refinement's band
#: at least 4 Hz (``input_weighting.MIN_BAND_HZ``): it lifted a by 0.6–1.1 % at 50–120 frames/s / 0.1 %, but by
#: over-shrinking in the band (an offsetting error), σ rose at 25–30 frames/s, and the rule fixed before its
#: confirmation failed; not adopted (docs/numerics.md, "Stop 49").  Kept so that ``benchmarks.input_noise_gain``'s
#: figures rerun.
GAIN_WITHOUT_OWN_BIN = False
#: The spectrum the smoother's gain and cut-off are read from: ``"periodogram"``, the padded window's periodogram averaged
#: over :data:`WIENER_SMOOTH_HZ`; ``"multitaper"``, Thomson's estimate on the window itself with Slepian tapers of
#: half-bandwidth :data:`WIENER_SMOOTH_HZ` / 2 (the same resolution; far less leakage from the steep low-frequency
#: spectrum into the bins near the cut-off).  A candidate (stop 55).
GAIN_SPECTRUM = "periodogram"


@lru_cache(maxsize=32)
def _taper(n: int) -> tuple[np.ndarray, float]:
    """The periodic 10 % Tukey window of n samples and the sum of its squares."""
    w = signal.get_window(("tukey", 0.1), n)
    return w, float(w @ w)


def _detrend(x: np.ndarray) -> np.ndarray:
    """x minus its least-squares line along the last axis."""
    n = x.shape[-1]
    k = np.arange(n, dtype=np.float64) - 0.5 * (n - 1)
    slope = (x @ k) / (k @ k)
    return x - x.mean(axis=-1, keepdims=True) - np.multiply.outer(slope, k)


def periodogram(r: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided periodogram of a linearly detrended residual with a 10 % Tukey taper [pu²/Hz].

    The same numbers as ``scipy.signal.periodogram(r, fs, ("tukey", 0.1), detrend="linear")`` along the
    last axis, at a tenth of its cost (the identifier takes four per window).

    Parameters
    ----------
    r : ndarray
        Signal(s) [pu or rad], time along the last axis.
    fs : float
        Sample rate [Hz].

    Returns
    -------
    f : ndarray
        Frequencies [Hz].
    pxx : ndarray
        Power spectral density [unit²/Hz].
    """
    r = np.asarray(r, dtype=np.float64)
    n = r.shape[-1]
    w, ww = _taper(n)
    spec = np.fft.rfft(_detrend(r) * w, axis=-1)
    pxx = (spec.real**2 + spec.imag**2) / (fs * ww)
    if n % 2:
        pxx[..., 1:] *= 2.0
    else:
        pxx[..., 1:-1] *= 2.0
    return np.fft.rfftfreq(n, 1.0 / fs), pxx


def noise_floor(r: np.ndarray, fs: float, from_hz: float = FLOOR_FROM_HZ) -> dict:
    """White-noise floor of a residual from its high-frequency band.

    Parameters
    ----------
    r : ndarray
        Residual [pu].
    fs : float
        Sample rate [Hz].
    from_hz : float
        Lower edge of the floor band [Hz]; the band ends at 0.95 × Nyquist.  If that leaves fewer than
        20 bins (low frame rates) the top 40 % of the spectrum is used.

    Returns
    -------
    dict
        ``psd`` [pu²/Hz] (median of the band's bins divided by ln 2 — the median of a χ²₂ periodogram
        bin is ln 2 times its mean — so a tone or a few outliers do not lift the floor), ``sigma`` [pu] (white-noise std that floor implies, sqrt(psd·fs/2)),
        ``bins`` (number of bins), ``dof`` (the χ² degrees of freedom of ``psd`` as an estimate of the
        white level, for F tests against it) [-], ``band`` [Hz].

    Notes
    -----
    The floor is a median of M exponential bins over ln 2, whose relative variance is about 1/(M·ln² 2)
    where their mean's is 1/M; a scaled χ²_ν has 2/ν, so the floor counts as ν = 2·M·ln² 2 ≈ 0.96·M degrees
    of freedom, not the mean's 2·M.
    """
    f, pxx = periodogram(r, fs)
    sel = _floor_band(f, fs, from_hz)
    vals = pxx[sel]
    psd = float(np.median(vals) / math.log(2.0))
    return {"psd": psd, "sigma": math.sqrt(psd * fs / 2), "bins": int(vals.size),
            "dof": 2.0 * vals.size * math.log(2.0) ** 2,
            "band": [float(f[sel][0]), float(f[sel][-1])]}


def _floor_band(f: np.ndarray, fs: float, from_hz: float) -> np.ndarray:
    """The periodogram bins the floor is the median of (see :func:`noise_floor`)."""
    sel = (f >= from_hz) & (f <= 0.95 * fs / 2)
    return sel if sel.sum() >= 20 else f >= 0.6 * fs / 2


def channel_floors(V: np.ndarray, theta: np.ndarray, P: np.ndarray, Q: np.ndarray, fs: float) -> dict[str, float]:
    """White-noise std of each channel from its band above :data:`FLOOR_FROM_HZ`.

    Ambient V, θ, P and Q have (almost) no content there, so the floor of the channel itself is its
    measurement noise; an input without noise reports the level of its own high-frequency content.

    Parameters
    ----------
    V, theta, P, Q : ndarray
        The channels on a uniform grid [pu, rad, pu, pu].
    fs : float
        Sample rate [Hz].

    Returns
    -------
    dict
        ``noise_v`` [pu], ``noise_theta`` [rad], ``noise_p``, ``noise_q`` [pu], ``floor_tilt_v``,
        ``floor_tilt_theta``, ``floor_tilt_p``, ``floor_tilt_q`` [-]: the median power of the floor band's lower half
        over its upper half's (~1 for white noise; well above where the band holds the input's own falling spectrum:
        exact inputs, or a reporting filter's roll-off),
        and ``floor_slope_v``, ``floor_slope_theta`` [-] with their standard error ``floor_slope_se`` [-]: the
        slope of the band's log-periodogram on log(4·sin²(π·f/fs)) (:func:`_slope_design`), 0 for white noise,
        −1 for an input driven by steps (a sampled random walk: white increments).
    """
    # One FFT call for the four and a partition instead of np.median: this runs for every window.
    x = np.stack([V, theta, P, Q])
    _, pxx = periodogram(x, fs)
    bins = _floor_bins(x.shape[1], round(fs, 3), FLOOR_FROM_HZ)
    vals = pxx[:, bins]
    psd = _median(vals) / math.log(2.0)
    h = vals.shape[1] // 2
    tilt = _median(vals[:, :h]) / np.maximum(_median(vals[:, h:]), 1e-300)
    xc, se = _slope_design(x.shape[1], round(fs, 3), FLOOR_FROM_HZ)
    slope = np.log(np.maximum(vals[:2], 1e-300)) @ xc
    return {"noise_v": math.sqrt(psd[0] * fs / 2), "noise_theta": math.sqrt(psd[1] * fs / 2),
            "noise_p": math.sqrt(psd[2] * fs / 2), "noise_q": math.sqrt(psd[3] * fs / 2),
            "floor_tilt_v": float(tilt[0]), "floor_tilt_theta": float(tilt[1]), "floor_tilt_p": float(tilt[2]),
            "floor_tilt_q": float(tilt[3]),
            "floor_slope_v": float(slope[0]), "floor_slope_theta": float(slope[1]), "floor_slope_se": se}


def incoherent_level(x: np.ndarray, fs: float, band_hz: tuple[float, float] = INCOHERENT_BAND_HZ) -> tuple[float, int]:
    """The noise of the first row of ``x``, read as the part of it the other rows do not explain, per bin of a band.

    A PMU's noise on one channel is independent of the other channels, while the ambient signal of an input is
    coherent with theirs (P and Q respond to V and θ; the network couples V and θ), so the residual of the first
    channel's tapered DFT regressed bin by bin on the others' over ``band_hz`` (one complex coefficient per regressor
    for the band) is its noise, where the signal alone would be mistaken for it (docs/numerics.md, "Stop 55: a PMU's
    reporting filter").

    Parameters
    ----------
    x : ndarray, shape (c, n)
        The channel first (e.g. V [pu]), then the others (θ [rad], P, Q [pu]), on a uniform grid.
    fs : float
        Sample rate [Hz].
    band_hz : (float, float)
        The band [Hz].

    Returns
    -------
    float
        The noise's one-sided PSD in the band, as :func:`periodogram` gives it [unit²/Hz]; NaN where the band has no
        more bins than regressors.
    int
        The residual's degrees of freedom: twice the bins less the regressors (its χ² over that number is the PSD's
        relative error).
    """
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    c, n = x.shape
    w, ww = _taper(n)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    sel = (f >= band_hz[0]) & (f < band_hz[1]) & (f < 0.5 * fs)
    spec = np.fft.rfft(_detrend(x) * w, axis=-1)[:, sel]
    m, k = int(sel.sum()), c - 1
    if m <= k:
        return math.nan, 0
    y, z = spec[0], spec[1:].T
    beta = np.linalg.lstsq(z, y, rcond=None)[0]
    res = y - z @ beta
    return 2.0 * float(np.sum(np.abs(res) ** 2)) / (m - k) / (fs * ww), 2 * (m - k)


def white_level(x: np.ndarray, fs: float, from_hz: float = FLOOR_FROM_HZ) -> tuple[float, float]:
    """A channel's white-noise std with its own falling content in the floor band separated, and the evidence for it.

    :func:`channel_floors` reads the floor band's median as white noise.  Where the channel's own spectrum still falls
    through the band (a motor's fast response in P and Q at 25–50 frames/s, whose band starts at 5 Hz and ends at
    12.5–25 Hz) that median is the signal's, several times the noise (docs/numerics.md, "Stop 57").  The band's
    periodogram is fitted by the Whittle likelihood of S(f) = w + A·(f / from_hz)^−k, w, A ≥ 0, for each k of
    :data:`WHITE_LEVEL_EXPONENTS` (reweighted least squares: S is linear in w and A), and the best k's w returned.

    Parameters
    ----------
    x : ndarray
        The channel on a uniform grid [pu].
    fs : float
        Sample rate [Hz].
    from_hz : float
        Lower edge of the band [Hz].

    Returns
    -------
    float
        The white noise's std [pu] (as ``channel_floors``' ``noise_*``): the fit's, or the level the band's top third
        reads where the fit's is below :data:`WHITE_LEVEL_TOP_FRACTION` of it; NaN where the band has fewer than 8
        bins.
    float
        Twice the log-likelihood ratio of that fit against a white band at its mean level [-]: about χ² with 2 degrees
        of freedom where the band is white, large where it holds falling content.
    """
    f, p = periodogram(np.asarray(x, dtype=np.float64), fs)
    sel = (f >= from_hz) & (f < 0.5 * fs)
    f, p = f[sel], p[sel]
    if p.size < 8:
        return math.nan, 0.0
    scale = float(np.mean(p))
    if not scale > 0.0:
        return 0.0, 0.0
    y = p / scale
    w, nll = _white_fit(y, f / from_hz, np.asarray(WHITE_LEVEL_EXPONENTS), 0.5 * float(np.median(y)),
                        float(np.mean(y[:4])), WHITE_LEVEL_ITER, WHITE_LEVEL_RTOL)
    best = int(np.argmin(nll))
    lr = 2.0 * (float(y.size) - float(nll[best]))  # a white band at the mean: Σ log 1 + y = m
    top = float(np.median(y[-(y.size // 3):])) / math.log(2.0)  # a median of χ²₂ ordinates is ln 2 × their mean
    level = float(w[best]) if w[best] >= WHITE_LEVEL_TOP_FRACTION**2 * top else top
    return math.sqrt(level * scale * fs / 2.0), max(lr, 0.0)


def output_floors(floors: dict[str, float], P: np.ndarray, Q: np.ndarray, fs: float) -> dict[str, float]:
    """The floors with P's and Q's white noise read under their floor bands' own falling content.

    At 25–50 frames/s the floor band of P and Q (5 Hz to the Nyquist frequency) still holds the motor's fast response,
    and its median reads it as noise, several times a PMU's P noise at 25 frames/s (docs/numerics.md, "Stop 57" and
    "Stop 59").  Where :func:`white_level` finds such content (its likelihood ratio above
    :data:`WHITE_LEVEL_LR_MIN`) and a lower level, that level becomes ``noise_p`` (``noise_q``) and the band's median is
    kept as ``floor_p`` (``floor_q``).  Not where a reporting filter's roll-off was found (``floor_ratio_*`` other than
    1, ``input_noise="measured"``): the band's fall is then the filter's.

    Parameters
    ----------
    floors : dict
        :func:`channel_floors`' output (raised by a filter's reading where one was found).
    P, Q : ndarray
        The channels on a uniform grid, unfiltered [pu].
    fs : float
        Sample rate [Hz].

    Returns
    -------
    dict
        A copy of ``floors``, ``noise_p``, ``noise_q`` [pu] replaced where separated and ``floor_p``, ``floor_q`` [pu]
        added there.
    """
    out = dict(floors)
    if not math.isfinite(WHITE_LEVEL_LR_MIN) or any(
            floors.get(f"floor_ratio_{c}", 1.0) != 1.0 for c in ("v", "theta", "p", "q")):
        return out
    for c, x in (("p", P), ("q", Q)):
        sd, lr = white_level(x, fs)
        if lr > WHITE_LEVEL_LR_MIN and sd < floors[f"noise_{c}"]:
            out[f"floor_{c}"], out[f"noise_{c}"] = floors[f"noise_{c}"], sd
    return out


@nb.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _white_fit(y: np.ndarray, f_rel: np.ndarray, exponents: np.ndarray, w0: float, head: float, iterations: int,
               rtol: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`white_level`'s fit of y ≈ w + A·f_rel^−k per exponent k by reweighted least squares (the Whittle
    likelihood's weights 1/S²), from w = w0 and A = head − w0, all exponents iterated until every w moves by less than
    rtol; each exponent's w and negative log-likelihood Σ log S + y/S.  Compiled: as array operations the iterations
    over a few hundred bins and ten exponents were most of a noisy window's cost of the fit (docs/numerics.md, "Stop 57");
    with fastmath, which lets the bin sums vectorise, since every window pays for it (docs/numerics.md, "Stop 59")."""
    n_k, m = exponents.size, y.size
    lo = 1e-9
    g = np.empty((n_k, m))
    for k in range(n_k):
        e = exponents[k]
        whole = e == math.floor(e) and 0.0 < e <= 16.0  # powers by products: pow() would cost most of the fit
        for j in range(m):
            if whole:
                inv, val = 1.0 / f_rel[j], 1.0
                for _ in range(int(e)):
                    val *= inv
                g[k, j] = val
            else:
                g[k, j] = f_rel[j] ** -e
    w = np.full(n_k, w0)
    a = np.maximum(head - w, lo)
    w_new = np.empty(n_k)
    for _ in range(iterations):
        moved = 0.0
        for k in range(n_k):
            # The normal equations of the weighted fit of y on [1, g], solved in closed form.
            s00 = s01 = s11 = b0 = b1 = 0.0
            for j in range(m):
                s = w[k] + a[k] * g[k, j]
                v = 1.0 / (s * s)
                vg = v * g[k, j]
                s00 += v
                s01 += vg
                s11 += vg * g[k, j]
                b0 += v * y[j]
                b1 += vg * y[j]
            det = max(s00 * s11 - s01 * s01, 1e-300)
            w_new[k] = max((s11 * b0 - s01 * b1) / det, lo)
            a[k] = max((s00 * b1 - s01 * b0) / det, 0.0)
            moved = max(moved, abs(w_new[k] - w[k]) / w_new[k])
        w[:] = w_new
        if moved < rtol:
            break
    nll = np.zeros(n_k)
    for k in range(n_k):
        for j in range(m):
            s = w[k] + a[k] * g[k, j]
            nll[k] += math.log(s) + y[j] / s
    return w, nll


@lru_cache(maxsize=32)
def _slope_design(n: int, fs: float, from_hz: float) -> tuple[np.ndarray, float]:
    """The floor band's regressor of the log-periodogram slope, centred and scaled so that its dot product with
    the bins' log power is the least-squares slope, and that slope's standard error for white noise [-].

    The regressor is log(4·sin²(π·f/fs)), the log-spectrum of white noise's first difference: a random walk
    (white increments, the sampled response to many small steps) has slope −1 on it at every rate, white
    noise 0.  The log of a periodogram bin of a Gaussian series has variance π²/6 whatever its spectrum (a
    log χ²₂), which gives the standard error without estimating a variance.
    """
    f = np.fft.rfftfreq(n, 1.0 / fs)[_floor_bins(n, fs, from_hz)]
    x = np.log(4.0 * np.sin(np.pi * f / fs) ** 2)
    x -= x.mean()
    sxx = float(x @ x)
    return x / sxx, math.sqrt(math.pi**2 / 6.0 / sxx)


def _median(vals: np.ndarray) -> np.ndarray:
    """Median along the last axis by a partition (cheaper than np.median for these short rows)."""
    m = vals.shape[1]
    part = np.partition(vals, ((m - 1) // 2, m // 2), axis=1)
    return 0.5 * (part[:, (m - 1) // 2] + part[:, m // 2])


@lru_cache(maxsize=32)
def _floor_bins(n: int, fs: float, from_hz: float) -> np.ndarray:
    """Indices of the periodogram bins of an n-sample record the floor is the median of."""
    return np.flatnonzero(_floor_band(np.fft.rfftfreq(n, 1.0 / fs), fs, from_hz))


def input_ratios(V: np.ndarray, theta: np.ndarray, floors: dict[str, float]) -> dict[str, float]:
    """Ambient std of the inputs V and θ over their white-noise std: how far the PMU noise swamps them.

    Parameters
    ----------
    V, theta : ndarray
        The measured inputs on a uniform grid [pu, rad].
    floors : dict
        ``noise_v`` [pu], ``noise_theta`` [rad] (:func:`channel_floors`).

    Returns
    -------
    dict
        ``input_ratio_v``, ``input_ratio_theta`` [-]: sqrt(var − σ²)/σ of each linearly detrended input (σ its
        floor; 1e6 where σ is zero, an exact input).
    """
    out = {}
    for name, x in (("v", V), ("theta", theta)):
        sigma = floors[f"noise_{name}"]
        var = float(np.var(_detrend(np.asarray(x, dtype=np.float64))))
        out[f"input_ratio_{name}"] = math.sqrt(max(var - sigma * sigma, 0.0)) / sigma if sigma > 0.0 else 1e6
    return out


def _end_value(x: np.ndarray, m: int, at_start: bool) -> float:
    """Value at the first (or last) sample of the least-squares line through the first (last) m samples."""
    seg = x[:m] if at_start else x[-m:]
    k = np.arange(m, dtype=np.float64) - 0.5 * (m - 1)
    slope = float(seg @ k) / float(k @ k)
    return float(seg.mean()) + slope * float(k[0] if at_start else k[-1])


def _moving_average(x: np.ndarray, width: int, without_centre: bool = False) -> np.ndarray:
    """Centred moving average (shorter at the ends); ``without_centre``: each bin's average over its neighbours only."""
    if width <= 1:
        return x
    k = np.ones(width + (1 - width % 2 if without_centre else 0))  # odd, so that the centre is one bin
    if without_centre:
        k[k.size // 2] = 0.0
    return np.convolve(x, k, mode="same") / np.convolve(np.ones_like(x), k, mode="same")


def _extend(x: np.ndarray, pad: int, m: int) -> np.ndarray:
    """x extended by ``pad`` samples at both ends, point-reflected about the value of a local line through
    m samples (C¹ at the joints, so the extension adds no high-frequency content there)."""
    x0, x1 = _end_value(x, m, True), _end_value(x, m, False)
    return np.concatenate((2.0 * x0 - x[pad:0:-1], x, 2.0 * x1 - x[-2:-pad - 2:-1]))


@dataclass(frozen=True)
class InputPeriodogram:
    """One window's tapered periodogram matrix of its inputs (V, θ) below the band a pooled spectrum uses,
    and their white floors: what a bus's history keeps of a window (:func:`pooled_spectrum`).

    Attributes
    ----------
    fs : float
        Sample rate [Hz].
    n : int
        The window's samples (bins are fs / n apart).
    p : ndarray, shape (m, c, c)
        The periodogram matrix of bins 0 … m − 1 (of the linearly detrended, 10 % Tukey-tapered channels) in
        per-sample units (white noise of variance σ² is flat at σ²) [unit of x squared].
    floor : ndarray, shape (c,)
        Each channel's white-noise variance, :func:`noise_floor` ``sigma`` squared [unit of x squared].
    """

    fs: float
    n: int
    p: np.ndarray
    floor: np.ndarray

    @property
    def df(self) -> float:
        """Bin spacing [Hz]."""
        return self.fs / self.n

    @property
    def freqs(self) -> np.ndarray:
        """Frequencies of the bins kept [Hz]."""
        return np.fft.rfftfreq(self.n, 1.0 / self.fs)[:self.p.shape[0]]


@dataclass(frozen=True)
class InputSpectrum:
    """The inputs' signal cross-spectrum known from beyond the window, for :func:`wiener_smooth`.

    Attributes
    ----------
    freqs : ndarray, shape (m,)
        Frequencies [Hz].
    s : ndarray, shape (m, c, c)
        The signal's cross-spectral matrix in per-sample units [unit of x squared]; zero beyond ``freqs[-1]``.
    n_windows : int
        Windows it was pooled from.
    """

    freqs: np.ndarray
    s: np.ndarray
    n_windows: int


def input_periodogram(x: np.ndarray, fs: float, keep_hz: float = FLOOR_FROM_HZ + WIENER_SMOOTH_HZ) -> InputPeriodogram:
    """The periodogram matrix and white floors of one window's noisy inputs, for :func:`pooled_spectrum`.

    Parameters
    ----------
    x : ndarray, shape (c, n)
        Measured signals on a uniform grid (V [pu], θ [rad] unwrapped), c ≤ 2.
    fs : float
        Sample rate [Hz].
    keep_hz : float
        Bins up to this frequency are kept [Hz]: a pooled spectrum is zero from ``top_hz`` up and smoothed over
        ``smooth_hz``, so ``top_hz + smooth_hz`` keeps every bin it reads.

    Returns
    -------
    InputPeriodogram
    """
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    c, n = x.shape
    if c > 2 or n < 8:
        raise ValueError(f"input_periodogram takes one or two channels of at least 8 samples, got shape {x.shape}")
    taper, ww = _taper(n)
    spec = np.fft.rfft(_detrend(x) * taper, axis=1)
    m = min(spec.shape[1], int(math.floor(keep_hz * n / fs)) + 1)
    spec = spec[:, :m]
    p = np.einsum("if,jf->fij", spec, spec.conj()) / ww
    floor = np.array([noise_floor(xi, fs)["sigma"] ** 2 for xi in x])
    return InputPeriodogram(float(fs), n, p, floor)


def poolable(a: InputPeriodogram, b: InputPeriodogram) -> bool:
    """Whether two windows' periodograms can be pooled into one spectrum: the same channels and sample rate, bin
    spacings within :data:`POOL_SPACING_TOL`."""
    return (a.p.shape[1] == b.p.shape[1] and abs(a.fs - b.fs) <= 1e-6 * b.fs
            and abs(a.df - b.df) <= POOL_SPACING_TOL * b.df)


def pooled_spectrum(periodograms: Sequence[InputPeriodogram], smooth_hz: float = WIENER_SMOOTH_HZ,
                    top_hz: float = FLOOR_FROM_HZ) -> InputSpectrum:
    """The inputs' signal cross-spectrum from several noisy windows of the same bus, for :func:`wiener_smooth`.

    Parameters
    ----------
    periodograms : sequence of InputPeriodogram
        :func:`input_periodogram` of K windows of the bus (e.g. its previous ones), one sample rate and
        channel count; their bin spacings may differ by up to :data:`POOL_SPACING_TOL` (windows with missing frames):
        each is interpolated onto the last one's bins.
    smooth_hz : float
        Width of the moving average over the averaged periodogram matrix [Hz].
    top_hz : float
        The signal spectrum is zero from this frequency up [Hz]: the band the floor is measured in.

    Returns
    -------
    InputSpectrum

    Notes
    -----
    The windows' tapered periodogram matrices are averaged and smoothed over ``smooth_hz``, and the white floor
    (each channel's :func:`noise_floor` variance, averaged over the windows) is subtracted; negative eigenvalues
    are clipped.  Averaging K windows cuts the periodogram's scatter by √K, so the signal is resolved down to
    ~floor/√(K·bins) (bins: those in ``smooth_hz``) instead of one window's floor: :func:`wiener_smooth`'s own
    estimate must cut the signal where its power reaches the floor and loses what lies beneath.  Above
    ``top_hz`` the floor band's premise (no signal there) holds the spectrum at zero; without it the floor's
    residual scatter opened the gain there.  Measurements: docs/numerics.md.
    """
    if not periodograms:
        raise ValueError("pooled_spectrum needs at least one window")
    last = periodograms[-1]
    c = last.p.shape[1]
    if not all(poolable(g, last) for g in periodograms):
        raise ValueError(f"periodograms must share one sample rate, channel count and (within {POOL_SPACING_TOL:.0%}) "
                         f"bin spacing: {[(g.fs, g.df, g.p.shape[1]) for g in periodograms]}")
    m = min(g.p.shape[0] if g.n == last.n else int((g.p.shape[0] - 1) * g.df / last.df) + 1
            for g in periodograms)
    freqs = last.freqs[:m]
    acc = np.zeros((m, c, c), dtype=complex)
    for g in periodograms:
        if g.n == last.n:
            acc += g.p[:m]
        else:
            own = g.freqs
            for i in range(c):
                for j in range(c):
                    acc[:, i, j] += np.interp(freqs, own, g.p[:, i, j].real) + 1j * np.interp(freqs, own, g.p[:, i, j].imag)
    acc /= len(periodograms)
    floor = np.mean([g.floor for g in periodograms], axis=0)
    width = max(1, int(round(smooth_hz * last.n / last.fs)))
    sm = np.empty_like(acc)
    for i in range(c):
        for j in range(c):
            sm[:, i, j] = _moving_average(acc[:, i, j], width)
    lam, vec = np.linalg.eigh(sm - np.diag(floor))
    s = (vec * np.maximum(lam, 0.0)[:, None, :]) @ vec.conj().transpose(0, 2, 1)
    s[freqs >= top_hz] = 0.0
    return InputSpectrum(freqs, s, len(periodograms))


def pooled_input_spectrum(windows: Sequence[np.ndarray], fs: float, smooth_hz: float = WIENER_SMOOTH_HZ,
                          top_hz: float = FLOOR_FROM_HZ) -> InputSpectrum:
    """The inputs' signal cross-spectrum from several noisy windows of the same bus (:func:`pooled_spectrum` of
    their :func:`input_periodogram`).

    Parameters
    ----------
    windows : sequence of ndarray, each shape (c, n)
        Measured signals of K windows on the same uniform grid and length (e.g. V [pu] and θ [rad] of the
        bus's previous windows), c ≤ 2, each carrying white measurement noise.
    fs : float
        Sample rate [Hz].
    smooth_hz, top_hz : float
        As :func:`pooled_spectrum` [Hz].

    Returns
    -------
    InputSpectrum
    """
    xs = [np.atleast_2d(np.asarray(w, dtype=np.float64)) for w in windows]
    if not xs:
        raise ValueError("pooled_input_spectrum needs at least one window")
    c, n = xs[0].shape
    if c > 2 or any(x.shape != (c, n) for x in xs):
        raise ValueError(f"windows must share one shape (c, n) with c ≤ 2, got {[x.shape for x in xs]}")
    return pooled_spectrum([input_periodogram(x, fs, keep_hz=top_hz + smooth_hz) for x in xs], smooth_hz, top_hz)


def spectrum_at(spectrum: InputSpectrum, freqs: np.ndarray) -> np.ndarray:
    """``spectrum.s`` interpolated linearly onto ``freqs`` [Hz], zero beyond its last frequency, shape (len(freqs), c, c)
    [unit of x squared, per sample]."""
    f, s = spectrum.freqs, spectrum.s
    out = np.empty((freqs.size,) + s.shape[1:], dtype=complex)
    for i in range(s.shape[1]):
        for j in range(s.shape[2]):
            out[:, i, j] = (np.interp(freqs, f, s[:, i, j].real, right=0.0)
                            + 1j * np.interp(freqs, f, s[:, i, j].imag, right=0.0))
    return out


def wiener_smooth(x: np.ndarray, fs: float, sigma: np.ndarray, smooth_hz: float = WIENER_SMOOTH_HZ,
                  return_cutoffs: bool = False, return_error: bool = False,
                  spectrum: InputSpectrum | None = None, tail: bool = False,
                  cutoffs_before_tail: bool = False) -> np.ndarray | tuple:
    """Conditional mean of jointly stationary signals observed in white noise of known std: a non-causal
    multichannel Wiener smoother.

    Parameters
    ----------
    x : ndarray, shape (c, n)
        Measured signals on a uniform grid (e.g. V [pu] and θ [rad]).
    fs : float
        Sample rate [Hz].
    sigma : array_like, shape (c,)
        Std of each channel's white measurement noise, independent between channels [unit of x]
        (e.g. :func:`noise_floor`'s ``sigma``).
    smooth_hz : float
        Width of the moving average over the cross-spectrum the gain is formed from [Hz].
    return_cutoffs : bool
        Also return each channel's signal cut-off.
    return_error : bool
        Also return the smoothed signals' error spectrum (after the cut-offs, whether or not they were asked).
    spectrum : InputSpectrum, optional
        The signals' cross-spectrum known from elsewhere (:func:`pooled_spectrum`): used instead of the
        window's own estimate and its cut-off rule, a channel's cut-off then where that spectrum ends, if
        every channel carries noise (σ > 0: an exact channel must pass whole, which the given spectrum, zero
        in places, would not ensure).  Absent: the window's estimate.
    tail : bool
        With the window's own estimate: above each channel's cut-off, continue its signal spectrum up to
        :data:`FLOOR_FROM_HZ` by the power law (slope at most −1) fitted to its log-spectrum over [cut-off / 2,
        cut-off), the cross-spectrum at the coherence of that band, instead of zero, and hold it at zero from
        :data:`FLOOR_FROM_HZ` up (the floor band's premise, as :func:`pooled_spectrum`); the cut-off returned is
        then where that spectrum ends, unless ``cutoffs_before_tail``.  Only where every channel carries noise, as
        ``spectrum``.  The ambient signal does not stop where one window's estimate loses it in the floor
        (docs/numerics.md, "Stop 41: the signal above the smoother's cut-off").
    cutoffs_before_tail : bool
        With ``return_cutoffs``: the cut-offs of the window's own estimate (or of ``spectrum``) before any tail.

    Returns
    -------
    ndarray, shape (c, n)
        The smoothed signals.
    ndarray, shape (c,)
        Only with ``return_cutoffs``: per channel the frequency above which its signal is taken as zero
        (where its averaged power sinks to its floor; fs/2 when it never does) [Hz]; with ``tail``, where the
        continued spectrum ends, or with ``cutoffs_before_tail`` where the window's own estimate did.
    ndarray, shape (m,), and ndarray, shape (m, c, c)
        Only with ``return_error``: frequencies [Hz] and, per frequency, the covariance spectrum of the error
        x − x̂, P_x = R − R·(S + R)⁻¹·R = gain·R, in per-sample units (white noise of variance σ² has
        the flat spectrum σ²) [unit of x squared].

    Notes
    -----
    Each signal is extended at both ends by a point reflection (``_extend``), its line removed, and taken
    to the Fourier domain.  Per frequency the measured cross-spectral matrix S_m (the periodogram matrix
    averaged over ``smooth_hz``; without the frequency's own bin with :data:`GAIN_WITHOUT_OWN_BIN`) is the signal's
    S plus R = diag(σ²); S = S_m − R with its negative eigenvalues clipped, and a channel's signal is zero above the first frequency (from 0.5 Hz) where its
    power sinks to its floor (ambient content falls with frequency; without that rule the floor's own
    scatter opened the gain above 5 Hz and left half the error variance there).  The gain is S·(S + R)⁻¹.
    Why the conditional mean: with x̂ = E[x | V, θ measured] the error x − x̂ is uncorrelated with x̂ at
    every lag, so a model fitted on x̂ (regression calibration) is consistent to first order in the
    ambient excursions.  Jointly, because the network makes V and θ coherent: V's error must be
    uncorrelated with θ̂ too.  A low-pass instead leaves its in-band noise in the regressors and removes
    the signal beyond its cut-off.  Measurements: docs/numerics.md.
    """
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    var = np.asarray(sigma, dtype=np.float64) ** 2
    c, n = x.shape
    if c > 2:
        raise ValueError(f"wiener_smooth takes one or two channels, got {c}")
    if np.any(var <= 0.0):  # an exact channel passes whole: no spectrum from elsewhere, no tail
        spectrum, tail = None, False
    if n < 8 or not np.any(var > 0.0):
        freqs = np.fft.rfftfreq(n, 1.0 / fs)
        return _returned(x.copy(), np.full(c, 0.5 * fs), freqs, np.zeros((freqs.size, c, c), complex),
                         return_cutoffs, return_error)
    var = np.maximum(var, 1e-30)
    pad = min(n - 2, int(round(2.0 * fs)))
    m = max(2, min(n // 4, int(round(EDGE_FIT_S * fs))))
    ext = np.stack([_extend(xi, pad, m) for xi in x])
    ne = ext.shape[1]
    line = ext - _detrend(ext)
    # Tapered to zero over the outer half of each pad, so the wrap-around of the FFT joins two zeros.
    taper = np.ones(ne)
    h = pad // 2
    if h > 0:
        ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(h) / h)
        taper[:h], taper[ne - h:] = ramp, ramp[::-1]
    spec = np.fft.rfft((ext - line) * taper, axis=1)  # white noise of variance σ² has E|X_k|² ≈ ne·σ²
    width = max(1, int(round(smooth_hz * ne / fs)))
    r = ne * var
    p = [_moving_average((spec[i] * spec[i].conj()).real, width) for i in range(c)]
    # The cut-off reads the plain average (where the power sinks to the floor); the gain its neighbours' only.
    own_out = GAIN_WITHOUT_OWN_BIN
    p_gain = [_moving_average((spec[i] * spec[i].conj()).real, width, True) for i in range(c)] if own_out else p
    mt = None
    if GAIN_SPECTRUM == "multitaper":
        mt = _multitaper((x - line[:, pad:pad + n]), fs, ne, 0.5 * smooth_hz)
        p = p_gain = [mt[i, i].real for i in range(c)]
    k_min = int(np.ceil(MIN_CUTOFF_HZ * ne / fs))
    ends = []
    for i in range(c):
        below = np.flatnonzero(p[i][k_min:] <= CUTOFF_FACTOR * r[i])
        ends.append(k_min + int(below[0]) if below.size else p[i].size)
    if spectrum is not None:
        given = spectrum_at(spectrum, np.fft.rfftfreq(ne, 1.0 / fs)) * ne  # to |X_k|² units, as r
        ends = []
        for i in range(c):
            on = np.flatnonzero(given[k_min:, i, i].real <= 0.0)
            ends.append(k_min + int(on[0]) if on.size else given.shape[0])
    cutoffs = own_cutoffs = np.array(ends, dtype=np.float64) * fs / ne
    if c == 1:
        if spectrum is not None:
            s = np.maximum(given[:, 0, 0].real, 0.0)
        else:
            s = np.maximum(p_gain[0] - r[0], 0.0)
            s[ends[0]:] = 0.0
            if tail:
                freqs = np.fft.rfftfreq(ne, 1.0 / fs)
                top = int(np.searchsorted(freqs, FLOOR_FROM_HZ))
                ends = [min(_power_tail(s, ends[0], k_min, freqs, top), top)]
                s[top:] = 0.0
                cutoffs = np.array(ends, dtype=np.float64) * fs / ne
        out = (np.fft.irfft(s / (s + r[0]) * spec[0], n=ne) + line[0])[None, pad:pad + n]
        px = (s / (s + r[0]) * var[0]).astype(complex)[:, None, None]
        return _returned(out, own_cutoffs if cutoffs_before_tail else cutoffs, np.fft.rfftfreq(ne, 1.0 / fs), px,
                         return_cutoffs, return_error)
    # Two channels: S = S_m − R with its negative eigenvalue clipped, in closed form per frequency.
    b = _moving_average(spec[0] * spec[1].conj(), width, own_out) if mt is None else mt[0, 1]
    a, d = p_gain[0] - r[0], p_gain[1] - r[1]
    mid, rad = 0.5 * (a + d), np.sqrt(0.25 * (a - d) ** 2 + np.abs(b) ** 2)
    lo, hi = mid - rad, mid + rad
    # Where only the larger eigenvalue is positive, S = λ₊·(A − λ₋·I)/(λ₊ − λ₋); where none is, S = 0.
    part = (lo < 0.0) & (hi > 0.0)
    scale = np.where(part, hi / np.where(part, hi - lo, 1.0), 1.0)
    shift = np.where(part, lo, 0.0)
    keep = hi > 0.0
    sa = np.where(keep, scale * (a - shift), 0.0)
    sd = np.where(keep, scale * (d - shift), 0.0)
    sb = np.where(keep, scale * b, 0.0)
    sa[ends[0]:] = 0.0
    sb[min(ends):] = 0.0
    sd[ends[1]:] = 0.0
    if tail and spectrum is None:
        first = min(ends)
        coh = _band_coherence(sa, sb, sd, first, k_min)
        freqs = np.fft.rfftfreq(ne, 1.0 / fs)
        top = int(np.searchsorted(freqs, FLOOR_FROM_HZ))  # the floor band's premise, as the pooled spectrum's
        ends = [_power_tail(sa, ends[0], k_min, freqs, top), _power_tail(sd, ends[1], k_min, freqs, top)]
        if coh is not None:
            k = np.arange(first, min(ends))
            sb[k] = coh * np.sqrt(sa[k] * sd[k])
        sa[top:], sb[top:], sd[top:] = 0.0, 0.0, 0.0
        ends = [min(e, top) for e in ends]
        cutoffs = np.array(ends, dtype=np.float64) * fs / ne
    if spectrum is not None:
        sa, sb, sd = given[:, 0, 0].real, given[:, 0, 1], given[:, 1, 1].real
    # gain = S·(S + R)⁻¹
    ta, td = sa + r[0], sd + r[1]
    det = ta * td - np.abs(sb) ** 2
    g00, g01 = (sa * td - sb * sb.conj()) / det, (sb * ta - sa * sb) / det
    g10, g11 = (sb.conj() * td - sd * sb.conj()) / det, (sd * ta - sb.conj() * sb) / det
    est = np.stack([g00 * spec[0] + g01 * spec[1], g10 * spec[0] + g11 * spec[1]])
    out = (np.fft.irfft(est, n=ne, axis=1) + line)[:, pad:pad + n]
    px = np.empty((g00.size, 2, 2), dtype=complex)
    px[:, 0, 0], px[:, 0, 1] = g00 * var[0], g01 * var[1]
    px[:, 1, 0], px[:, 1, 1] = g10 * var[0], g11 * var[1]
    return _returned(out, own_cutoffs if cutoffs_before_tail else cutoffs, np.fft.rfftfreq(ne, 1.0 / fs), px,
                     return_cutoffs, return_error)


def _multitaper(y: np.ndarray, fs: float, ne: int, half_bw_hz: float) -> np.ndarray:
    """Thomson's multitaper cross-spectral matrix of the rows of ``y`` (c, n), interpolated onto the rfft grid of ``ne``
    samples and scaled to that grid's |X_k|² units (white noise of variance σ² gives ne·σ²), shape (c, c, ne // 2 + 1)."""
    c, n = y.shape
    nw = max(1.0, half_bw_hz * n / fs)
    k = max(1, int(2.0 * nw) - 1)
    tapers = _dpss(n, nw, k)  # (k, n), unit energy
    yk = np.fft.rfft(tapers[None, :, :] * y[:, None, :], axis=2)  # (c, k, m)
    s = np.einsum("ikm,jkm->ijm", yk, yk.conj()) / k  # per-sample units
    f, fe = np.fft.rfftfreq(n, 1.0 / fs), np.fft.rfftfreq(ne, 1.0 / fs)
    out = np.empty((c, c, fe.size), dtype=complex)
    for i in range(c):
        for j in range(c):
            out[i, j] = np.interp(fe, f, s[i, j].real) + 1j * np.interp(fe, f, s[i, j].imag)
    return out * ne


@lru_cache(maxsize=32)
def _dpss(n: int, nw: float, k: int) -> np.ndarray:
    """Slepian tapers of n samples, time-half-bandwidth nw, the first k, unit energy."""
    return signal.windows.dpss(n, nw, k, norm=2)


def _power_tail(s: np.ndarray, end: int, k_min: int, freqs: np.ndarray, top: int) -> int:
    """Continue a one-sided signal spectrum ``s`` (zero from bin ``end``) up to bin ``top`` by the power law fitted to
    its positive bins in [end / 2, end), slope at most −1, in place; the bin where it now ends."""
    band = np.arange(max(k_min, end // 2), end)
    band = band[s[band] > 0.0]
    if end >= top or band.size < 3:
        return end
    slope, level = np.polyfit(np.log(freqs[band]), np.log(s[band]), 1)
    k = np.arange(end, top)
    s[k] = np.exp(level + min(slope, -1.0) * np.log(freqs[k]))
    return top


def _band_coherence(sa: np.ndarray, sb: np.ndarray, sd: np.ndarray, end: int, k_min: int) -> complex | None:
    """The complex coherence of two signals over the bins [end / 2, end) of their spectra, held below 1."""
    band = np.arange(max(k_min, end // 2), end)
    if band.size < 3 or sa[band].sum() <= 0.0 or sd[band].sum() <= 0.0:
        return None
    coh = sb[band].sum() / np.sqrt(sa[band].sum() * sd[band].sum())
    return coh * min(1.0, 0.999 / max(abs(coh), 1e-12))


def _returned(out: np.ndarray, cutoffs: np.ndarray, freqs: np.ndarray, px: np.ndarray, with_cutoffs: bool,
              with_error: bool) -> np.ndarray | tuple:
    """:func:`wiener_smooth`'s return value for the outputs asked for."""
    extra = ((cutoffs,) if with_cutoffs else ()) + ((freqs, px) if with_error else ())
    return (out, *extra) if extra else out


def reflected_mean(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Moving average of a one-sided spectrum, reflected at DC and Nyquist (as the full DFT continues it)."""
    h = kernel.size // 2
    return np.convolve(np.concatenate((x[h:0:-1], x, x[-2:-h - 2:-1])), kernel, mode="valid") if h else x
