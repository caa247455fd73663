"""Noise model of a window: white measurement noise on P and Q plus the noise of the inputs V and θ
propagated through the model (errors in variables), per frequency; and the ambient-band transform the
fits and tests work in.

Why: the model is driven by the *measured* V and θ.  When they carry PMU noise, the model output carries
it too, filtered by the model's sensitivity G(f) = ∂(P, Q)/∂(V, θ) — large and instantaneous at high
frequency (the static regressors, the motor's output equation at frozen flux), different in the ambient
band (the motor's flux and slip respond).  The residual's noise is then not white at the level measured
above 5 Hz but

    S_r(f) = S_P + |G_V(f)|²·S_V + |G_θ(f)|²·S_θ

and it is correlated between P and Q (both see the same V noise).  A fit weighted as if it were white is
dominated by the propagated high-frequency noise, which a model can reduce by distorting its parameters
(or a candidate by smoothing its input): the classic errors-in-variables bias.

What is done here (all in :func:`estimate`):

* **Ambient band.**  Fits and held-out tests use the orthonormal DCT-II coefficients of a residual below
  ``band_hz`` (5 Hz; the ambient dynamics live below ~2 Hz, the noise floor is measured above 5 Hz).
  The DCT (even extension) has no wrap-around edge; white noise of variance σ² gives independent
  coefficients of variance σ², a stationary coloured one approximately independent coefficients of
  variance S(f_k)·fs/2 at f_k = k·fs/(2n).
* **Input noise floors** σ_V, σ_θ: the white-noise floor (median periodogram above 5 Hz) of V and of
  θ themselves — ambient V and θ have no content there (the same rule as P's floor).
* **Output noise floors** σ_P, σ_Q: the floor of P − model(V_lp, θ_lp), the model played back on V and θ
  low-passed below the floor band, so the input noise it would propagate above 5 Hz is not counted as
  measurement noise on P and Q.  The same rule with conditional-mean inputs (below): x̂ and its error have
  nothing above the smoother's cut-off, so what is left there is P's and Q's own noise.
* **Propagation** by Monte Carlo through the model itself (any model, any candidate structure): white
  V and θ noise at σ_V, σ_θ (independent draws, a fixed seed) perturbs the inputs; the change of the
  model output (parameters fixed) is a realisation of G·e.  Its DCT coefficients, averaged over the
  draws and smoothed over ±½ Hz, give per coefficient the variances of P and Q and their covariance:
  v_P = σ_P² + ⟨(G_P e)_k²⟩, v_Q likewise, c_PQ = ⟨(G_P e)_k (G_Q e)_k⟩.
* **Conditional-mean inputs** (a segment whose V and θ are their Wiener conditional mean x̂,
  :func:`aslm_core.diagnosis.segment.conditional_mean`): the draws stand for the smoother's error e = x − x̂, white
  at the measured floors σ_V, σ_θ — the bound of its spectrum at every frequency, as P and Q see it (or, with
  ``error_draws``, the smoother's own error spectrum, :func:`draw_error`).  The residual then carries G_true·e,
  independent of the inputs the models see, so the held-out tests take no errors-in-variables bias term.

With noise on P and Q only (the paper's protocol) σ_V and σ_θ are at the level of the recordings' own
content above 5 Hz, the propagated part is negligible and every statistic reduces to the white one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from scipy import fft

from aslm_core.diagnosis.segment import Segment, _lowpass, driver_noise
from aslm_core.noise import FLOOR_FROM_HZ, noise_floor, periodogram

#: Upper edge of the ambient band the fits and held-out tests use [Hz].
BAND_HZ = 5.0
#: Monte Carlo draws of the input noise.
N_PROBES = 16
#: Width of the smoothing of the propagated-noise spectrum [Hz].
SMOOTH_HZ = 1.0


def n_band(n: int, fs: float, band_hz: float = BAND_HZ) -> int:
    """Number of DCT-II coefficients of an n-sample record below ``band_hz`` (f_k = k·fs/(2n))."""
    return int(min(n, max(1, math.ceil(2.0 * n * band_hz / fs))))


@lru_cache(maxsize=32)
def _dct_basis(n: int, m: int) -> np.ndarray:
    """The first m orthonormal DCT-II basis vectors as rows, shape (m, n)."""
    return np.ascontiguousarray(fft.dct(np.eye(n), type=2, norm="ortho", axis=0)[:m])


def band_basis(n: int, fs: float, band_hz: float = BAND_HZ) -> np.ndarray:
    """The orthonormal DCT-II rows of an n-sample record below ``band_hz`` (fs [Hz]), shape (m, n); cached."""
    return _dct_basis(n, n_band(n, fs, band_hz))


def dct_band(x: np.ndarray, fs: float, band_hz: float = BAND_HZ) -> np.ndarray:
    """Orthonormal DCT-II of x along axis 0, the coefficients below ``band_hz`` only."""
    x = np.asarray(x, dtype=np.float64)
    return band_basis(x.shape[0], fs, band_hz) @ x


def _smooth(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average (shorter at the ends)."""
    if width <= 1 or x.size < 2:
        return x
    k = np.ones(width)
    return np.convolve(x, k, mode="same") / np.convolve(np.ones_like(x), k, mode="same")


@dataclass
class NoiseModel:
    """Noise of one window's residuals (see the module docstring).

    Attributes
    ----------
    sigma_p, sigma_q : float
        White measurement noise on P and Q [pu].
    fs : float
        Sample rate [Hz].
    band_hz : float
        Upper edge of the ambient band [Hz].
    sigma_v, sigma_theta : float
        White noise on V [pu] and θ [rad] (0: noise-free inputs).
    probes_p, probes_q : ndarray, shape (k, n)
        Input noise propagated through the model: k realisations of G·e over the window [pu].
    floors : dict
        The white floors of P and Q as :func:`aslm_core.diagnosis.locate.noise_floor` gives them.
    inputs_v, inputs_theta : ndarray, shape (k, n)
        The input-noise draws behind the probes [pu, rad] (to push the same draws through another model).
    conditional_mean : bool
        The models are driven by the conditional mean of the inputs and the draws are its error: the models'
        inputs carry no part of the draws (no errors-in-variables bias in a comparison of two of them).
    """

    sigma_p: float
    sigma_q: float
    fs: float
    band_hz: float = BAND_HZ
    sigma_v: float = 0.0
    sigma_theta: float = 0.0
    probes_p: np.ndarray | None = None
    probes_q: np.ndarray | None = None
    floors: dict = field(default_factory=dict)
    inputs_v: np.ndarray | None = None
    inputs_theta: np.ndarray | None = None
    conditional_mean: bool = False
    _cache: dict = field(default_factory=dict, repr=False)
    # The segments the draws make of the last segment propagated: shared by the models :meth:`through` makes (the
    # same draws go through every candidate, and building them — Δf's and dV/dt's low-passes — was ~10 % of a
    # diagnosis).
    _drawn: dict = field(default_factory=dict, repr=False)

    @classmethod
    def white(cls, sigma_p: float, sigma_q: float, fs: float, band_hz: float = BAND_HZ) -> NoiseModel:
        """Noise on P and Q only, white with the given std [pu]."""
        return cls(float(sigma_p), float(sigma_q), float(fs), band_hz)

    def coefficients(self, sl: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Variances of P and Q and their covariance per ambient-band DCT coefficient of samples ``sl`` [pu²]."""
        key = (sl.start, sl.stop)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        m = n_band(sl.stop - sl.start, self.fs, self.band_hz)
        vp = np.full(m, self.sigma_p**2)
        vq = np.full(m, self.sigma_q**2)
        cpq = np.zeros(m)
        if self.probes_p is not None and self.probes_p.shape[0]:
            cp = dct_band(self.probes_p[:, sl].T, self.fs, self.band_hz)
            cq = dct_band(self.probes_q[:, sl].T, self.fs, self.band_hz)
            width = max(1, int(round(SMOOTH_HZ * 2.0 * (sl.stop - sl.start) / self.fs)))
            vp = vp + _smooth(np.mean(cp * cp, axis=1), width)
            vq = vq + _smooth(np.mean(cq * cq, axis=1), width)
            cpq = _smooth(np.mean(cp * cq, axis=1), width)
        tiny = 1e-300
        out = (np.maximum(vp, tiny), np.maximum(vq, tiny), cpq)
        self._cache[key] = out
        return out

    def extra_psd(self, sl: slice, ch: str) -> np.ndarray | None:
        """Mean periodogram of the propagated input noise on channel ``ch`` over samples ``sl`` (the bins of
        :func:`aslm_core.diagnosis.locate.periodogram` of a residual on those samples) [pu²/Hz], or None."""
        if self.probes_p is None or not self.probes_p.shape[0]:
            return None
        pr = self.probes_p if ch == "P" else self.probes_q
        _, pxx = periodogram(pr[:, sl], self.fs)
        mean = np.mean(pxx, axis=0)
        width = max(1, int(round(SMOOTH_HZ * (sl.stop - sl.start) / self.fs)))
        return _smooth(mean, width)

    @property
    def has_inputs(self) -> bool:
        """True when input noise is modelled (probes exist)."""
        return self.probes_p is not None and self.probes_p.shape[0] > 0

    def propagate(self, seg: Segment, output: Callable[[Segment], tuple[np.ndarray, np.ndarray] | None],
                  base: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
        """The same input-noise draws pushed through another model: arrays (k, n) of its P and Q change.

        ``output`` as in :func:`estimate`, ``base`` its output on the measured inputs.  None when input
        noise is not modelled or the model fails on a draw.
        """
        if self.inputs_v is None or not len(self.inputs_v):
            return None
        pp, pq = [], []
        for drawn in self._drawn_segments(seg):
            out = output(drawn)
            if out is None:
                return None
            pp.append(out[0] - base[0])
            pq.append(out[1] - base[1])
        return np.array(pp), np.array(pq)

    def _drawn_segments(self, seg: Segment) -> list[Segment]:
        """``seg`` perturbed by each draw (cached for the last ``seg`` and draws)."""
        key = (seg, self.inputs_v, self.inputs_theta)
        hit = self._drawn.get("key")
        if hit is None or any(a is not b for a, b in zip(hit, key, strict=True)):
            self._drawn["segs"] = [perturbed(seg, seg.V + ev, seg.theta + et)
                                   for ev, et in zip(self.inputs_v, self.inputs_theta, strict=True)]
            self._drawn["key"] = key
        return self._drawn["segs"]

    def through(self, seg: Segment, output: Callable[[Segment], tuple[np.ndarray, np.ndarray] | None],
                base: tuple[np.ndarray, np.ndarray]) -> NoiseModel:
        """The same noise (floors, draws) propagated through another model — the propagated spectrum depends
        on the model (e.g. the height of the motor's electromechanical resonance), so every test uses the
        model whose residual it tests.  ``output`` and ``base`` as in :meth:`propagate`; self if that fails."""
        prop = self.propagate(seg, output, base)
        if prop is None:
            return self
        return replace(self, probes_p=prop[0], probes_q=prop[1], _cache={})

    def location_floor(self, ch: str, sl: slice) -> dict:
        """The floor :func:`aslm_core.diagnosis.locate.locate` takes for channel ``ch`` on samples ``sl``: the
        white floor, ``extra_psd`` (propagated input noise), ``sigma`` the whole noise std and
        ``input_share`` the propagated part of the noise variance [-]."""
        fl = dict(self.floors[ch])
        total = self.total_sigma(ch, sl)
        fl["extra_psd"] = self.extra_psd(sl, ch)
        fl["sigma"] = total
        s = self.sigma_p if ch == "P" else self.sigma_q
        fl["input_share"] = max(0.0, 1.0 - (s / total) ** 2) if total > 0 else 0.0
        return fl

    def total_sigma(self, ch: str, sl: slice) -> float:
        """Std of the whole residual noise (measurement + propagated) over samples ``sl`` [pu]."""
        s = self.sigma_p if ch == "P" else self.sigma_q
        pr = self.probes_p if ch == "P" else self.probes_q
        extra = 0.0 if pr is None or not pr.shape[0] else float(np.mean(pr[:, sl] ** 2))
        return math.sqrt(s * s + extra)


def perturbed(seg: Segment, V: np.ndarray, theta: np.ndarray) -> Segment:
    """The segment with other V and θ: the dq inputs, dV/dt and (when derived from θ) Δf follow them.

    The candidates' extra columns are built from Δf and dV/dt, so an input-noise draw reaches a candidate's
    output through them as well as through the dq inputs; without them its propagated noise, and the
    errors-in-variables bias of the held-out tests estimated from it, missed that path (docs/diagnosis.md,
    "Stop 31: the frequency term with noise on V and θ").
    """
    dv, dtheta = V - seg.V, theta - seg.theta
    ddv, ddf = driver_noise(dv, dtheta, seg.fs)
    raw = {} if seg.V_raw is None else {"V_raw": seg.V_raw + dv, "theta_raw": seg.theta_raw + dtheta}
    return replace(seg, V=V, theta=theta, dvdt=seg.dvdt + ddv,
                   dfreq=seg.dfreq + ddf if seg.dfreq_from_theta else seg.dfreq, **raw)


def draw_error(freqs: np.ndarray, px: np.ndarray, n: int, fs: float, k: int,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian draws of a stationary two-channel error with a given covariance spectrum.

    Parameters
    ----------
    freqs : ndarray, shape (m,)
        Frequencies of the spectrum [Hz].
    px : ndarray, shape (m, 2, 2)
        Hermitian covariance spectrum of (V, θ) per frequency, per-sample units (white noise of variance σ² has
        the flat spectrum σ²) [pu², pu·rad, rad²] (:func:`aslm_core.noise.wiener_smooth`'s error spectrum).
    n : int
        Samples per draw.
    fs : float
        Sample rate [Hz].
    k : int
        Number of draws.
    rng : numpy.random.Generator

    Returns
    -------
    (ndarray, ndarray), each shape (k, n)
        The draws of V [pu] and θ [rad].

    Notes
    -----
    White unit noise on 2n samples, per rfft bin multiplied by L(f), the Cholesky factor of ``px`` interpolated
    there (L·Lᴴ = P_x), and the first n samples kept: a stationary series whose cross-spectrum is P_x (the
    doubled length keeps the circular filter's wrap-around correlation out of the kept samples).
    """
    m = 2 * n
    f = np.fft.rfftfreq(m, 1.0 / fs)

    def at(a: int, b: int) -> np.ndarray:
        return np.interp(f, freqs, px[:, a, b].real) + 1j * np.interp(f, freqs, px[:, a, b].imag)

    p00, p10, p11 = np.maximum(at(0, 0).real, 0.0), at(1, 0), np.maximum(at(1, 1).real, 0.0)
    l00 = np.sqrt(p00)
    l10 = np.where(l00 > 0.0, p10 / np.where(l00 > 0.0, l00, 1.0), 0.0)
    l11 = np.sqrt(np.maximum(p11 - np.abs(l10) ** 2, 0.0))
    w = np.fft.rfft(rng.standard_normal((2, k, m)), axis=2)
    ev = np.fft.irfft(l00 * w[0], n=m, axis=1)[:, :n]
    et = np.fft.irfft(l10 * w[0] + l11 * w[1], n=m, axis=1)[:, :n]
    return ev, et


def _in_band(floor: dict, seg: Segment, channel: str) -> dict:
    """A floor read above 5 Hz on ``channel`` (``v``, ``theta``, ``p``, ``q``) brought to the in-band level of a PMU
    whose reporting filter rolls off there (``seg.floor_scale``); its degrees of freedom combine the median's and the
    scale's, whose relative variances add.  Unchanged where the segment has no such filter."""
    ratio, dof = seg.floor_scale.get(channel, (1.0, math.inf))
    if ratio == 1.0 and math.isinf(dof):
        return floor
    out = dict(floor)
    out["psd"] = floor["psd"] * ratio
    out["sigma"] = floor["sigma"] * math.sqrt(ratio)
    out["dof"] = 1.0 / (1.0 / floor["dof"] + 1.0 / dof)
    return out


def estimate(seg: Segment, output: Callable[[Segment], tuple[np.ndarray, np.ndarray] | None], win: slice, *,
             n_probes: int = N_PROBES, band_hz: float = BAND_HZ, seed: int = 0,
             error_draws: bool = False, exact_quiet: bool = False) -> NoiseModel:
    """Noise model of a segment for a fitted model.

    Parameters
    ----------
    seg : Segment
        The prepared window.
    output : callable
        ``output(segment) -> (P, Q)``: the fitted model's powers over the whole window for a segment with
        the same samples but other V and θ (parameters fixed); None if the model fails.
    win : slice
        Samples the floors are measured on (after the initial transient).
    n_probes : int
        Monte Carlo draws of the input noise.
    band_hz : float
        Upper edge of the ambient band [Hz].
    seed : int
        Seed of the draws.
    error_draws : bool
        With conditional-mean inputs, draw the smoother's error spectrum (``seg.input_error``); False: white noise
        at the measured floors, the bound of that error at every frequency (the default: on ``confirm7`` and
        ``confirm8`` the smoother's spectrum left P's and Q's residual above the modelled noise at 2–5 Hz, where
        they respond to input content V itself does not show above its floor; docs/diagnosis.md, "Stop 32").
    exact_quiet : bool
        No noise on an input the segment marks exact (``seg.exact_inputs``), and P's and Q's floors from the model on
        the inputs as they are where both are (``DiagnosisConfig.exact_inputs_quiet``); False: every input's floor.

    Returns
    -------
    NoiseModel
    """
    fs = seg.fs
    # The measured inputs' floors (reported; with conditional-mean inputs the draws come from their error spectrum).
    # With exact_quiet an input the identifier's rule takes as exact carries no noise: what lies above the floor's
    # edge is its own content (at 25 frames/s the band is 5–12.5 Hz, where ambient V and θ still have some).
    exact = seg.exact_inputs if exact_quiet else (False, False)
    sv = 0.0 if exact[0] else _in_band(noise_floor(seg.v_measured[win], fs), seg, "v")["sigma"]
    st = 0.0 if exact[1] else _in_band(noise_floor(seg.theta_measured[win], fs), seg, "theta")["sigma"]
    base = output(seg)
    if base is None:
        raise ValueError("the model cannot be played back on this window")
    if all(exact):
        ref = base  # nothing to keep out of P's and Q's floors: the model on the inputs as they are
    else:
        fc = 0.8 * FLOOR_FROM_HZ
        lp = output(perturbed(seg, _lowpass(seg.V, fs, fc), _lowpass(seg.theta, fs, fc)))
        ref = lp if lp is not None else base
    fp = _in_band(noise_floor((seg.P - ref[0])[win], fs), seg, "p")
    fq = _in_band(noise_floor((seg.Q - ref[1])[win], fs), seg, "q")
    nm = NoiseModel(max(fp["sigma"], 1e-12), max(fq["sigma"], 1e-12), fs, band_hz, sv, st, floors={"P": fp, "Q": fq},
                    conditional_mean=seg.conditional_mean)
    if n_probes <= 0 or (sv <= 0 and st <= 0):
        return nm
    rng = np.random.default_rng(seed)
    if seg.conditional_mean and error_draws:
        nm.inputs_v, nm.inputs_theta = draw_error(*seg.input_error, seg.n, fs, n_probes, rng)
    else:
        nm.inputs_v = sv * rng.standard_normal((n_probes, seg.n))
        nm.inputs_theta = st * rng.standard_normal((n_probes, seg.n))
    prop = nm.propagate(seg, output, base)
    if prop is None:
        nm.inputs_v = nm.inputs_theta = None
    else:
        nm.probes_p, nm.probes_q = prop
    return nm
