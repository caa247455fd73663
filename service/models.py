"""Data objects shared by storage, publication and the REST API (pydantic, so they document OpenAPI)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from aslm_core.params import DYNAMIC_PARAMS, EXPONENTIAL_PARAMS, ZIP_PARAMS, ParamSpec

Status = Literal["ok", "failed", "skipped"]
PeriodStatus = Literal["completed", "overrun", "interrupted"]


def _listed(params: tuple[ParamSpec, ...]) -> str:
    """``{a [1/s], b [1/s], ...}``: names and units as :mod:`aslm_core.params` declares them."""
    return "{" + ", ".join(f"{p.name} [{p.unit}]" for p in params) + "}"


class Identified(BaseModel):
    """Output of :func:`aslm_core.identify` for one window (``IdentificationResult.to_dict()``)."""

    model_config = ConfigDict(extra="allow")

    dynamic: dict[str, float] = Field(description=f"D = {_listed(DYNAMIC_PARAMS)}")
    static: dict[str, float] = Field(
        description=f"ZIP {_listed(ZIP_PARAMS)} or exponential {_listed(EXPONENTIAL_PARAMS)}")
    objective: float | None = Field(description="Objective value at the optimum")
    fit: dict[str, float | None] = Field(description="Fit degree of P and Q (paper eq. 9): {fd_p, fd_q}")
    stderr: dict[str, float | None] = Field(default_factory=dict, description="Standard errors of D (null: not available)")
    quality: dict[str, float | None] = Field(
        default_factory=dict,
        description="SNR [dB], excitation, margins; noise floors noise_v|theta|p|q; static_cond; "
                    "excitation_share_p|q (the share of the ambient P/Q variance V and θ explain) [-], "
                    "own_std_p|q (the load's own fluctuation: the residual's coloured part) [pu], own_ratio_p|q [-], "
                    "own_median_hz_p|q (half of the own fluctuation's variance lies below it; absent: none left) [Hz]; "
                    "where the AR/IV fit ran, own_q_per_p (ΔQ/ΔP of the own fluctuation, k of its second "
                    "channel Q − k·P) [-]; input_spectrum_windows (noisy V and θ smoothed with their spectrum "
                    "pooled from this many of the bus's previous windows; absent: from this window alone) [-]; "
                    "input_history_staleness (how far the window's V and θ depart from that history's spectrum, ~1 for "
                    "the same process; above 3 the window is identified alone and flagged input_history_stale) [-]; "
                    "with input_noise='measured' (a PMU's channels), inputs_measured (1), floor_plateau_ratio (where a "
                    "reporting filter makes the floor band fall, the noise where the filter is flat over the band's "
                    "median, read on V, on θ where V's band is white; flag input_noise_filtered) [-], "
                    "floor_plateau_dof (that ratio's degrees of freedom) [-], floor_ratio_v|theta|p|q (the factor "
                    "each channel's noise power was raised by, 1 where its band is white: V and θ each by its own "
                    "reading, P and Q by floor_plateau_ratio) [-] and floor_dof_theta (θ's reading's degrees of "
                    "freedom) [-]; where P's or Q's floor band holds the channel's own falling content (a motor's "
                    "fast response at 25–50 frames/s) rather than noise alone, floor_p|q (the band's median; "
                    "noise_p|q are then the white noise std under that content) [pu]")
    flags: list[str] = Field(default_factory=list,
                             description="Quality flags, e.g. at_bound:H2, static_split_unidentifiable")
    static_stderr: dict[str, float | None] = Field(
        default_factory=dict, description="Standard errors of the static coefficients (same keys as static)")
    static_local: dict[str, float | None] = Field(
        default_factory=dict,
        description="What ambient data identify of the static part: V0 (mean V) [pu], P0, Q0 at V0 [pu], "
                    "dPdV, dQdV [pu/pu], kpv, kqv (local exponents) [-], each with *_se")
    elapsed_s: float = Field(0.0, description="Identification time in the worker [s]")


class BusResult(BaseModel):
    """One bus, one period: identified parameters, or why there are none."""

    bus: str = Field(description="Bus identifier (the {bus} of {prefix}/pmu/{bus})")
    period: float = Field(description="Period boundary, UTC since the epoch [s]")
    period_s: float = Field(description="Period length T in force for this period [s]")
    status: Status = Field(description="ok, failed (worker error/timeout/crash) or skipped (window quality)")
    reason: str | None = Field(None, description="Why failed or skipped, e.g. coverage, timeout, worker_crashed")
    window_start: float | None = Field(None, description="PMU time of the window's first frame [s]")
    window_end: float | None = Field(None, description="PMU time of the window's last frame [s]")
    n_frames: int = Field(0, description="Frames in the window")
    warm_start: bool = Field(False, description="Started from the bus's previous result")
    completed_at: float = Field(description="Wall-clock time the result was recorded [s]")
    parameters: Identified | None = Field(None, description="Identification output when status is ok")
    clock_offset_s: float | None = Field(
        None, description="With reason clock_offset: PMU time of the bus's newest frame minus the clock time it "
        "arrived [s] (negative: the PMU clock is behind; includes transport delay)")


class PeriodSummary(BaseModel):
    """One completed period."""

    period: float = Field(description="Boundary, UTC since the epoch [s]")
    period_s: float = Field(description="Period length T [s]")
    n_ok: int
    n_failed: int
    n_skipped: int
    latency_s: float = Field(description="From the end of the late-data allowance to the last result published "
                                         "(overrun, interrupted: to when the record was made) [s]")
    completed_at: float
    status: PeriodStatus = Field(
        "completed", description="completed; overrun (not run: the previous period was still running at its "
                                 "boundary, or the scheduler was restarting); interrupted (the service stopped "
                                 "or failed while it ran, recorded at the next start)")
    no_result: list[str] = Field(
        default_factory=list, description="Buses known at the boundary that got no result (overrun, interrupted)")


# --- diagnosis ------------------------------------------------------------------------------------
# A field-for-field mirror of aslm_core.diagnosis.report (descriptions are its Attributes sections;
# tests/aslm_core/diagnosis/test_diagnosis_report.py keeps the two from drifting).  The service never imports aslm_core in its
# main process (numba), hence a mirror and not the dataclasses themselves.


class PerChannelModel(BaseModel):
    """One value for each of the load's channels."""

    p: float | None = Field(description="For the active power P (null where not defined).")
    q: float | None = Field(description="For the reactive power Q (null where not defined).")


class CandidateEntryModel(BaseModel):
    """One candidate physics in ``missing_physics``, tested or not (the same fields either way)."""

    name: str = Field(description="Library name of the candidate (aslm_core.diagnosis.candidates).")
    parameters: dict[str, float] = Field(description="Its fitted parameters, combined over windows by inverse variance (units in ``units``); empty when untested.")
    stderr: dict[str, float] = Field(description="Standard errors of ``parameters``, same units (Infinity where not determined); empty when untested.")
    derived: dict[str, float] = Field(description="Quantities derived from the parameters, e.g. the exponents np, nq [-] or Xp [pu]; empty when none.")
    units: dict[str, str] = Field(description="Unit of each parameter.")
    improvement: PerChannelModel = Field(description="Held-out residual-variance reduction per channel over the full band [-] (0 when untested).")
    improvement_band: PerChannelModel = Field(description="The same in the ambient band below 5 Hz [-] (null when untested).")
    excess_reduction: PerChannelModel = Field(description="Share of the held-out ambient-band residual above the noise expectation removed, per channel [-] (null without excess or when untested).")
    penalised_gain: float | None = Field(description="Held-out Gaussian log-likelihood gain (over P and Q given P) minus the BIC penalty, summed over windows and folds [nats]; a candidate judged on the time-ordered folds only counts its mean per fold × the folds (null when untested).")
    score_z: float = Field(description="Held-out score statistic, Stouffer-combined over windows [-] (0 when untested).")
    dm_z: float = Field(description="Diebold-Mariano statistic, reported only, not used for the verdict [-] (0 when untested).")
    magnitude_z: float | None = Field(description="Largest |magnitude parameter| / standard error, capped at 1e6 [-] (null when untested).")
    n_params: int = Field(description="Parameters the candidate adds to ZIP + IM (the penalty's k).")
    significant: bool = Field(description="Passes the score test, the penalty and the magnitude guard.")
    signature: str = Field(description="What in the residual makes the candidate plausible.")
    tested: bool = Field(description="Whether the candidate was fitted and tested against this model.")
    note: str | None = Field(None, description="Why it was not tested (null when tested).")
    explained_fraction: float | None = Field(None, description="Share of the held-out ambient-band excess the candidate removes [-]; set on the top significant candidate only.")
    remaining_excess_channels: list[str] | None = Field(None, description="Channels still above the noise floor after the candidate; set on the top significant candidate only.")
    separation_z: float | None = Field(None, description="Paired held-out statistic that the top significant candidate explains what this one leaves (N(0, 1) when this one is right) [-]; set on every other candidate that passes the held-out test and the penalty (its magnitude aside) when the top significant one explains the mismatch, null otherwise.")
    separated: bool | None = Field(None, description="Whether the top significant candidate is significantly better than this one (Holm over the rivals) and this one is not significantly better than it in turn (the reverse paired test); set with separation_z.")


class NoiseFloorModel(BaseModel):
    """Expected noise of one channel's residual."""

    psd: float = Field(description="White-noise floor: median periodogram above 5 Hz / ln 2 [pu²/Hz].")
    sigma: float = Field(description="Whole residual noise std, measurement plus propagated input noise [pu].")
    band_hz: list[float] = Field(description="Band the floor was measured in [Hz].")
    bins: int = Field(description="Periodogram bins in that band.")
    input_share: float = Field(description="Share of the noise variance propagated from the V and θ noise [-].")


class BandTestModel(BaseModel):
    """Residual power in one band against the expected noise (F test)."""

    band: list[float] = Field(description="Band edges [Hz].")
    ratio: float = Field(description="Mean residual PSD over the expected noise PSD in the band [-].")
    excess_var: float = Field(description="Residual variance above the expected noise in the band [pu²].")
    p_value: float = Field(description="P-value of the F test [-].")
    significant: bool = Field(description="Below 1 % Bonferroni-corrected over 8 tests.")


class CoherenceStatModel(BaseModel):
    """Coherence of a residual with one driver over 0.1-2 Hz."""

    mean: float = Field(description="Mean magnitude-squared coherence [-].")
    max: float = Field(description="Largest magnitude-squared coherence [-].")


class CoherenceModel(BaseModel):
    """Coherence (Welch) of one channel's residual with what drives the load."""

    threshold: float = Field(description="Level one bin exceeds with probability 1 % when residual and driver are independent [-].")
    V: CoherenceStatModel = Field(description="With the voltage magnitude V.")
    dVdt: CoherenceStatModel = Field(description="With its derivative dV/dt.")
    df: CoherenceStatModel = Field(description="With the bus frequency deviation Δf.")


class LocationModel(BaseModel):
    """Where the residual exceeds the expected noise (on the model refitted on the whole window)."""

    channels: list[str] = Field(description="Channels (P, Q) with a significant and material excess.")
    bands: dict[str, list[list[float]]] = Field(description="Per located channel, the significant bands [[f_lo, f_hi], ...] [Hz].")
    time_segments: dict[str, list[list[float]]] = Field(description="Per located channel, the intervals above the floor: [t_start, t_end] [s] for one window, [window index, t_start, t_end] for several.")
    noise_floor: dict[str, NoiseFloorModel] | None = Field(None, description="Per channel, the expected noise (one window; null for several: see ``windows``).")
    spectrum: dict[str, list[BandTestModel]] | None = Field(None, description="Per channel, the band tests of 0.05-0.5, 0.5-1, 1-2, 2-5 Hz (one window; null for several).")
    coherence: dict[str, CoherenceModel] | None = Field(None, description="Per channel, the residual's coherence with V, dV/dt and Δf (one window; null for several).")
    excess_over_noise: dict[str, float] | None = Field(None, description="Per channel, the in-band variance above the noise over the noise variance [-] (one window; null for several).")
    windows: list[LocationModel] | None = Field(None, description="The location of each window when several are diagnosed together (null for one).")


class HeldOutFitModel(BaseModel):
    """Fit of a model on the held-out samples."""

    fd_p: float = Field(description="Fit degree of P (paper eq. 9) [-].")
    fd_q: float = Field(description="Fit degree of Q (paper eq. 9) [-].")
    rms_p: float = Field(description="RMS of the P residual [pu].")
    rms_q: float = Field(description="RMS of the Q residual [pu].")


class NoiseSummaryModel(BaseModel):
    """The noise model, averaged over windows."""

    sigma_p: float = Field(description="Whole residual noise std of P: measurement plus propagated input noise [pu].")
    sigma_q: float = Field(description="The same for Q [pu].")
    sigma_v: float = Field(description="White noise floor of V [pu].")
    sigma_theta: float = Field(description="White noise floor of θ [rad].")
    input_share_p: float = Field(description="Share of P's noise variance propagated from the V and θ noise [-].")
    input_share_q: float = Field(description="The same for Q [-].")


class HeldOutInfoModel(BaseModel):
    """The held-out samples every comparison is made on."""

    windows: int = Field(description="Windows diagnosed together.")
    t_start: list[float] = Field(description="Per fold, time of the first held-out sample [s]: each window's time-ordered fold (held out after the training samples), then, when cross-fitted, each window's mirrored fold (held out first).")
    t_end: list[float] = Field(description="Per fold, time of the last held-out sample [s] (the order of ``t_start``).")
    n: int = Field(description="Held-out samples over all folds.")
    dm_critical: float = Field(description="One-sided critical value of the score statistic, 1 % Bonferroni-corrected over the tested candidates [-].")
    folds: int = Field(1, description="Held-out folds per window: 2 when cross-fitted (``DiagnosisConfig.cross_fit``), 1 otherwise or when a window's mirrored fold could not be fitted (``t_start`` then lists the folds judged) [-].")


class MotorModel(BaseModel):
    """A motor's parameters."""

    dynamic: dict[str, float] = Field(description="D = {a [1/s], b [1/s], H2 [s], Tm [pu]}.")


class DiagnosedModel(MotorModel):
    """The plain ZIP + IM model the candidates extend (of the first window)."""

    mode: Literal["identified", "user"] = Field(description="identified (fitted on the training samples) or user (the given model, frozen).")
    at_bound: dict[str, float] = Field(default_factory=dict, description="The parameters of D on a bound of the identifier's box in any window {name: the bound} (identified mode; empty when none): a cause is then named only if it beats, on the held-out data, the plain model refitted with the box opened there (a motor outside the box); and when that refit does not beat the plain model, a cause that changes the motor is not named while its own D stays on that bound and it leaves a located excess (``DiagnosisConfig.bound_rule``).")


class ParameterMismatchModel(BaseModel):
    """Against a user model: would re-identifying the same ZIP + IM structure fit the held-out data better."""

    significant: bool = Field(description="Whether the re-identified model passes the score test and the penalty (wrong parameters, not missing physics).")
    score_z: float = Field(description="Its held-out score statistic [-].")
    improvement: PerChannelModel = Field(description="Its held-out residual-variance reduction per channel [-].")
    reidentified: MotorModel = Field(description="The re-identified motor.")


class DiagnosisReportModel(BaseModel):
    """Outcome of a diagnosis (DESIGN §4)."""

    verdict: Literal["explained", "ambiguous", "consistent", "unexplained"] = Field(description="explained, ambiguous, consistent or unexplained.")
    cause: str | None = Field(description="The named cause when explained; null otherwise (also when ambiguous: no pick).")
    causes: list[str] = Field(description="The candidates that explain the mismatch and that the held-out data do not separate, ordered by penalised gain: the one cause when explained, two or more when ambiguous, empty otherwise.")
    located: LocationModel = Field(description="Where the residual exceeds the expected noise.")
    missing_physics: list[CandidateEntryModel] = Field(description="Every candidate of the library, ranked by penalised gain (untested ones last).")
    fit_before: HeldOutFitModel = Field(description="Held-out fit of the plain model.")
    fit_after: HeldOutFitModel = Field(description="Held-out fit of the named cause (equal to fit_before when nothing is named).")
    model: DiagnosedModel = Field(description="The plain model.")
    noise: NoiseSummaryModel = Field(description="The noise model.")
    held_out: HeldOutInfoModel = Field(description="The held-out samples and the test's critical value.")
    message: str = Field(description="One sentence for people.")
    mode: Literal["identified", "user"] = Field("identified", description="identified or user.")
    parameter_mismatch: ParameterMismatchModel | None = Field(None, description="Against a user model only (null otherwise).")
    elapsed_s: float = Field(0.0, description="Time the diagnosis took [s].")



class BusDiagnosis(DiagnosisReportModel):
    """A bus's diagnosis as the service stores, publishes on {prefix}/diagnosis/{bus} and serves it."""

    bus: str = Field(description="Bus identifier (the {bus} of {prefix}/pmu/{bus})")
    period: float = Field(description="Period boundary of the diagnosed window, UTC since the epoch [s]")


class FailedDiagnosis(BaseModel):
    """A diagnosis the worker could not complete: why, and nothing else."""

    bus: str = Field(description="Bus identifier (the {bus} of {prefix}/pmu/{bus})")
    period: float = Field(description="Period boundary of the diagnosed window, UTC since the epoch [s]")
    verdict: Literal["failed"] = Field(description="failed")
    reason: str | None = Field(description="window:<reason>, error:<ExceptionType>, timeout, worker_crashed, shutdown, "
                                           "or shed (not started before the next round of diagnoses was queued)")
    message: str = Field(description="What went wrong, for people")


#: What ``GET /buses/{bus}/diagnosis/latest`` answers: a report, or a failure (told apart by ``verdict``).
LatestDiagnosis = Annotated[BusDiagnosis | FailedDiagnosis, Field(discriminator="verdict")]


# --- tracking ---------------------------------------------------------------------------------------
class TrackedSummary(BaseModel):
    """A pool of windows' combined motor D (information-weighted mean of the windows' estimates)."""

    dynamic: dict[str, float] = Field(description=f"D = {_listed(DYNAMIC_PARAMS)}")
    stderr: dict[str, float | None] = Field(description="Standard errors of D (null: not determined)")
    n_windows: int = Field(description="Windows combined")


class TrackedModel(TrackedSummary):
    """The tracked model of a bus: its current best D, pooled since the last change (docs/tracking.md)."""

    bus: str
    period: float = Field(description="Period of the newest pooled window, UTC [s]")
    since: float = Field(description="Period of the oldest pooled window, UTC [s]")
    last_change: float | None = Field(description="Period of the first window after the last detected change, "
                                                  "UTC [s] (null: none since the tracking started)")
    suspect: bool = Field(description="The newest window stood out and is held out of the pool until the next one "
                                      "confirms a change or clears it")
    static: dict[str, float] = Field(description="Static part of the newest successful window (not pooled)")
    static_local: dict[str, float | None] = Field(default_factory=dict,
                                                  description="Its level and slope at V0 (as in parameters)")
    pool_windows: int = Field(description="Longest pool k in force [windows]")
    threshold: float = Field(description="Detector threshold h on the standardised innovations [-]")
    estimator: Literal["joint", "mean"] = Field(
        "mean", description="How dynamic and stderr were pooled: joint (one fit of D to the pool's windows, "
        "track_joint_fit; n_windows: the windows fitted, a winsorised outlier left out) or mean (the "
        "information-weighted mean of the windows' estimates, until the joint fit of this pool arrives)")
    disturbance: Literal["none", "ar_iv"] | None = Field(
        None, description="With estimator joint: the pool's disturbance model, none (white noise per window) or "
        "ar_iv (the load's own fluctuation dominates P: the pooled instrumental-variable fit, docs/tracking.md); "
        "null with the mean")


class ChangeEvidence(BaseModel):
    """Why a change was declared."""

    param: str = Field(description="Parameter that moved (a, b, H2 or Tm)")
    z: list[float] = Field(description="The two windows' standardised innovations on it [-]")
    threshold: float = Field(description="Threshold h [-]")
    z_all: list[list[float]] = Field(description="Both windows' innovations on a, b, H2, Tm [-]")


class ChangeEvent(BaseModel):
    """A detected change of a bus's load model."""

    bus: str
    t: float = Field(description="Period of the first window after the change, UTC [s]")
    detected_t: float = Field(description="Period of the window that confirmed it, UTC [s]")
    before: TrackedSummary = Field(description="The tracked model before the change")
    after: TrackedSummary = Field(description="The pool of the two windows after it")
    evidence: ChangeEvidence
