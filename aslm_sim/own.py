"""The identified load's own fluctuation: processes that move its P and Q whatever its voltage does.

At a real load bus much of the ambient variation of P and Q is the load's own switching, and it moves V
and θ through the network impedance (a closed loop: the identifier's input is correlated with the
disturbance).  These generators give unit-variance processes on the simulator's forcing grid; the case
builder scales them by σ·P and adds them to the constant-power part of the load at L, so the network
simulation carries their effect on V and θ.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

__all__ = ["OWN_SHAPES", "OWN_Q_PER_P", "own_process", "window_covariance"]

#: Shapes of the own process: ``lowpass`` (2 Hz low-passed white noise, as bus N's forcing), ``switching``
#: (many small loads switching on and off: steps), ``pink`` (1/f spectrum from 0.05 to 5 Hz), ``ramp`` (slow
#: ramps: straight lines between random levels at random instants, 30 s apart on average).
OWN_SHAPES = ("lowpass", "switching", "pink", "ramp")
#: ΔQ of the own fluctuation per ΔP: small loads at power factor 0.95 [-].
OWN_Q_PER_P = math.tan(math.acos(0.95))
#: Small loads in the switching process, and the mean time each stays in a state [s].
_N_SMALL_LOADS = 200
_SWITCH_MEAN_S = 1.0
#: Band of the pink process [Hz].
_PINK_BAND_HZ = (0.05, 5.0)
#: Mean time between the ramp's breakpoints [s].
_RAMP_MEAN_S = 30.0


def own_process(rng: np.random.Generator, shape: str, n: int, fs: float, sos: np.ndarray, gain: float) -> np.ndarray:
    """A zero-mean, unit-variance own-fluctuation process of n samples on a grid at fs [-].

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draws.
    shape : str
        One of :data:`OWN_SHAPES`.
    n : int
        Samples (the forcing grid of the whole simulation, warm-up included).
    fs : float
        Rate of the grid [Hz].
    sos, gain : ndarray, float
        The 2 Hz forcing filter and its unit-variance gain (:func:`aslm_sim.network.forcing_filter`), for
        ``lowpass``.
    """
    if shape == "lowpass":
        x = gain * signal.sosfilt(sos, rng.standard_normal(n))
    elif shape == "switching":
        # Two-state Markov loads, updated every 10 ms (a switching instant within 10 ms is a step at
        # the next update): the aggregate count is a birth–death process, its steps are the switchings.
        m = max(1, int(round(fs * 0.01)))
        k = -(-n // m)
        p_sw = 1.0 - math.exp(-0.01 / _SWITCH_MEAN_S)
        on = rng.random(_N_SMALL_LOADS) < 0.5
        count = np.empty(k)
        for i in range(k):
            on ^= rng.random(_N_SMALL_LOADS) < p_sw
            count[i] = on.sum()
        x = np.repeat(count, m)[:n]
        x = (x - x.mean()) / max(float(x.std()), 1e-12)
        return x
    elif shape == "pink":
        f = np.fft.rfftfreq(n, 1.0 / fs)
        amp = np.zeros_like(f)
        band = (f >= _PINK_BAND_HZ[0]) & (f <= _PINK_BAND_HZ[1])
        amp[band] = 1.0 / np.sqrt(f[band])
        spec = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
        x = np.fft.irfft(spec, n)
    elif shape == "ramp":
        # Exponential gaps between breakpoints (a Poisson process), enough of them to cover the grid.
        span = n / fs
        gaps = rng.exponential(_RAMP_MEAN_S, int(3 * span / _RAMP_MEAN_S) + 10)
        knots = np.concatenate(([0.0], np.cumsum(gaps)))
        while knots[-1] < span:
            knots = np.append(knots, knots[-1] + rng.exponential(_RAMP_MEAN_S))
        x = np.interp(np.arange(n) / fs, knots, rng.standard_normal(knots.size))
    else:
        raise ValueError(f"unknown own-fluctuation shape {shape!r} (use one of {OWN_SHAPES})")
    return (x - x.mean()) / max(float(x.std()), 1e-300)


def window_covariance(shape: str, length: int, fs: float, n_windows: int, seed: int) -> np.ndarray:
    """Covariance of the unit own process over windows of ``length`` samples, each window's mean removed [-].

    The process is stationary, so over a window its covariance is the Toeplitz matrix of its autocovariance,
    estimated here from one long realisation of ``n_windows`` windows' length (the biased estimator, so the
    matrix is positive semi-definite); each window's mean is then projected out and the result scaled to a
    mean variance of 1 over the window, so that a window's own-fluctuation covariance is its own variance
    times this (the mean is a static regressor, so removing it changes no bound on D).  Not the sample
    covariance of the ``n_windows`` windows: with fewer windows than samples its rank is below the window's,
    and a Cramér–Rao bound computed with it takes the directions it misses as free of the own process, which a
    broadband process (``switching``) is not: the bound comes out too small (docs/numerics.md, stop 36).

    Parameters
    ----------
    shape : str
        One of :data:`OWN_SHAPES`.
    length : int
        Samples per window.
    fs : float
        Sample rate [Hz].
    n_windows : int
        Length of the realisation, in windows.
    seed : int
        Seed of the realisation.
    """
    from scipy.linalg import toeplitz

    from aslm_sim.network import forcing_filter

    sos, gain = forcing_filter(fs)
    x = own_process(np.random.default_rng(seed), shape, length * n_windows, fs, sos, gain)
    x = x - x.mean()
    nfft = 1 << int(math.ceil(math.log2(2 * x.size)))
    spec = np.fft.rfft(x, nfft)
    acf = np.fft.irfft(spec.real**2 + spec.imag**2, nfft)[:length] / x.size
    cov = toeplitz(acf)
    cov = cov - cov.mean(axis=0, keepdims=True)
    cov = cov - cov.mean(axis=1, keepdims=True)
    return cov / float(np.mean(np.diag(cov)))
