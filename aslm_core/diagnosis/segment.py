"""One window made ready for diagnosis: uniform grid, bus-frequency deviation, train/test split.

A diagnosis fits on the first part of a window and judges on the rest (time-ordered hold-out), so the
motor states are simulated over the whole window while the linear coefficients and the parameters
only ever see the training samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import signal

from aslm_core import motor
from aslm_core.input_weighting import noisy_inputs
from aslm_core.preprocess import (
    FLOOR_CHANNELS,
    Prepared,
    falling_floors,
    prepare,
    white_floor,
)
from aslm_core.window import Window

#: Cut-off of the zero-phase low-pass applied to the bus-frequency deviation [Hz] (passes the ambient
#: band, 0.1–2 Hz, and removes the differentiation noise of dθ/dt).
FREQ_LOWPASS_HZ = 5.0


@dataclass
class Segment:
    """A prepared window with its split.

    Attributes
    ----------
    t, V, theta, P, Q : ndarray
        Uniform-grid channels [s, pu, rad, pu, pu].
    dfreq : ndarray
        Bus frequency deviation f − f0 [Hz] (recorded ``f`` if present, else dθ/dt/2π), low-passed.
    dvdt : ndarray
        dV/dt [pu/s] (central differences, low-passed like dfreq).
    dt : float
        Sample step [s].
    f0 : float
        Nominal frequency [Hz].
    k0 : int
        First sample of the objective (after the initial-state transient).
    ks : int
        First held-out sample.
    ke : int
        End (exclusive) of the held-out samples (a short guard before the window's end).
    bus : str
        The window's bus.
    dfreq_from_theta : bool
        Whether ``dfreq`` was derived from θ (False: from a recorded ``f``).
    V_raw, theta_raw : ndarray or None
        V [pu] and θ [rad] as measured, where ``V`` and ``theta`` are their conditional mean
        (:func:`conditional_mean`); None where they are the measured inputs themselves.
    input_error : (ndarray, ndarray) or None
        With the conditional mean: frequencies [Hz] and covariance spectrum (m, 2, 2) of its error x − x̂
        (:func:`error_spectrum`, per-sample units).
    held_out_first : bool
        The second fold of a cross-fitted diagnosis: the held-out samples are ``ke − ks`` samples from
        ``k0 + mirror_gap`` and the parameters are fitted on the samples after them, to ``ke``; False: the
        time-ordered split, fit first, judge after.
    mirror_gap : int
        Samples between the skip and the second fold's held-out samples (``held_out_first`` only): the model's
        states start from a steady state the recording is not in, and what that leaves decays with the slowest
        state's time constant, which the skip alone does not cover for a lag of seconds.
    exact_inputs : (bool, bool)
        Whether V and θ are exact by the identifier's rule (:func:`aslm_core.preprocess.white_floor`: the band above
        the floor's edge holds the input's own falling spectrum, not white PMU noise); with
        ``DiagnosisConfig.exact_inputs_quiet`` the noise model propagates no noise from them.
    floor_scale : dict
        A PMU's reporting filter (``DiagnosisConfig.input_noise="measured"`` and the identifier's
        :func:`aslm_core.preprocess.measured_floors` finding V's or θ's floor band falling): per channel (``v``,
        ``theta``, ``p``, ``q``) the in-band noise power over the floor band's median and that ratio's χ² degrees of
        freedom, (ratio [-], dof), by which the floor the noise model reads above 5 Hz on that channel (on P's and Q's
        residuals for ``p`` and ``q``) is raised (:func:`filter_scales`); empty otherwise.
    """

    t: np.ndarray
    V: np.ndarray
    theta: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    dfreq: np.ndarray
    dvdt: np.ndarray
    dt: float
    f0: float
    k0: int
    ks: int
    ke: int
    bus: str = ""
    dfreq_from_theta: bool = True
    V_raw: np.ndarray | None = None
    theta_raw: np.ndarray | None = None
    input_error: tuple[np.ndarray, np.ndarray] | None = None
    held_out_first: bool = False
    mirror_gap: int = 0
    exact_inputs: tuple[bool, bool] = (False, False)
    floor_scale: dict[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.omega0 = motor.omega0_of(self.f0)
        self.vd, self.vq, self.vdm, self.vqm = motor.dq_inputs(self.V, self.theta, motor.substeps(self.dt))

    @property
    def v_measured(self) -> np.ndarray:
        """V as measured [pu] (``V`` itself unless that is the conditional mean)."""
        return self.V if self.V_raw is None else self.V_raw

    @property
    def theta_measured(self) -> np.ndarray:
        """θ as measured [rad] (``theta`` itself unless that is the conditional mean)."""
        return self.theta if self.theta_raw is None else self.theta_raw

    @property
    def conditional_mean(self) -> bool:
        """Whether V and θ are the conditional mean of the measured inputs (their error modelled by
        ``input_error``)."""
        return self.input_error is not None

    @property
    def n(self) -> int:
        return int(self.V.shape[0])

    @property
    def train(self) -> slice:
        """Samples the parameters are fitted on."""
        if self.held_out_first:
            return slice(self.k0 + self.mirror_gap + self.ke - self.ks, self.ke)
        return slice(self.k0, self.ks)

    @property
    def test(self) -> slice:
        """Held-out samples the candidates are judged on."""
        if self.held_out_first:
            return slice(self.k0 + self.mirror_gap, self.k0 + self.mirror_gap + self.ke - self.ks)
        return slice(self.ks, self.ke)

    @property
    def fs(self) -> float:
        return 1.0 / self.dt


@lru_cache(maxsize=16)
def butter_sos(fc: float, fs: float) -> np.ndarray:
    """4th-order Butterworth low-pass at ``fc`` [Hz] for rate ``fs`` [Hz], as second-order sections.

    Cached: the design costs as much as the filtering, and the fits low-pass the same V hundreds of times.
    """
    return signal.butter(4, fc, fs=fs, output="sos")


@lru_cache(maxsize=16)
def _filtfilt_setup(fc: float, fs: float) -> tuple[np.ndarray, np.ndarray, int]:
    # sosfiltfilt's own steps that depend on the filter only: its initial state and its odd-extension length.
    sos = butter_sos(fc, fs)
    ntaps = 2 * sos.shape[0] + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return sos, signal.sosfilt_zi(sos), 3 * ntaps


def _lowpass(x: np.ndarray, fs: float, fc: float) -> np.ndarray:
    if fc >= 0.45 * fs:
        return x
    sos, zi, edge = _filtfilt_setup(float(fc), float(fs))
    if x.ndim != 1 or x.shape[0] <= edge or x.dtype != np.float64:
        return signal.sosfiltfilt(sos, x)
    # scipy's sosfiltfilt (odd extension, forward and backward passes from the steady state) step for step, its
    # initial state computed once per filter: the switched-shunt fits low-pass hundreds of V's a diagnosis, and
    # solving that state is most of each call (docs/diagnosis.md, stop 30).
    ext = np.concatenate((2 * x[0:1] - x[edge:0:-1], x, 2 * x[-1:] - x[-2:-(edge + 2):-1]))
    y, _ = signal.sosfilt(sos, ext, zi=zi * ext[0:1])
    y, _ = signal.sosfilt(sos, y[::-1], zi=zi * y[-1:])
    return y[::-1][edge:-edge]


def driver_noise(dv: np.ndarray, dtheta: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """What a change (dv, dθ) of V [pu] and θ [rad] does to dV/dt [pu/s] and to Δf derived from θ [Hz], as
    :func:`make_segment` builds them (both linear in the inputs but for Δf's median, a constant).

    Parameters
    ----------
    dv, dtheta : ndarray
        Changes of V and θ on the segment's grid.
    fs : float
        Sample rate [Hz].

    Returns
    -------
    (ndarray, ndarray)
        The changes of dV/dt and of Δf.
    """
    dt = 1.0 / fs
    return (_lowpass(np.gradient(dv, dt), fs, FREQ_LOWPASS_HZ),
            _lowpass(np.gradient(dtheta, dt) / (2.0 * math.pi), fs, FREQ_LOWPASS_HZ))


def conditional_mean(window: Window, *, tail: bool = False, input_noise: str = "auto") -> tuple[Prepared, Prepared | None]:
    """The window prepared as measured and, where V or θ carries white PMU noise, with V and θ replaced by their
    conditional mean given the window.

    Parameters
    ----------
    window : Window
    tail : bool
        Continue the smoother's estimate of the inputs' spectrum above its cut-off
        (:func:`aslm_core.noise.wiener_smooth`'s ``tail``, the identifier's ``input_spectrum_tail``).
    input_noise : {"auto", "measured"}
        :func:`aslm_core.preprocess.prepare`'s: ``measured`` for a PMU's channels (a falling floor band is its
        reporting filter's, not an exact input's).

    Returns
    -------
    (Prepared, Prepared or None)
        ``prepare(window)`` with the floors (``noise``), and ``prepare(window, input_smoother="wiener")`` (P and Q
        as measured, no low-pass) where :func:`aslm_core.input_weighting.noisy_inputs` says V or θ is noisy, else
        None.

    Notes
    -----
    Why: a model driven by the measured x = x_true + n leaves in its output residual −G·n, whose power
    |G(f)|²·S_n(f) the fit reduces by shrinking G (errors in variables).  Driven by x̂ = E[x | window] the residual
    carries G_true·e with e = x − x̂ independent of x̂ (jointly Gaussian signal and noise): its power does not
    depend on the fitted parameters (regression calibration, as the identifier's ``input_smoother="wiener"``,
    docs/numerics.md).  Exact inputs are left as measured, so their segment is the one built without this step.
    """
    # P's and Q's floors as the band's median: the diagnosis's noise model was confirmed on it (docs/diagnosis.md).
    raw = prepare(window, floors=True, input_noise=input_noise, output_white=False)
    if not noisy_inputs(raw.noise):
        return raw, None
    return raw, prepare(window, input_smoother="wiener", input_tail=tail, input_noise=input_noise, output_white=False)


def error_spectrum(raw: Prepared, smooth: Prepared) -> tuple[np.ndarray, np.ndarray]:
    """The covariance spectrum of the conditional mean's error x − x̂ the diagnosis models: the smoother's
    (``smooth.input_error``), with each noisy input's white-noise variance where the smoother passes none of it.

    Parameters
    ----------
    raw, smooth : Prepared
        :func:`conditional_mean`'s two.

    Returns
    -------
    (ndarray, ndarray)
        Frequencies [Hz] and the spectrum, shape (m, 2, 2), per-sample units [pu², pu·rad, rad²].

    Notes
    -----
    Where its gain is zero (above a channel's cut-off, where the input's power sinks to its floor) the smoother
    sets the signal to zero and its error spectrum says none is lost.  But P and Q respond to that signal with far
    less noise than V shows it: on ANDES's clean loads with V/θ noise (confirm8 9701, 2–12 s) the residual of Q
    stood above the modelled noise at 2–5 Hz in all three levels.  The lost signal's power lies below the floor
    there, so the floor's variance bounds it: the white noise the measured input would have carried.
    """
    f, px = smooth.input_error
    px = px.copy()
    for c, name in enumerate(("v", "theta")):
        var = raw.noise[f"noise_{name}"] ** 2 if white_floor(raw.noise, name) else 0.0
        px[:, c, c] = np.where(px[:, c, c].real > 0.0, px[:, c, c], var)
    return f, px


def make_segment(window: Window, *, skip_s: float = 1.0, train_fraction: float = 0.65,
                 guard_s: float = 0.1, input_mean: bool = True, input_tail: bool = False,
                 input_noise: str = "auto") -> Segment:
    """Prepare a window and split it in time.

    Parameters
    ----------
    window : Window
        Measurements (V [pu], θ [rad], P, Q [pu], optional f [Hz]).
    skip_s : float
        Initial transient excluded from every objective [s] (the motor starts from a steady state).
    train_fraction : float
        Fraction of the window (from its start) used for fitting [-]; the rest is held out.
    guard_s : float
        Samples at the very end left out of the held-out set [s] (room for time shifts).
    input_mean : bool
        Replace V and θ by their conditional mean where they carry white noise (:func:`conditional_mean`);
        False: the measured inputs always.
    input_tail : bool
        With ``input_mean``: the smoother's spectrum continued above its cut-off (:func:`conditional_mean`).
    input_noise : {"auto", "measured"}
        ``measured``: a PMU's channels (:func:`conditional_mean`); where their floor band falls, the noise model's
        floors are raised to the filter's flat level (``Segment.floor_scale``).

    Returns
    -------
    Segment
        Where V or θ carries white noise, V and θ (and Δf, dV/dt built from them) are their conditional mean
        (:func:`conditional_mean`); a recorded f is used as measured.
    """
    raw, smooth = (conditional_mean(window, tail=input_tail, input_noise=input_noise) if input_mean
                   else (prepare(window, floors=True, input_noise=input_noise, output_white=False), None))
    scale = filter_scales(raw)
    prep = raw if smooth is None else smooth
    exact = tuple(not (white_floor(raw.noise, c) and raw.noise[f"noise_{c}"] > 0.0) for c in ("v", "theta"))
    n = prep.V.shape[0]
    dt = prep.dt
    fs = 1.0 / dt
    from_theta = not (window.f is not None and window.f.shape[0] == n and np.all(np.isfinite(window.f)))
    if not from_theta:
        df = np.asarray(window.f, float) - window.f0
    else:
        df = np.gradient(prep.theta, dt) / (2.0 * math.pi)
    df = _lowpass(df - np.median(df), fs, FREQ_LOWPASS_HZ)
    dvdt = _lowpass(np.gradient(prep.V, dt), fs, FREQ_LOWPASS_HZ)
    k0 = min(int(math.ceil(skip_s / dt - 1e-9)), n // 4)
    ks = int(round(train_fraction * n))
    ke = n - max(1, int(round(guard_s / dt)))
    if ks - k0 < 50 or ke - ks < 50:
        raise ValueError(f"window too short to split: {n} samples")
    extra = {} if smooth is None else {
        "V_raw": raw.V, "theta_raw": raw.theta, "input_error": error_spectrum(raw, smooth)}
    return Segment(t=prep.t, V=prep.V, theta=prep.theta, P=prep.P, Q=prep.Q, dfreq=df, dvdt=dvdt, dt=dt,
                   f0=window.f0, k0=k0, ks=ks, ke=ke, bus=window.bus, dfreq_from_theta=from_theta,
                   exact_inputs=exact, floor_scale=scale, **extra)


def filter_scales(raw: Prepared) -> dict[str, tuple[float, float]]:
    """Per channel, the factor a PMU's reporting filter asks the noise model's floor to be raised by, and its χ²
    degrees of freedom (:attr:`Segment.floor_scale`); empty where :func:`aslm_core.preprocess.measured_floors` found
    no filter.

    The identifier's own raises (``floor_ratio_v|theta|p|q``), each where that channel's band falls: V and θ by their
    own incoherent levels, P's and Q's residual floors by the filter's ratio read on V (θ where V's band is white).
    Their own incoherent levels, tried for P and Q at stop 56, also read the part of an unmodelled motor response
    that one coefficient a regressor does not follow across 4–6 Hz, and hid a speed-dependent torque on ANDES's
    records (docs/diagnosis.md, "Stop 56").
    """
    est = raw.noise
    if "floor_plateau_dof" not in est:
        return {}
    dof = {"v": est["floor_plateau_dof"], "theta": est.get("floor_dof_theta", math.inf),
           "p": est["floor_plateau_dof"], "q": est["floor_plateau_dof"]}
    return {c: (est[f"floor_ratio_{c}"], dof[c]) for c, f in zip(FLOOR_CHANNELS, falling_floors(est), strict=True) if f}
