"""How much of a window's P and Q the bus voltage explains, and how much is the load's own fluctuation.

Ambient P and Q at a load bus move for two reasons: the voltage the grid imposes (what the identifier
models) and the load's own switching, which is not a function of V and θ and, through the network
impedance, moves V and θ as well.  After the fit, the measured variance splits into the model's part,
a white measurement floor and a coloured remainder: the remainder is the own fluctuation as this window
shows it.  A window whose P and Q are mostly own fluctuation carries little information about D.
"""

from __future__ import annotations

import math

import numpy as np

from aslm_core.noise import FLOOR_FROM_HZ, periodogram

#: :func:`own_median_hz` reads the own fluctuation's spectrum only where its excess over the white floor, summed over the
#: band, exceeds this many standard deviations of that sum under white noise alone (one-sided, ~2 % of windows without
#: own fluctuation) [-].
OWN_MEDIAN_Z = 2.0

# Equivalent noise bandwidth of the preprocessing's 2nd-order Butterworth low-pass, × its cut-off:
# (π/4)/sin(π/4).
_LOWPASS_ENBW = (math.pi / 4.0) / math.sin(math.pi / 4.0)


def white_variance(noise_std: float, fs: float, lowpass_hz: float = 0.0) -> float:
    """Variance the white measurement floor leaves in a channel after the optional causal low-pass [unit²].

    Parameters
    ----------
    noise_std : float
        White-noise std of the raw channel (its floor above 5 Hz) [unit].
    fs : float
        Sample rate [Hz].
    lowpass_hz : float
        Cut-off of the 2nd-order Butterworth low-pass applied (0: none) [Hz].
    """
    if lowpass_hz <= 0.0:
        return noise_std * noise_std
    return noise_std * noise_std * min(1.0, 2.0 * _LOWPASS_ENBW * lowpass_hz / fs)


def split(var_meas: float, var_resid: float, white_var: float) -> tuple[float, float, float]:
    """Excitation share and own-fluctuation level of one channel.

    Parameters
    ----------
    var_meas : float
        Variance of the measured channel over the regression samples [pu²].
    var_resid : float
        Variance of the fit's residual over the same samples [pu²].
    white_var : float
        Variance of the white measurement floor in the channel [pu²] (:func:`white_variance`).

    Returns
    -------
    share : float
        The share of the measured ambient variance (white floor removed) that the model explains, i.e.
        not left in the residual's coloured part, in [0, 1]: near 1 when V and θ drive the channel, small
        when the load's own fluctuation does.
    own_std : float
        Std of the residual's coloured part, the own fluctuation not explained by V and θ [pu].
    own_ratio : float
        own_std over the std of the measured ambient part [-] (0 without own fluctuation, → 1 when it
        dominates).
    """
    own_var, amb = variances(var_meas, var_resid, white_var)
    return 1.0 - own_var / amb, math.sqrt(own_var), math.sqrt(own_var / amb)


def variances(var_meas: float, var_resid: float, white_var: float) -> tuple[float, float]:
    """The own fluctuation's variance and the ambient variance of one channel [pu²], as :func:`split` reads them.

    The ambient part is the measured variance less the white floor (at least 1e-300); the own fluctuation the
    residual's variance less the floor, within [0, ambient].  Arguments as :func:`split`'s.
    """
    amb = max(var_meas - white_var, 1e-300)
    return min(max(var_resid - white_var, 0.0), amb), amb


def own_median_hz(resid: np.ndarray, fs: float, noise_std: float, lowpass_hz: float = 0.0,
                  top_hz: float = FLOOR_FROM_HZ) -> float:
    """Frequency below which half of the own fluctuation's variance lies, up to ``top_hz`` [Hz].

    The own fluctuation's spectrum as one number (issue 20's excitation indicator): the residual's periodogram
    less the white floor (flat at 2σ²/fs, shaped by the 2nd-order Butterworth low-pass where one was applied),
    accumulated from the lowest frequency; where that first reaches half its total.  Not clipped bin by bin:
    clipping would keep the floor's positive scatter, so that a residual without own fluctuation would read
    about half the band instead of nothing; and nothing where the total is within :data:`OWN_MEDIAN_Z` standard
    deviations of its scatter under white noise alone.  Step-like switching reads low, a 2 Hz band-limited process near
    1 Hz (docs/numerics.md, "Excitation indicators"); it means something where ``own_ratio`` is sizeable.

    Parameters
    ----------
    resid : ndarray
        The fit's residual of one channel over the regression samples [pu].
    fs : float
        Sample rate [Hz].
    noise_std : float
        White-noise std of the raw channel (``quality["noise_p"]``) [pu].
    lowpass_hz : float
        Cut-off of the causal low-pass applied to the channel (0: none) [Hz].
    top_hz : float
        Upper end of the band read [Hz] (the white floor is estimated above it).

    Returns
    -------
    float
        [Hz]; NaN when nothing stands out above the floor.
    """
    f, pxx = periodogram(resid, fs)
    floor = 2.0 * noise_std * noise_std / fs
    if lowpass_hz > 0.0:
        floor = floor / (1.0 + (f / lowpass_hz) ** 4)
    band = (f > 0.0) & (f <= top_hz)
    fb_floor = floor[band] if np.ndim(floor) else np.full(int(band.sum()), floor)
    own = pxx[band] - fb_floor
    total = float(own.sum())
    # A periodogram bin of white noise scatters by its mean: the excess over the floor counts where it stands out of
    # that scatter, not where an unbiased floor leaves half the windows a little above it.
    if not total > OWN_MEDIAN_Z * math.sqrt(float(fb_floor @ fb_floor)):
        return math.nan
    cum = np.cumsum(own)
    i = int(np.argmax(cum >= 0.5 * total))
    fb = f[band]
    df = float(f[1] - f[0])
    # Bin k holds the power from fb[k] − df/2 to fb[k] + df/2; linear within the bin where the half is crossed
    # (own[i] > 0 there: the sum rose past it).
    before = float(cum[i - 1]) if i > 0 else 0.0
    return float(fb[i] - 0.5 * df + df * (0.5 * total - before) / own[i])
