"""Locate a mismatch: noise floor, residual spectrum against it per band, coherence, time segments.

The measurement noise of a PMU is broadband while ambient load dynamics live below ~2 Hz (paper §III.A),
so the residual's spectrum above a few hertz is the noise floor.  A model error shows as residual power
above that floor in the ambient band, coherent with what drives it (V, dV/dt, the bus frequency).
"""

from __future__ import annotations

import numpy as np
from scipy import signal, stats

from aslm_core.diagnosis.segment import butter_sos
from aslm_core.noise import FLOOR_FROM_HZ, noise_floor, periodogram

__all__ = ["FLOOR_FROM_HZ", "band_excess", "coherence", "locate", "noise_floor", "periodogram", "time_segments"]

#: Bands reported [Hz] (the last one is capped at the Nyquist frequency).
BANDS: tuple[tuple[float, float], ...] = ((0.05, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, 5.0))
#: Smallest in-band excess variance, as a fraction of the noise variance, that counts as a mismatch [-].
MIN_EXCESS = 0.05


def band_excess(r: np.ndarray, fs: float, floor: dict, *, alpha: float = 0.01, n_tests: int = 8) -> list[dict]:
    """Residual power per band against the floor, with an F test.

    Parameters
    ----------
    r : ndarray
        Residual [pu].
    fs : float
        Sample rate [Hz].
    floor : dict
        From :func:`noise_floor` (``psd`` [pu²/Hz], ``dof``); optionally ``extra_psd``: the expected PSD of
        noise propagated from the inputs, per bin of :func:`periodogram` of ``r`` [pu²/Hz], added to the
        white floor.
    alpha : float
        Family-wise significance level [-].
    n_tests : int
        Number of tests the Bonferroni correction divides ``alpha`` by.

    Notes
    -----
    Under white noise the band mean of m periodogram bins over the floor is F(2m, ν)-distributed, ν the
    floor's degrees of freedom (a median of M bins: 2·M·ln² 2, :func:`noise_floor`); a band is significant
    at ``alpha`` Bonferroni-corrected over ``n_tests``.
    With ``extra_psd`` the band mean is compared with the band mean of the expected PSD.

    Returns
    -------
    list of dict
        Per band: ``band`` [Hz], ``ratio`` (mean PSD / floor) [-], ``excess_var`` (variance above the
        floor in the band) [pu²], ``p_value``, ``significant``.
    """
    f, pxx = periodogram(r, fs)
    expected = _expected_psd(floor, f)
    out = []
    for lo, hi in BANDS:
        hi = min(hi, 0.95 * fs / 2)
        sel = (f >= lo) & (f < hi)
        m = int(sel.sum())
        if m == 0:
            continue
        ratio = float(pxx[sel].mean() / expected[sel].mean())
        df_hz = float(f[1] - f[0])
        p = float(stats.f.sf(ratio, 2 * m, floor["dof"]))
        out.append({"band": [lo, hi], "ratio": ratio,
                    "excess_var": float(max(pxx[sel].sum() - expected[sel].sum(), 0.0) * df_hz),
                    "p_value": p, "significant": bool(p < alpha / n_tests)})
    return out


def _expected_psd(floor: dict, f: np.ndarray) -> np.ndarray:
    """White floor plus the propagated input noise, if any, per periodogram bin [pu²/Hz]."""
    extra = floor.get("extra_psd")
    if extra is None or len(extra) != f.size:
        return np.full(f.size, floor["psd"])
    return floor["psd"] + np.asarray(extra, float)


def coherence(r: np.ndarray, drivers: dict[str, np.ndarray], fs: float, band: tuple[float, float] = (0.1, 2.0),
              alpha: float = 0.01) -> dict:
    """Magnitude-squared coherence of a residual with each driver (Welch, Hann, 50 % overlap).

    Parameters
    ----------
    r : ndarray
        Residual [pu].
    drivers : dict
        Name → signal of the same length (e.g. V [pu], dV/dt [pu/s], Δf [Hz]).
    fs : float
        Sample rate [Hz].
    band : (float, float)
        Band the coherence is summarised over [Hz].
    alpha : float
        False-alarm probability of the reported threshold [-].

    Returns
    -------
    dict
        Per driver: ``mean`` and ``max`` coherence over ``band`` [-]; plus ``threshold``: the level a
        single bin exceeds with probability ``alpha`` when residual and driver are independent,
        1 − alpha^(1/(K−1)) for K segments.
    """
    n = r.size
    nperseg = int(min(256, max(32, n // 4)))
    out: dict = {}
    k_seg = max(2, int((n - nperseg) // (nperseg // 2)) + 1)
    out["threshold"] = float(1.0 - alpha ** (1.0 / (k_seg - 1)))
    for name, x in drivers.items():
        f, c = signal.coherence(r, x, fs=fs, nperseg=nperseg)
        sel = (f >= band[0]) & (f <= band[1])
        out[name] = {"mean": float(c[sel].mean()), "max": float(c[sel].max())} if sel.any() else {"mean": 0.0, "max": 0.0}
    return out


def time_segments(r: np.ndarray, t: np.ndarray, fs: float, floor: dict, *, band: tuple[float, float] = (0.05, 5.0),
                  win_s: float = 1.0, alpha: float = 0.001) -> list[list[float]]:
    """Time intervals where the residual's ambient-band power exceeds what the noise floor allows.

    Parameters
    ----------
    r : ndarray
        Residual [pu].
    t : ndarray
        Sample times [s].
    fs : float
        Sample rate [Hz].
    floor : dict
        From :func:`noise_floor` (with ``extra_psd`` as in :func:`band_excess`, if any).
    band : (float, float)
        Only ``band[1]`` is used: the low-pass cut-off [Hz].
    win_s : float
        Moving-average window [s].
    alpha : float
        Per-window false-alarm probability of the threshold [-].

    The residual is linearly detrended and low-passed (zero phase, 4th order) at ``band[1]``; its moving
    mean square over ``win_s`` is compared with the floor's variance in [0, band[1]] times the chi-square
    quantile for 2·B·T degrees of freedom (no high-pass: its long ringing would smear the segments).

    Returns
    -------
    list of [t_start, t_end] [s]
    """
    hi = min(band[1], 0.45 * fs)
    x = signal.sosfiltfilt(butter_sos(float(hi), float(fs)), signal.detrend(r))
    w = max(3, int(round(win_s * fs)))
    ms = np.convolve(x * x, np.ones(w) / w, mode="same")
    fb, _ = periodogram(r, fs)
    var_band = float(_expected_psd(floor, fb)[fb <= hi].mean()) * hi
    dof = max(2.0 * hi * win_s, 1.0)
    thr = var_band * stats.chi2.isf(alpha, dof) / dof
    above = ms > thr
    segs = []
    if above.any():
        edges = np.flatnonzero(np.diff(np.concatenate(([0], above.astype(np.int8), [0]))))
        for a, b in zip(edges[0::2], edges[1::2], strict=True):
            if b - a >= w // 2:
                segs.append([float(t[a]), float(t[b - 1])])
    return segs


def locate(rp: np.ndarray, rq: np.ndarray, t: np.ndarray, fs: float, drivers: dict[str, np.ndarray],
           floors: dict[str, dict] | None = None, min_excess: float = MIN_EXCESS) -> dict:
    """Where a residual pair carries energy above the noise floor.

    Parameters
    ----------
    rp, rq : ndarray
        Residuals of P and Q [pu] (the initial transient already removed).
    t : ndarray
        Their sample times [s].
    fs : float
        Sample rate [Hz].
    drivers : dict
        Signals to test coherence with, e.g. ``V`` [pu], ``dVdt`` [pu/s], ``df`` [Hz].
    floors : dict, optional
        Noise floors {"P": ..., "Q": ...} from :func:`noise_floor` (default: estimated from rp, rq), each
        optionally with ``extra_psd`` (see :func:`band_excess`) and ``sigma`` the whole noise std.
    min_excess : float
        A channel is located only if, besides a significant band, its variance above the floor over the
        reported bands is at least this fraction of the noise variance [-] (a mismatch far below the
        noise is statistically visible at high SNR but immaterial).

    Returns
    -------
    dict
        ``channels`` (with significant excess), ``bands`` (significant bands per channel, [Hz]),
        ``time_segments`` (per channel, [s]), ``noise_floor`` (per channel: psd, sigma), ``spectrum``
        (per channel, per band), ``coherence`` (per channel, per driver), ``excess_over_noise`` (per
        channel: variance above the floor in the bands / noise variance).
    """
    floors = floors or {"P": noise_floor(rp, fs), "Q": noise_floor(rq, fs)}
    out = {"channels": [], "bands": {}, "time_segments": {}, "noise_floor": {}, "spectrum": {}, "coherence": {},
           "excess_over_noise": {}}
    for ch, r in (("P", rp), ("Q", rq)):
        fl = floors[ch]
        bands = band_excess(r, fs, fl)
        sig = [b["band"] for b in bands if b["significant"]]
        excess = sum(b["excess_var"] for b in bands)
        out["excess_over_noise"][ch] = excess / fl["sigma"] ** 2
        if excess < min_excess * fl["sigma"] ** 2:
            sig = []
        out["noise_floor"][ch] = {"psd": fl["psd"], "sigma": fl["sigma"], "band_hz": fl["band"], "bins": fl["bins"],
                                  "input_share": float(fl.get("input_share", 0.0))}
        out["spectrum"][ch] = bands
        out["coherence"][ch] = coherence(r, drivers, fs)
        if sig:
            out["channels"].append(ch)
            out["bands"][ch] = sig
            out["time_segments"][ch] = time_segments(r, t, fs, fl)
    return out
