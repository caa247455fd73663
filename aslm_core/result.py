"""Configuration and result objects of one identification."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Literal

import numpy as np

from aslm_core.params import DYNAMIC_NAMES

Integrator = Literal["rk4", "euler"]
Objective = Literal["paper", "ml", "ssq"]
StaticModel = Literal["zip", "exponential"]
InputSmoother = Literal["none", "wiener", "wiener_lowpass", "zero_phase"]
Disturbance = Literal["none", "ar", "ar_iv", "gated"]
StderrMethod = Literal["spectral", "ar1"]
IvEstimator = Literal["2sls", "liml"]
IvWhitening = Literal["residual", "own"]
InputWeighting = Literal["none", "spectral", "temporal"]
InputNoise = Literal["auto", "measured"]


@dataclass(frozen=True)
class IdentifyConfig:
    """Options of :func:`aslm_core.identify`.

    Attributes
    ----------
    integrator : {"rk4", "euler"}
        RK4 at the sample step, starting from the steady state that turns with the bus frequency at the
        first sample (default), or the paper's formulation: explicit Euler from the steady state at nominal
        frequency (reproduction mode).
    objective : {"paper", "ml", "ssq"}
        ``paper``: (‖r_p‖ + ‖r_q‖)/l, eq. 7.  ``ml``: Gaussian likelihood with one unknown noise
        variance per channel (weights 1/‖r‖²).  ``ssq``: plain sum of squares.
    static : {"zip", "exponential"}
        Static load model regressed in the lower stage.
    skip_s : float
        Initial transient excluded from the objective [s] (the paper's 1 s), at least.
    transient_tau : float
        Skip at least this many of the identified motor's slowest time constants (its modes linearised
        at the first sample): when that is longer than ``skip_s``, the optimum is polished once more on
        the later samples (up to ``skip_max_s``).  The motor starts from the steady state at the first
        sample, and a slow motor (τ up to ~0.5 s in the box) carries that assumption's error for
        seconds: with a fixed 1 s, 3 of 1,000 noise-free cases were off by 1–5 %.  0: the fixed skip.
    skip_max_s : float
        Longest skip the transient rule may ask for [s].
    n_starts : int
        Random feasible starts (in addition to the warm start, if given).
    lowpass_hz : float or None
        Cut-off of the optional causal Butterworth low-pass applied to V, θ, P, Q [Hz].
    input_smoother : {"none", "wiener", "wiener_lowpass", "zero_phase"}
        Smoother of the inputs V and θ before the model is played back on them (P and Q not smoothed),
        against the bias their PMU noise causes (errors in variables): ``wiener`` = their conditional
        mean given the window, the noise std taken from each channel's floor above 5 Hz;
        ``wiener_lowpass`` = the same, then (unless ``lowpass_hz`` is set) the causal low-pass of all
        four channels at half the frequency where V's or θ's signal sinks to its floor, none with exact
        inputs (the default: one default for the Python API, the CLI and the service; exact inputs
        identify as with ``none``); ``zero_phase`` = a zero-phase low-pass of V and θ at
        ``input_cutoff_hz``.  See docs/numerics.md.
    input_cutoff_hz : float
        Cut-off of the ``zero_phase`` input smoother [Hz].
    max_iter : int
        Levenberg–Marquardt iterations per start.
    seed : int or None
        Seed of the random starts (None: fixed per window for reproducibility).
    max_gap_samples : int
        Longest run of missing samples repaired by interpolation.
    min_duration_s : float
        Shortest window accepted [s].
    disturbance : {"none", "ar", "ar_iv", "gated"}
        Noise model of P and Q.  ``none``: white (output error).  ``ar``: the load's own fluctuation as
        an AR process per channel (order by BIC, up to ``ar_max_order``) estimated from the output-error
        residuals, then D by the prediction-error criterion on the whitened residuals, the AR models
        re-estimated at that optimum and the fit repeated (:mod:`aslm_core.disturbance`); standard errors
        from the whitened Jacobian.  ``ar_iv``: the same AR models, D and the static part by instrumental
        variables (the whitened regressors lagged by 2 and 3 samples, so the own fluctuation's same-sample
        effect on V and θ does not bias them; :mod:`aslm_core.instrumental`); standard errors from the IV
        moment conditions with the innovations' spectrum (``stderr_method="spectral"``) or from the white-noise
        IV covariance (``"ar1"``).  ``gated``: output error's answer where its ``own_ratio_p`` is at most
        0.3 (``OWN_UNMODELLED_RATIO``), else ``ar_iv``'s unless its instruments are rejected (``iv_overid`` above
        ``IV_OVERID_MAX``), then output error's with its warning; ``quality["gated_ar_iv"]`` says which (1: IV).
        ``gated`` is the default (one default for the Python API, the CLI and the service, with
        ``input_weighting="spectral"``: issues 11 and 20); ``none`` is output error alone.
        See docs/numerics.md.
    ar_max_order : int
        Longest AR noise model tried [samples].
    couple_channels : bool
        ``ar`` and ``ar_iv`` (and the gated estimator where the IV answers): the second channel is Q − k·P
        instead of Q, k the least-squares ratio of the Q residual to the P residual at each pass's start
        (reported as ``quality["own_q_per_p"]``).  A load's own switching moves P and Q together, so the
        combination carries little of it, and what it carries is not fed back through the network: the
        disturbance left there is the white floor.  The default (one default for the Python API, the CLI and
        the service); False gives the channels as measured.  See docs/numerics.md, "P and Q together".
    coarse_to_fine : bool
        RK4 only: random starts descend first on a coarse grid (every m-th sample, m·dt ≤ 40 ms, the
        half-step inputs taken from the measured sample in between), then polish on the full grid.
        The answer is the full grid's optimum either way; False descends on the full grid throughout.
    stderr_method : {"spectral", "ar1"}
        Output-error standard errors: the score's variance from the residual's smoothed spectrum (every
        lag of its colour; default), or the lag-1 inflation (1+ρ)/(1−ρ) of a white-noise sandwich (before
        issue 11).  ``ar_iv``: the same spectral rule on its moment conditions (and Hansen's statistic for
        ``iv_overid``), or the white-noise IV covariance and Sargan's statistic.  See docs/numerics.md.
    input_weighting : {"none", "spectral", "temporal"}
        ``spectral`` (the default, one default for the Python API, the CLI and the service): where V or θ carries
        white PMU noise (exact inputs: the output-error fit, untouched) and ``disturbance="none"`` (or ``"gated"``
        where its gate stays shut), D is refined from the output-error fit by weighting the residuals per
        frequency by the inverse of the disturbance spectrum the inputs' noise adds through the model
        (:mod:`aslm_core.input_weighting`), on the Wiener-smoothed V, θ and the unfiltered P, Q; standard errors
        from the weighted fit.  About twice the time on noisy windows.  ``none``: the output-error fit alone.
        See docs/numerics.md.
    input_spectrum_tail : bool
        The S-weighted refinement's Wiener smoother continues each input's signal spectrum above its cut-off (where
        the window's estimate sinks into the PMU floor) by a power law fitted over the octave below it, up to 5 Hz,
        instead of taking it as zero there (:func:`aslm_core.noise.wiener_smooth`'s ``tail``).  On by default (one
        default for the Python API, the CLI and the service) since its confirmation run; False: the refinement as
        before.  See docs/numerics.md, "Stop 41: the signal above the smoother's cut-off".
    iv_estimator : {"2sls", "liml"}
        Criterion of the IV fit (``ar_iv``, and ``gated`` where the IV answers): two-stage least squares, or
        limited-information maximum likelihood, whose criterion divides by the structural residual's variance
        outside the instruments, so that with weak instruments it does not pull toward the least-squares answer
        that the loop through the network biases (:class:`aslm_core.instrumental.Liml`).  See docs/numerics.md,
        "Stop 37: LIML".
    iv_whitening : {"residual", "own"}
        AR noise models of the IV fit: of the residual as it is (the load's own fluctuation plus the PMU's white noise
        on P and Q), or of the own fluctuation alone (``own``: the white noise's variance taken off where the
        residual's autocovariance is exponential, as for many small loads switching;
        :func:`aslm_core.disturbance.own_whitener`).  The instruments see the own fluctuation through V, not the
        noise: whitening the sum leaves them correlated with the residual (docs/numerics.md, "Stop 37").
    input_noise : {"auto", "measured"}
        What the channels' noise is taken to be.  ``auto`` (the default): an input whose band above 5 Hz falls
        instead of lying flat holds its own spectrum there and is taken as exact (simulated data, Table I).
        ``measured``: the channels are a PMU's, which always carry noise; a band that falls is its reporting
        filter's roll-off (an M-class PMU's), and each channel's noise is read where the filter is still flat: V's
        and θ's each from its own part at 4–6 Hz that the other channels do not explain, P's and Q's by V's ratio
        (:func:`aslm_core.preprocess.measured_floors`; flag ``input_noise_filtered``).  For
        windows from a PMU: in ``auto`` an M-class PMU's inputs are taken as exact and the answer is biased as
        without a smoother (docs/numerics.md, "Stop 55: a PMU's reporting filter").
    """

    integrator: Integrator = "rk4"
    objective: Objective = "paper"
    static: StaticModel = "zip"
    skip_s: float = 1.0
    transient_tau: float = 5.0
    skip_max_s: float = 3.0
    n_starts: int = 3
    lowpass_hz: float | None = None
    input_smoother: InputSmoother = "wiener_lowpass"
    input_cutoff_hz: float = 3.0
    max_iter: int = 60
    seed: int | None = 0
    max_gap_samples: int = 5
    min_duration_s: float = 5.0
    coarse_to_fine: bool = True
    disturbance: Disturbance = "gated"
    ar_max_order: int = 30
    couple_channels: bool = True
    stderr_method: StderrMethod = "spectral"
    input_weighting: InputWeighting = "spectral"
    input_spectrum_tail: bool = True
    iv_estimator: IvEstimator = "2sls"
    iv_whitening: IvWhitening = "residual"
    input_noise: InputNoise = "auto"

    def to_dict(self) -> dict:
        """The options as a plain dict (flat, so cheaper than ``dataclasses.asdict``)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass
class IdentificationResult:
    """Identified composite load of one window.

    Attributes
    ----------
    dynamic : dict
        D = {a [1/s], b [1/s], H2 [s], Tm [pu]}.
    static : dict
        ZIP {Pz, Pi, Pp, Qz, Qi, Qp} [pu] or exponential {P0, np, Q0, nq}.
    objective : float
        Value of the configured objective at the optimum (eq. 7 for ``paper``).
    fit : dict
        Fit degree (eq. 9) of P and Q over the regression samples: {fd_p, fd_q}.
    stderr : dict
        Standard errors of D from the Jacobian at the optimum, sandwich form of the configured objective
        (per-channel noise, residual autocorrelation).
    quality : dict
        Indicators: SNR estimates [dB], excitation (std of V [pu]), constraint margin, n samples, the
        white-noise std of the measured channels ``noise_v``, ``noise_p``, ``noise_q`` [pu] and
        ``noise_theta`` [rad], ``lowpass_hz`` the causal low-pass applied (0: none) [Hz], ``static_cond``
        (condition number of the static regressors, unit-norm columns), ``excitation_share_p``, ``_q``
        (the model's share of the measured ambient variance, white floor removed) [-], ``own_std_p``,
        ``_q`` (std of the residual's coloured part: the load's own fluctuation) [pu], ``own_ratio_p``,
        ``_q`` (that std over the measured ambient std) [-] and ``own_median_hz_p``, ``_q`` (its spectrum as one
        number: half of its variance lies below this frequency; absent when none is left) [Hz], ``input_ratio_v``, ``input_ratio_theta`` (the
        inputs' ambient std over their white PMU noise std) [-], ``floor_p``, ``floor_q`` (where P's or Q's floor
        band holds the channel's own falling content, a motor's fast response at 25–50 frames/s, the band's median;
        ``noise_p``, ``noise_q`` are then the white noise std under that content, :func:`aslm_core.noise.output_floors`)
        [pu],
        ``rk4_substeps`` (RK4 steps per sample);
        with a disturbance model ``ar_order_p``, ``_q`` (the AR orders) and, for ``ar_iv``, ``iv_strength_p``, ``_q`` (the smallest share of D's whitened information that the
        instruments keep: 1 = all, near 0 = a weak instrument and large standard errors) [-], ``iv_overid``
        (the over-identification statistic over its degrees of freedom, Hansen's with the innovations'
        spectrum: ~1 for valid instruments) [-], ``iv_overid_p`` (its χ² upper-tail probability) [-] and
        ``iv_overid_white`` (Sargan's, which assumes white innovations) [-]; where the S-weighted refinement
        answered, ``weighted_shift_z`` (the largest |D − output error's D| / SE over the parameters) [-] and, where
        its smoother was given the inputs' spectrum of the bus's previous windows (and its fit took the history's
        time-domain form, :data:`aslm_core.input_weighting.HISTORY_BAND_HZ`), ``input_spectrum_windows`` (how
        many) [-]; where a history's spectrum was given to the refinement, ``input_history_staleness`` (how far the
        window's inputs depart from it per degree of freedom, :func:`aslm_core.input_history.staleness`; ~1 for the
        same process; above 3 the history is not used) [-]; where the
        gated estimator's IV answered, ``halves_z`` (the largest |D₁ − D₂| / √(SE₁² + SE₂²) of the two
        half-window IV fits; NaN when a half cannot be identified) [-].
    flags : list of str
        Quality flags, e.g. ``at_bound:H2``, ``low_excitation``, ``restarts_disagree``,
        ``static_split_unidentifiable`` (a static coefficient's standard error above 10 % of the load),
        ``unexplained_fluctuation`` (``own_ratio_p`` above 0.7: P moves mostly for reasons V and θ do not
        explain), ``own_fluctuation_unmodelled`` (``disturbance="none"`` and ``own_ratio_p`` above 0.3: the
        white-noise fit's D and standard errors are not to be trusted; ``disturbance="ar_iv"`` models it),
        ``iv_instruments_rejected`` (``ar_iv``: ``iv_overid`` above 3, the instruments are correlated with the
        innovations and the IV estimate is biased),
        ``iv_error_may_exceed_20pct`` (``ar_iv``, and ``gated`` where the IV answers: a standard error above 6 %
        of its parameter, so an error above 20 % is not a rare draw),
        ``input_noise_too_large`` (``input_ratio_v`` below 2: V's PMU noise swamps its ambient
        variation and D is not trustworthy), ``input_noise_filtered`` (``input_noise="measured"``: V's or θ's noise
        floor falls towards the Nyquist frequency, a reporting filter's, and the falling channels' noise was raised to
        the level where the filter is flat: each channel's power by ``floor_ratio_v|theta|p|q`` [-], V's and θ's read
        at 4–6 Hz as the part of each the other channels do not explain, P and Q by V's, ``floor_plateau_ratio``),
        and since stop 28 (docs/numerics.md, "Flags that catch the tail"):
        ``input_noise_correction_large`` (the S-weighted answer's ``weighted_shift_z`` above 2.5: the
        input-noise correction moved D far in its own standard errors, so D rests on the estimated input-noise
        spectrum), ``error_may_exceed_20pct`` (the rule of ``iv_error_may_exceed_20pct`` on every other answer,
        output error's and the S-weighted refinement's: a standard error above 6 % of its parameter), ``halves_disagree`` (the gated IV answer's ``halves_z``
        above 3.5: the window's two halves disagree beyond their standard errors), and since stop 48
        ``input_history_stale`` (a history's spectrum was given and the window's ``input_history_staleness`` is above
        3: its inputs depart from that spectrum, so the window was identified alone).
    static_stderr : dict
        Standard errors of the ``static`` coefficients [pu or -] (D taken as known).
    static_local : dict
        What ambient data identify of the static part: ``V0`` (mean V) [pu], ``P0``, ``Q0`` (static power
        at V0) [pu], ``dPdV``, ``dQdV`` [pu/pu], ``kpv``, ``kqv`` (local exponents) [-], each with ``*_se``.
    """

    dynamic: dict[str, float]
    static: dict[str, float]
    objective: float
    fit: dict[str, float]
    stderr: dict[str, float]
    quality: dict[str, float]
    flags: list[str] = field(default_factory=list)
    iterations: int = 0
    starts: int = 0
    evaluations: int = 0
    elapsed_s: float = 0.0
    bus: str = ""
    config: dict = field(default_factory=dict)
    static_stderr: dict[str, float] = field(default_factory=dict)
    static_local: dict[str, float] = field(default_factory=dict)

    @property
    def d(self) -> np.ndarray:
        """D as an array [a, b, H2, Tm]."""
        return np.array([self.dynamic[k] for k in DYNAMIC_NAMES])

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dict (the CLI/REST/Zenoh payload)."""
        return asdict(self)
