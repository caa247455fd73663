"""Measurement noise of the synthetic PMU channels: the paper's SNR (eq. 10) and its three disturbance levels.

The SNR of a channel is 10·log10(Σy²/Σe²) with y the ambient part of the noise-free signal (minus its
mean; θ also minus a linear trend) and e the added noise.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NOISE_LEVELS", "SNR_SPREAD_DB", "ambient", "ambient_rows", "channel_snr_db", "noise_sigma", "target_snr"]

#: Mean SNR [dB] (paper eq. 10, mean of P and Q) of the three disturbance levels of Table I.
NOISE_LEVELS: dict[int, float] = {1: 14.0, 2: 22.0, 3: 28.0}
#: Half-width of the uniform spread of the per-case SNR around the level's mean [dB].
SNR_SPREAD_DB: float = 2.0


def ambient(y: np.ndarray, detrend: bool = False) -> np.ndarray:
    """Ambient part of a record: minus its mean (and its linear trend, for θ).

    Parameters
    ----------
    y : ndarray
        Record, in its own unit.
    detrend : bool
        Remove a least-squares line instead of the mean.
    """
    if detrend:
        t = np.arange(y.shape[-1], dtype=float)
        coef = np.polyfit(t, y, 1)
        return y - np.polyval(coef, t)
    return y - y.mean()


def ambient_rows(y: np.ndarray, detrend: bool) -> np.ndarray:
    """Row-wise :func:`ambient` of a (rows, samples) array (the trend by a closed-form slope).

    Parameters
    ----------
    y : ndarray
        (rows, samples) records, in their own unit.
    detrend : bool
        Remove each row's least-squares line instead of its mean.
    """
    if not detrend:
        return y - y.mean(axis=1, keepdims=True)
    t = np.arange(y.shape[1], dtype=float)
    tc = t - t.mean()
    slope = (y - y.mean(axis=1, keepdims=True)) @ tc / (tc @ tc)
    return y - y.mean(axis=1, keepdims=True) - slope[:, None] * tc[None, :]


def channel_snr_db(clean: np.ndarray, noisy: np.ndarray, *, detrend: bool = False) -> float:
    """SNR of a channel per eq. 10 [dB], y = ambient part of the clean signal, e = noisy − clean.

    Parameters
    ----------
    clean, noisy : ndarray
        The channel without and with noise, in its own unit.
    detrend : bool
        Take y minus a linear trend (θ) instead of minus the mean.
    """
    y = ambient(np.asarray(clean, float), detrend)
    e = np.asarray(noisy, float) - np.asarray(clean, float)
    return float(10.0 * np.log10(np.sum(y * y) / np.sum(e * e)))


def noise_sigma(y_amb_rms: float, snr: float) -> float:
    """Noise std giving an expected SNR of snr for an ambient part of rms y_amb_rms (eq. 10).

    Parameters
    ----------
    y_amb_rms : float
        Rms of the channel's ambient part, in its own unit.
    snr : float
        Target SNR [dB].
    """
    return float(y_amb_rms * 10.0 ** (-snr / 20.0))


def target_snr(rng: np.random.Generator, level: int | None, snr: float | None) -> float | None:
    """SNR target of one record [dB]: drawn around a level's mean, or given, or None (noise-free).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draw (one uniform when level is given).
    level : int or None
        Key of :data:`NOISE_LEVELS`: the target is its mean ± :data:`SNR_SPREAD_DB` (uniform).
    snr : float or None
        Fixed target [dB]; not together with level.
    """
    if level is not None and snr is not None:
        raise ValueError("give level or snr_db, not both")
    if level is not None:
        if level not in NOISE_LEVELS:
            raise ValueError(f"level must be one of {sorted(NOISE_LEVELS)}")
        return NOISE_LEVELS[level] + rng.uniform(-SNR_SPREAD_DB, SNR_SPREAD_DB)
    return snr
