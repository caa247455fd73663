"""Window checks and conditioning before identification: grid, gaps, ranges, excitation, low-pass."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import signal

from aslm_core import noise
from aslm_core.errors import WindowError
from aslm_core.window import SIGNALS, Window

CHANNELS = SIGNALS  # V, θ, P, Q: put on one grid and filtered together
#: Smoothers of the inputs V and θ (see :func:`prepare`).
INPUT_SMOOTHERS = ("none", "wiener", "wiener_lowpass", "zero_phase")
#: What the channels' noise is taken to be (see :func:`prepare`'s ``input_noise``).
INPUT_NOISE = ("auto", "measured")
#: ``wiener_lowpass``: cut-off of the low-pass as a fraction of the lower signal cut-off of V and θ [-].
PREFILTER_FRACTION = 0.5
#: An input whose floor band tilts by more than this (``floor_tilt_*``) holds its own falling spectrum there, not
#: white PMU noise: it is taken as exact (not smoothed).  Measured at 25–120 frames/s: white noise 0.4–2.3,
#: exact inputs of the synthetic generator 14–1,600, 2 Hz low-passed noise (tests' equation window) 42–165.
FLOOR_TILT_MAX = 5.0
#: An input whose floor band's log-periodogram slope (``floor_slope_*``, 0 for white noise, −1 for a step-driven
#: input) is at most this, and at least :data:`STEP_SLOPE_Z` standard errors below 0, is taken as exact: the band
#: holds the response to steps (e.g. the load's own switching seen through the network), not PMU noise.  −0.5 is
#: halfway between the two shapes; development windows (docs/numerics.md, "The floor test on step-driven inputs"):
#: white noise at 25–120 frames/s −1.9 to +1.7 (z ≥ −6.4), step-driven exact inputs at 100 frames/s −2.4 to −0.9.
STEP_SLOPE_MAX = -0.5
#: Standard errors (``floor_slope_se``) the slope must lie below 0 for :data:`STEP_SLOPE_MAX` to apply [-]: at low
#: rates the band is short and the slope's scatter wide, and white noise with ambient content at the band's lower
#: edge reached z = −6.4 on the development windows (θ, 0.03 % / 3e-4 rad).
STEP_SLOPE_Z = 8.0


@dataclass
class Prepared:
    """A window on a uniform grid, gaps repaired, θ unwrapped, optionally smoothed or low-passed.

    ``noise``: the white-noise std of the measured channels (:func:`aslm_core.noise.channel_floors`,
    before any filtering), when asked for.  ``lowpass_hz``: the cut-off of the causal low-pass applied
    (given, or chosen by ``wiener_lowpass``), 0 for none [Hz].  ``input_error``: after a Wiener smoother, the
    frequencies [Hz] and error spectrum of the smoothed V and θ (:func:`aslm_core.noise.wiener_smooth`).
    ``signal_cutoffs``: when asked for, V's and θ's signal cut-offs of the window's own spectrum, before any tail (where
    each channel's power sinks to its floor) [Hz].
    """

    t: np.ndarray
    V: np.ndarray
    theta: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    dt: float
    flags: list[str] = field(default_factory=list)
    noise: dict[str, float] = field(default_factory=dict)
    lowpass_hz: float = 0.0
    input_error: tuple[np.ndarray, np.ndarray] | None = None
    signal_cutoffs: np.ndarray | None = None


def _fill_short_gaps(x: np.ndarray, max_run: int, name: str) -> int:
    """Linearly interpolate runs of NaN up to max_run samples long, in place; return the count filled."""
    bad = ~np.isfinite(x)
    if not bad.any():
        return 0
    if bad[0] or bad[-1]:
        raise WindowError("gaps", f"{name} is missing at the window's edge")
    edges = np.flatnonzero(np.diff(np.concatenate(([0], bad.view(np.int8), [0]))))
    runs = edges[1::2] - edges[0::2]
    if runs.max() > max_run:
        raise WindowError("gaps", f"{name} has a gap of {runs.max()} samples (repair limit {max_run})")
    idx = np.arange(x.size)
    x[bad] = np.interp(idx[bad], idx[~bad], x[~bad])
    return int(bad.sum())


@lru_cache(maxsize=128)
def _lowpass(cutoff_hz: float, fs: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """2nd-order Butterworth low-pass (b, a) and its unit-step initial state (cached: designing it costs as much as a
    short identification)."""
    b, a = signal.butter(2, cutoff_hz, fs=fs)
    return b, a, signal.lfilter_zi(b, a)


@lru_cache(maxsize=32)
def _zero_phase(cutoff_hz: float, fs: float) -> np.ndarray:
    """4th-order Butterworth low-pass as second-order sections (run forwards and backwards: zero phase)."""
    return signal.butter(4, cutoff_hz, fs=fs, output="sos")


def white_floor(floors: dict[str, float], channel: str) -> bool:
    """Whether an input's floor band holds white PMU noise rather than its own spectrum.

    Parameters
    ----------
    floors : dict
        :func:`aslm_core.noise.channel_floors`'s output.
    channel : {"v", "theta"}

    Returns
    -------
    bool
        True for inputs declared measured (``inputs_measured`` in the floors: ``input_noise="measured"`` of
        :func:`prepare`): a PMU's channel always carries noise.  Otherwise False (an exact input) where the band
        falls (``floor_tilt_*`` above :data:`FLOOR_TILT_MAX`), or where V's
        and θ's bands both have a step-driven input's shape (``floor_slope_*`` at most :data:`STEP_SLOPE_MAX` and
        :data:`STEP_SLOPE_Z` standard errors below 0).  Both: a PMU's noise is on its magnitude and its angle
        alike, so one channel with a white floor says the other's step shape is its own content on top of the
        noise, not an exact input (ANDES at 0.03 % / 3e-4 rad: θ's band is step-shaped, slope −0.85 to −0.55, in
        every window while V's is white; taking θ as exact there biased a by −2.6 %, docs/numerics.md).
    """
    if floors.get("inputs_measured"):
        return True
    return _white_shaped(floors, channel)


def _white_shaped(floors: dict[str, float], channel: str) -> bool:
    """Whether an input's floor band has white noise's shape (:func:`white_floor`'s rule for inputs not declared
    measured)."""
    if floors[f"floor_tilt_{channel}"] > FLOOR_TILT_MAX:
        return False
    return not all(_step_shaped(floors, c) for c in ("v", "theta"))


def _step_shaped(floors: dict[str, float], channel: str) -> bool:
    """Whether an input's floor band has the shape of a step-driven input's (see :func:`white_floor`)."""
    slope = floors[f"floor_slope_{channel}"]
    return slope <= STEP_SLOPE_MAX and slope <= -STEP_SLOPE_Z * floors["floor_slope_se"]


def measured_floors(floors: dict[str, float], x: np.ndarray, fs: float) -> list[str]:
    """The floors of a PMU's channels, read where its reporting filter is flat; in place.

    An M-class PMU low-passes its phasors before reporting them (C37.118.1's out-of-band rejection), so its noise
    is white only up to the filter's passband and falls towards the Nyquist frequency: the median of the floor band
    (:func:`aslm_core.noise.channel_floors`) then reads below the noise in the signal's band, and the band's fall
    looks like an exact input's own spectrum.  Where V's or θ's band falls (not white-shaped by :func:`white_floor`'s
    rule), the floor of each channel whose band falls is raised to its level where the filter is flat:

    * V and θ each to its own noise, read as the part of it at 4–6 Hz that the other three channels do not explain
      (:func:`incoherent_ratio`);
    * P and Q (``floor_tilt_*`` above :data:`FLOOR_TILT_MAX`) by V's ratio (θ's where V's band is white), one filter
      being behind all of a PMU's phasors: their own incoherent part holds the load's own fluctuation, which the
      identifier models apart from the white floor (read alone it worsened σ and coverage, docs/numerics.md,
      "Stop 56").

    Marks the floors ``inputs_measured`` (1.0) and records ``floor_plateau_ratio`` [-] (V's ratio, θ's where V's
    band is white; 1 where no band falls or the band has too few bins for the regression) with its χ² degrees of
    freedom ``floor_plateau_dof``, and the power factor each channel's floor was raised by, ``floor_ratio_v|theta|p|q``
    [-] (1 where its band is white), with θ's own degrees of freedom ``floor_dof_theta``.

    Parameters
    ----------
    floors : dict
        :func:`aslm_core.noise.channel_floors`' output for ``x``.
    x : ndarray, shape (4, n)
        V [pu], θ [rad], P, Q [pu] on the uniform grid.
    fs : float
        Sample rate [Hz].

    Returns
    -------
    list of str
        ``["input_noise_filtered"]`` where V's or θ's floor was raised, else empty.
    """
    falling = falling_floors(floors)
    floors["inputs_measured"] = 1.0
    floors["floor_plateau_ratio"] = 1.0
    if not (falling[0] or falling[1]):
        # No filter on the inputs: a PMU's filter acts on all its phasors alike, so a falling P or Q band is their
        # own signal's (P's and Q's noise is the smaller part of them near 5 Hz), and read as it is.
        return []
    # The band's lowest bins alone read the ambient signal there as noise (2.5–5.6 × the noise on ANDES's records at
    # 0.03 %), and V's ratio applied to θ misreads θ wherever the two bands hold different shares of their own signal
    # above 5 Hz (docs/numerics.md, "Stop 55" and "Stop 56").
    ratios = [incoherent_ratio(floors, x, fs, c) if falling[c] else (1.0, math.inf) for c in (0, 1)]
    i = 0 if falling[0] else 1
    if not math.isfinite(ratios[i][1]):
        return []  # a window too short for the regression (under ~2 s): the band's median, as measured
    ratios += [ratios[i] if f else (1.0, math.inf) for f in falling[2:]]
    for name, (ratio, _) in zip(FLOOR_CHANNELS, ratios, strict=True):
        floors[f"noise_{name}"] *= math.sqrt(ratio)
        floors[f"floor_ratio_{name}"] = ratio
    floors["floor_plateau_ratio"], floors["floor_plateau_dof"] = ratios[i][0], float(ratios[i][1])
    if falling[1] and math.isfinite(ratios[1][1]):
        floors["floor_dof_theta"] = float(ratios[1][1])
    return ["input_noise_filtered"]


#: The channels of :func:`aslm_core.noise.channel_floors`' ``noise_*`` keys, in the order of the stacked window.
FLOOR_CHANNELS = ("v", "theta", "p", "q")


def falling_floors(floors: dict[str, float]) -> tuple[bool, bool, bool, bool]:
    """Whether each channel's floor band (V, θ, P, Q) falls as a reporting filter makes it: V and θ not white-shaped
    by :func:`white_floor`'s rule for undeclared inputs, P and Q tilted above :data:`FLOOR_TILT_MAX`."""
    return (not _white_shaped(floors, "v"), not _white_shaped(floors, "theta"),
            floors["floor_tilt_p"] > FLOOR_TILT_MAX, floors["floor_tilt_q"] > FLOOR_TILT_MAX)


def incoherent_ratio(floors: dict[str, float], x: np.ndarray, fs: float, channel: int) -> tuple[float, float]:
    """A channel's noise where a reporting filter is flat over its floor band's median, and that ratio's χ² degrees
    of freedom (:func:`aslm_core.noise.incoherent_level`: its part at 4–6 Hz the other channels do not explain).

    Parameters
    ----------
    floors : dict
        :func:`aslm_core.noise.channel_floors`' output for ``x``, not yet raised.
    x : ndarray, shape (4, n)
        V [pu], θ [rad], P, Q [pu] on the uniform grid.
    fs : float
        Sample rate [Hz].
    channel : int
        The row of ``x`` (0 V, 1 θ, 2 P, 3 Q).

    Returns
    -------
    float
        The power ratio [-], at least 1 (a filter does not raise a band).
    float
        Its degrees of freedom; ∞ (and the ratio 1) where the band has too few bins for the regression.
    """
    level, dof = noise.incoherent_level(x[[channel] + [k for k in range(4) if k != channel]], fs)
    if not (math.isfinite(level) and level > 0.0):
        return 1.0, math.inf
    median = floors[f"noise_{FLOOR_CHANNELS[channel]}"] ** 2 * 2.0 / fs  # the band median's PSD (σ² = PSD·fs/2)
    return max(1.0, level / median), float(dof)


def prepare(window: Window, *, max_gap_samples: int = 5, min_duration_s: float = 5.0,
            lowpass_hz: float | None = None, floors: bool = False, input_smoother: str = "none",
            input_cutoff_hz: float = 3.0, input_spectrum: noise.InputSpectrum | None = None,
            input_tail: bool = False, signal_cutoffs: bool = False, input_noise: str = "auto",
            output_white: bool = True) -> Prepared:
    """Check a window and bring it onto a clean uniform grid.

    Parameters
    ----------
    window : Window
        Raw measurements.
    max_gap_samples : int
        Longest run of missing samples (missing time stamps or non-finite values) repaired by linear
        interpolation; a longer gap is an error.
    min_duration_s : float
        Shortest usable window [s].
    lowpass_hz : float or None
        Cut-off [Hz] of a causal 2nd-order Butterworth low-pass applied identically to V, θ, P, Q
        (causal so the end of the window, the most recent data, is not distorted).
    floors : bool
        Estimate the white-noise floor of every channel (``Prepared.noise``); implied by the Wiener smoothers.
    input_smoother : {"none", "wiener", "wiener_lowpass", "zero_phase"}
        Applied to V and θ only, before the low-pass: ``wiener`` replaces them by their conditional
        mean given the window, with the noise std from their floors (:func:`aslm_core.noise.wiener_smooth`;
        an input whose floor band is not white noise's, :func:`white_floor`, is taken as exact);
        ``wiener_lowpass`` does the same and then, unless ``lowpass_hz`` is given, low-passes all four
        channels as ``lowpass_hz`` would at ``PREFILTER_FRACTION`` × the lower of V's and θ's signal
        cut-off (where their power sinks to the noise floor; no low-pass when neither does: exact inputs);
        ``zero_phase`` by a 4th-order Butterworth low-pass at ``input_cutoff_hz`` run forwards and
        backwards.  P and Q are not smoothed: only the inputs' noise is propagated by the model.
    input_cutoff_hz : float
        Cut-off of the ``zero_phase`` smoother [Hz].
    input_spectrum : aslm_core.noise.InputSpectrum, optional
        For the Wiener smoothers: V's and θ's signal cross-spectrum known from elsewhere (the bus's previous
        windows, :func:`aslm_core.noise.pooled_spectrum`), instead of the window's own.
    input_tail : bool
        For the Wiener smoothers: continue the window's own estimate of the inputs' spectrum above its cut-off
        (:func:`aslm_core.noise.wiener_smooth`'s ``tail``).
    signal_cutoffs : bool
        With ``input_smoother="wiener"`` (the refinement's): also record the signal cut-offs of V and θ before any
        tail (``Prepared.signal_cutoffs``).
    input_noise : {"auto", "measured"}
        With the floors: ``auto`` takes an input whose floor band is not white noise's as exact (:func:`white_floor`);
        ``measured`` declares the channels a PMU's, which always carry noise, and reads a falling band's noise
        where a reporting filter is flat (:func:`measured_floors`).
    output_white : bool
        With the floors: P's and Q's noise read under their floor bands' own falling content where the band holds some
        (:func:`aslm_core.noise.output_floors`; the band's median kept as ``floor_p``, ``floor_q``); False: the band's
        median (the diagnosis's noise model, confirmed on it).

    Returns
    -------
    Prepared

    Raises
    ------
    WindowError
        ``shape``, ``too_short``, ``non_monotonic``, ``non_uniform``, ``gaps``, ``non_finite``,
        ``bad_range`` or ``no_excitation``, with a message naming the problem.
    """
    t = window.t
    n = t.shape[0]
    arrays = {c: getattr(window, c) for c in CHANNELS}
    if t.ndim != 1 or any(a.shape != t.shape for a in arrays.values()):
        shapes = ", ".join(f"{k}{a.shape}" for k, a in {"t": t, **arrays}.items())
        raise WindowError("shape", f"channels must be 1-D and of equal length, got {shapes}")
    if n < 3:
        raise WindowError("too_short", f"{n} samples")
    if not np.all(np.isfinite(t)):
        raise WindowError("non_finite", "time stamps contain NaN or Inf")
    steps = np.diff(t)
    s_min, s_max = float(steps.min()), float(steps.max())
    if s_min <= 0:
        k = int(np.flatnonzero(steps <= 0)[0])
        raise WindowError("non_monotonic", f"time does not increase at sample {k + 1} (t={t[k + 1]!r})")
    if s_max <= 1.05 * s_min:
        # No missing samples: the mean step, which averages out time-stamp rounding.
        dt = float(t[-1] - t[0]) / (n - 1)
        k_steps = np.ones(n - 1)
    else:
        dt = float(np.median(steps))
        ratio = steps / dt
        k_steps = np.rint(ratio)
        if np.any(np.abs(ratio - k_steps) > 0.1):
            worst = float(np.max(np.abs(ratio - k_steps)))
            raise WindowError("non_uniform", f"sample times deviate from a {dt:.6g} s grid by {worst:.2f} steps")
    if t[-1] - t[0] < min_duration_s:
        raise WindowError("too_short", f"window covers {t[-1] - t[0]:.3g} s, need at least {min_duration_s:g} s")

    flags: list[str] = []
    stacked = np.stack([arrays[c] for c in CHANNELS])
    finite = bool(np.isfinite(stacked).all())
    if not finite and np.isinf(stacked).any():
        raise WindowError("non_finite", "a channel contains Inf")
    n_grid = int(k_steps.sum()) + 1
    if n_grid == n and finite:
        grid = stacked  # already a complete uniform grid (np.stack made a copy)
    else:
        idx = np.concatenate(([0], np.cumsum(k_steps).astype(np.int64)))
        grid = np.full((len(CHANNELS), n_grid), np.nan)
        grid[:, idx] = stacked
        repaired = 0
        for i, c in enumerate(CHANNELS):
            repaired = max(repaired, _fill_short_gaps(grid[i], max_gap_samples, c))
        if repaired:
            flags.append(f"repaired_samples:{repaired}")
    V, theta, P, Q = grid
    lo, hi = grid.min(axis=1), grid.max(axis=1)
    if lo[0] <= 0.3 or hi[0] > 2.0:
        raise WindowError("bad_range", f"V outside (0.3, 2] pu: min {lo[0]:.4g}, max {hi[0]:.4g}")
    if np.abs(np.diff(theta)).max() > np.pi:
        theta = np.unwrap(theta)
    if hi[0] - lo[0] < 1e-6 * V[0] or hi[2] == lo[2] or hi[3] == lo[3]:
        raise WindowError("no_excitation", "V, P or Q is constant: ambient signals carry no information")
    if input_smoother not in INPUT_SMOOTHERS:
        raise ValueError(f"input_smoother must be one of {INPUT_SMOOTHERS}, got {input_smoother!r}")
    wiener = input_smoother in ("wiener", "wiener_lowpass")
    if input_noise not in INPUT_NOISE:
        raise ValueError(f"input_noise must be one of {INPUT_NOISE}, got {input_noise!r}")
    est = noise.channel_floors(V, theta, P, Q, 1.0 / dt) if floors or wiener else {}
    if est and input_noise == "measured":
        flags += measured_floors(est, np.stack([V, theta, P, Q]), 1.0 / dt)
    if est and output_white:
        est = noise.output_floors(est, P, Q, 1.0 / dt)
    # The inputs' white noise: none where the floor band is not white (an exact input's own spectrum).
    white = {k: (est[k] if white_floor(est, k[6:]) else 0.0) for k in ("noise_v", "noise_theta") if k in est}
    if est:
        est.update(noise.input_ratios(V, theta, white))
    input_error = own_cut = None
    if signal_cutoffs and input_smoother != "wiener":
        raise ValueError("signal_cutoffs is recorded with input_smoother='wiener' only")
    if wiener:
        (V, theta), cut, *input_error = noise.wiener_smooth(
            np.stack([V, theta]), 1.0 / dt, [white["noise_v"], white["noise_theta"]], return_cutoffs=True,
            return_error=True, spectrum=input_spectrum, tail=input_tail, cutoffs_before_tail=signal_cutoffs)
        own_cut = cut if signal_cutoffs else None
        if input_smoother == "wiener_lowpass" and lowpass_hz is None and cut.min() < 0.45 / dt:
            # Rounded to 0.1 Hz so the filter designs are cached.
            lowpass_hz = max(0.1, round(PREFILTER_FRACTION * float(cut.min()), 1))
    elif input_smoother == "zero_phase":
        if not 0.0 < input_cutoff_hz < 0.5 / dt:
            raise ValueError(f"input_cutoff_hz must lie in (0, {0.5 / dt:g}) Hz for a {1 / dt:g} Hz window")
        sos = _zero_phase(float(input_cutoff_hz), round(1.0 / dt, 3))
        V, theta = signal.sosfiltfilt(sos, np.stack([V, theta]), axis=1)
    if lowpass_hz is not None:
        fs = 1.0 / dt
        if not 0.0 < lowpass_hz < 0.5 * fs:
            raise ValueError(f"lowpass_hz must lie in (0, {0.5 * fs:g}) Hz for a {fs:g} Hz window")
        b, a, zi = _lowpass(float(lowpass_hz), round(fs, 3))  # rounded: time-stamp jitter must not defeat the cache
        x = np.stack([V, theta, P, Q])
        V, theta, P, Q = signal.lfilter(b, a, x, axis=1, zi=zi[None, :] * x[:, :1])[0]
    tg = t[0] + dt * np.arange(n_grid)
    return Prepared(tg, V, theta, P, Q, dt, flags, est, float(lowpass_hz or 0.0),
                    tuple(input_error) if input_error else None, own_cut)


def input_periodogram(window: Window, max_gap_samples: int = 5) -> noise.InputPeriodogram:
    """The periodogram matrix and white floors of a window's V and θ, on the grid :func:`prepare` puts it on:
    what a bus's history keeps of the window for the inputs' spectrum (:func:`aslm_core.noise.pooled_spectrum`).

    Parameters
    ----------
    window : Window
        Raw measurements (V [pu], θ [rad], possibly wrapped, a few frames missing).
    max_gap_samples : int
        As :func:`prepare`.

    Returns
    -------
    aslm_core.noise.InputPeriodogram

    Raises
    ------
    WindowError
        As :func:`prepare`.
    """
    prep = prepare(window, max_gap_samples=max_gap_samples, min_duration_s=0.0)
    return noise.input_periodogram(np.stack([prep.V, prep.theta]), 1.0 / prep.dt)
