"""The diagnosis report as typed parts (DESIGN §4): one dataclass per part, :meth:`to_dict` gives the JSON.

Every part always carries all of its fields; where a value does not exist (an untested candidate, a
per-window quantity of a multi-window report) it is None, i.e. ``null`` in the JSON.  The REST mirror is
:class:`service.models.DiagnosisReportModel` (its field descriptions are these ``Attributes`` sections).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field, fields, is_dataclass


def _plain(x):
    if is_dataclass(x):
        return x.to_dict()
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


class _Part:
    """JSON of a report part: its fields in declaration order, nested parts as dicts."""

    def to_dict(self) -> dict:
        """JSON-ready dict of the fields (those marked ``json=False`` in their metadata left out)."""
        return {f.name: _plain(getattr(self, f.name)) for f in fields(self) if f.metadata.get("json", True)}


def field_docs(cls: type) -> dict[str, str]:
    """Descriptions of a class's fields from its numpy-style ``Attributes`` section.

    Parameters
    ----------
    cls : type
        A class whose docstring lists ``name : type`` lines (``a, b : type`` for several) each followed
        by an indented description.

    Returns
    -------
    dict
        Field name → description (its lines joined by spaces; the type when there is no description).
    """
    lines = (inspect.getdoc(cls) or "").splitlines()
    try:
        start = next(i for i in range(len(lines) - 1) if lines[i] == "Attributes" and lines[i + 1].startswith("---"))
    except StopIteration:
        return {}
    out: dict[str, str] = {}
    names: list[str] = []
    kind = ""
    text: list[str] = []

    def flush() -> None:
        for n in names:
            out[n] = " ".join(text) or kind

    for line in lines[start + 2:]:
        if not line.strip():
            continue
        if not line.startswith(" "):
            if " : " not in line:  # the next section
                break
            flush()
            head, kind = line.split(" : ", 1)
            names, text = [n.strip() for n in head.split(",")], []
        else:
            text.append(line.strip())
    flush()
    return out


@dataclass
class PerChannel(_Part):
    """One value for each of the load's channels.

    Attributes
    ----------
    p : float or None
        For the active power P (null where not defined).
    q : float or None
        For the reactive power Q (null where not defined).
    """

    p: float | None
    q: float | None


@dataclass
class CandidateEntry(_Part):
    """One candidate physics in ``missing_physics``, tested or not (the same fields either way).

    Attributes
    ----------
    name : str
        Library name of the candidate (aslm_core.diagnosis.candidates).
    parameters : dict
        Its fitted parameters, combined over windows by inverse variance (units in ``units``); empty when untested.
    stderr : dict
        Standard errors of ``parameters``, same units (Infinity where not determined); empty when untested.
    derived : dict
        Quantities derived from the parameters, e.g. the exponents np, nq [-] or Xp [pu]; empty when none.
    units : dict
        Unit of each parameter.
    improvement : PerChannel
        Held-out residual-variance reduction per channel over the full band [-] (0 when untested).
    improvement_band : PerChannel
        The same in the ambient band below 5 Hz [-] (null when untested).
    excess_reduction : PerChannel
        Share of the held-out ambient-band residual above the noise expectation removed, per channel [-] (null without excess or when untested).
    penalised_gain : float or None
        Held-out Gaussian log-likelihood gain (over P and Q given P) minus the BIC penalty, summed over windows and
        folds [nats]; a candidate judged on the time-ordered folds only counts its mean per fold × the folds (null
        when untested).
    score_z : float
        Held-out score statistic, Stouffer-combined over windows [-] (0 when untested).
    dm_z : float
        Diebold-Mariano statistic, reported only, not used for the verdict [-] (0 when untested).
    magnitude_z : float or None
        Largest |magnitude parameter| / standard error, capped at 1e6 [-] (null when untested).
    n_params : int
        Parameters the candidate adds to ZIP + IM (the penalty's k).
    significant : bool
        Passes the score test, the penalty and the magnitude guard.
    signature : str
        What in the residual makes the candidate plausible.
    tested : bool
        Whether the candidate was fitted and tested against this model.
    note : str or None
        Why it was not tested (null when tested).
    explained_fraction : float or None
        Share of the held-out ambient-band excess the candidate removes [-]; set on the top significant candidate only.
    remaining_excess_channels : list of str or None
        Channels still above the noise floor after the candidate; set on the top significant candidate only.
    separation_z : float or None
        Paired held-out statistic that the top significant candidate explains what this one leaves (N(0, 1) when this one is right) [-]; set on every other candidate that passes the held-out test and the penalty (its magnitude aside) when the top significant one explains the mismatch, null otherwise.
    separated : bool or None
        Whether the top significant candidate is significantly better than this one (Holm over the rivals) and this one is not significantly better than it in turn (the reverse paired test); set with separation_z.
    """

    name: str
    parameters: dict[str, float]
    stderr: dict[str, float]
    derived: dict[str, float]
    units: dict[str, str]
    improvement: PerChannel
    improvement_band: PerChannel
    excess_reduction: PerChannel
    penalised_gain: float | None
    score_z: float
    dm_z: float
    magnitude_z: float | None
    n_params: int
    significant: bool
    signature: str
    tested: bool
    note: str | None = None
    explained_fraction: float | None = None
    remaining_excess_channels: list[str] | None = None
    separation_z: float | None = None
    separated: bool | None = None


@dataclass
class NoiseFloor(_Part):
    """Expected noise of one channel's residual.

    Attributes
    ----------
    psd : float
        White-noise floor: median periodogram above 5 Hz / ln 2 [pu²/Hz].
    sigma : float
        Whole residual noise std, measurement plus propagated input noise [pu].
    band_hz : list of float
        Band the floor was measured in [Hz].
    bins : int
        Periodogram bins in that band.
    input_share : float
        Share of the noise variance propagated from the V and θ noise [-].
    """

    psd: float
    sigma: float
    band_hz: list[float]
    bins: int
    input_share: float


@dataclass
class BandTest(_Part):
    """Residual power in one band against the expected noise (F test).

    Attributes
    ----------
    band : list of float
        Band edges [Hz].
    ratio : float
        Mean residual PSD over the expected noise PSD in the band [-].
    excess_var : float
        Residual variance above the expected noise in the band [pu²].
    p_value : float
        P-value of the F test [-].
    significant : bool
        Below 1 % Bonferroni-corrected over 8 tests.
    """

    band: list[float]
    ratio: float
    excess_var: float
    p_value: float
    significant: bool


@dataclass
class CoherenceStat(_Part):
    """Coherence of a residual with one driver over 0.1-2 Hz.

    Attributes
    ----------
    mean : float
        Mean magnitude-squared coherence [-].
    max : float
        Largest magnitude-squared coherence [-].
    """

    mean: float
    max: float


@dataclass
class Coherence(_Part):
    """Coherence (Welch) of one channel's residual with what drives the load.

    Attributes
    ----------
    threshold : float
        Level one bin exceeds with probability 1 % when residual and driver are independent [-].
    V : CoherenceStat
        With the voltage magnitude V.
    dVdt : CoherenceStat
        With its derivative dV/dt.
    df : CoherenceStat
        With the bus frequency deviation Δf.
    """

    threshold: float
    V: CoherenceStat
    dVdt: CoherenceStat
    df: CoherenceStat


@dataclass
class Location(_Part):
    """Where the residual exceeds the expected noise (on the model refitted on the whole window).

    Attributes
    ----------
    channels : list of str
        Channels (P, Q) with a significant and material excess.
    bands : dict
        Per located channel, the significant bands [[f_lo, f_hi], ...] [Hz].
    time_segments : dict
        Per located channel, the intervals above the floor: [t_start, t_end] [s] for one window, [window index, t_start, t_end] for several.
    noise_floor : dict or None
        Per channel, the expected noise (one window; null for several: see ``windows``).
    spectrum : dict or None
        Per channel, the band tests of 0.05-0.5, 0.5-1, 1-2, 2-5 Hz (one window; null for several).
    coherence : dict or None
        Per channel, the residual's coherence with V, dV/dt and Δf (one window; null for several).
    excess_over_noise : dict or None
        Per channel, the in-band variance above the noise over the noise variance [-] (one window; null for several).
    windows : list of Location or None
        The location of each window when several are diagnosed together (null for one).
    """

    channels: list[str]
    bands: dict[str, list[list[float]]]
    time_segments: dict[str, list[list[float]]]
    noise_floor: dict[str, NoiseFloor] | None = None
    spectrum: dict[str, list[BandTest]] | None = None
    coherence: dict[str, Coherence] | None = None
    excess_over_noise: dict[str, float] | None = None
    windows: list[Location] | None = None

    @classmethod
    def from_locate(cls, d: dict) -> Location:
        """The part for one window from :func:`aslm_core.diagnosis.locate.locate`'s dict (drivers V, dVdt, df).

        Parameters
        ----------
        d : dict
            The output of ``locate``.
        """
        chans = d["noise_floor"]
        return cls(
            channels=list(d["channels"]), bands=d["bands"], time_segments=d["time_segments"],
            noise_floor={ch: NoiseFloor(**d["noise_floor"][ch]) for ch in chans},
            spectrum={ch: [BandTest(**b) for b in d["spectrum"][ch]] for ch in chans},
            coherence={ch: Coherence(threshold=c["threshold"], V=CoherenceStat(**c["V"]),
                                     dVdt=CoherenceStat(**c["dVdt"]), df=CoherenceStat(**c["df"]))
                       for ch, c in d["coherence"].items()},
            excess_over_noise=d["excess_over_noise"],
        )


@dataclass
class HeldOutFit(_Part):
    """Fit of a model on the held-out samples.

    Attributes
    ----------
    fd_p : float
        Fit degree of P (paper eq. 9) [-].
    fd_q : float
        Fit degree of Q (paper eq. 9) [-].
    rms_p : float
        RMS of the P residual [pu].
    rms_q : float
        RMS of the Q residual [pu].
    """

    fd_p: float
    fd_q: float
    rms_p: float
    rms_q: float


@dataclass
class NoiseSummary(_Part):
    """The noise model, averaged over windows.

    Attributes
    ----------
    sigma_p : float
        Whole residual noise std of P: measurement plus propagated input noise [pu].
    sigma_q : float
        The same for Q [pu].
    sigma_v : float
        White noise floor of V [pu].
    sigma_theta : float
        White noise floor of θ [rad].
    input_share_p : float
        Share of P's noise variance propagated from the V and θ noise [-].
    input_share_q : float
        The same for Q [-].
    """

    sigma_p: float
    sigma_q: float
    sigma_v: float
    sigma_theta: float
    input_share_p: float
    input_share_q: float


@dataclass
class HeldOutInfo(_Part):
    """The held-out samples every comparison is made on.

    Attributes
    ----------
    windows : int
        Windows diagnosed together.
    t_start : list of float
        Per fold, time of the first held-out sample [s]: each window's time-ordered fold (held out after the
        training samples), then, when cross-fitted, each window's mirrored fold (held out first).
    t_end : list of float
        Per fold, time of the last held-out sample [s] (the order of ``t_start``).
    n : int
        Held-out samples over all folds.
    dm_critical : float
        One-sided critical value of the score statistic, 1 % Bonferroni-corrected over the tested candidates [-].
    folds : int
        Held-out folds per window: 2 when cross-fitted (``DiagnosisConfig.cross_fit``), 1 otherwise or when a
        window's mirrored fold could not be fitted (``t_start`` then lists the folds judged) [-].
    """

    windows: int
    t_start: list[float]
    t_end: list[float]
    n: int
    dm_critical: float
    folds: int = 1


@dataclass
class Motor(_Part):
    """A motor's parameters.

    Attributes
    ----------
    dynamic : dict
        D = {a [1/s], b [1/s], H2 [s], Tm [pu]}.
    """

    dynamic: dict[str, float]


@dataclass
class Diagnosed(Motor):
    """The plain ZIP + IM model the candidates extend (of the first window).

    Attributes
    ----------
    dynamic : dict
        D = {a [1/s], b [1/s], H2 [s], Tm [pu]}.
    mode : str
        identified (fitted on the training samples) or user (the given model, frozen).
    at_bound : dict
        The parameters of D on a bound of the identifier's box in any window {name: the bound} (identified mode;
        empty when none): a cause is then named only if it beats, on the held-out data, the plain model refitted
        with the box opened there (a motor outside the box); and when that refit does not beat the plain model,
        a cause that changes the motor is not named while its own D stays on that bound and it leaves a located
        excess (``DiagnosisConfig.bound_rule``).
    """

    mode: str
    at_bound: dict[str, float] = field(default_factory=dict)


@dataclass
class ParameterMismatch(_Part):
    """Against a user model: would re-identifying the same ZIP + IM structure fit the held-out data better.

    Attributes
    ----------
    significant : bool
        Whether the re-identified model passes the score test and the penalty (wrong parameters, not missing physics).
    score_z : float
        Its held-out score statistic [-].
    improvement : PerChannel
        Its held-out residual-variance reduction per channel [-].
    reidentified : Motor
        The re-identified motor.
    """

    significant: bool
    score_z: float
    improvement: PerChannel
    reidentified: Motor


@dataclass
class DiagnosisReport(_Part):
    """Outcome of a diagnosis (JSON via :meth:`to_dict`, DESIGN §4).

    Attributes
    ----------
    verdict : str
        explained, ambiguous, consistent or unexplained.
    cause : str or None
        The named cause when explained; null otherwise (also when ambiguous: no pick).
    causes : list of str
        The candidates that explain the mismatch and that the held-out data do not separate, ordered by penalised gain: the one cause when explained, two or more when ambiguous, empty otherwise.
    located : Location
        Where the residual exceeds the expected noise.
    missing_physics : list of CandidateEntry
        Every candidate of the library, ranked by penalised gain (untested ones last).
    fit_before : HeldOutFit
        Held-out fit of the plain model.
    fit_after : HeldOutFit
        Held-out fit of the named cause (equal to fit_before when nothing is named).
    model : Diagnosed
        The plain model.
    noise : NoiseSummary
        The noise model.
    held_out : HeldOutInfo
        The held-out samples and the test's critical value.
    message : str
        One sentence for people.
    mode : str
        identified or user.
    parameter_mismatch : ParameterMismatch or None
        Against a user model only (null otherwise).
    elapsed_s : float
        Time the diagnosis took [s].
    series : list
        Time series for the report's plots, one dict per window (not in the JSON).
    """

    verdict: str
    cause: str | None
    causes: list[str]
    located: Location
    missing_physics: list[CandidateEntry]
    fit_before: HeldOutFit
    fit_after: HeldOutFit
    model: Diagnosed
    noise: NoiseSummary
    held_out: HeldOutInfo
    message: str
    mode: str = "identified"
    parameter_mismatch: ParameterMismatch | None = None
    elapsed_s: float = 0.0
    series: list = field(default_factory=list, repr=False, metadata={"json": False})

    def candidate(self, name: str) -> CandidateEntry:
        """The entry of one candidate.

        Parameters
        ----------
        name : str
            Library name.
        """
        for e in self.missing_physics:
            if e.name == name:
                return e
        raise KeyError(f"no candidate {name!r} in the report (not in DiagnosisConfig.candidates?)")
