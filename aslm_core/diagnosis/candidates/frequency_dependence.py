"""``frequency_dependence``: load power sensitive to the bus frequency deviation.

Notes
-----
A linear extra term on each channel (lower stage) of the frequency the load responds to, a first-order lag
of the bus frequency::

    Tf·dΔf_m/dt = Δf − Δf_m
    P = P_ZIP(V) + P_im(D) + Kpf·Δf_m
    Q = Q_ZIP(V) + Q_im(D) + Kqf·Δf_m

with Δf = f − f0 [Hz] the bus frequency deviation (the recorded ``f``, else dθ/dt/2π), low-passed at
5 Hz (zero phase), and Δf_m its lag (trapezoidal rule, from rest at Δf(0)).  Parameters: Kpf [pu/Hz],
Kqf [pu/Hz] (on the system base; divide by the static P or Q and multiply by f0 for the usual per-unit
sensitivity, e.g. Kpf·f0/P0 ≈ 0–3 for mixed loads) and Tf [s] in [0, :data:`TF_MAX_S`], one nonlinear
parameter of the upper stage started from a scan (:func:`aslm_core.diagnosis.lag.lag_start`).  Tf = 0 is the
instantaneous law.

Why the lag: a frequency-dependent load responds to a frequency *estimate*, not to dθ/dt itself — simulators
model it so (ANDES's ``FLoad`` reads its ``BusFreq`` device: a 0.02 s lag on the bus angle, then a washout
s/(1 + 0.1 s), i.e. the angle's derivative through two first-order lags, 39° behind Δf at 1 Hz), and a
load's own controls and mechanics add their delay.  Without it, on the 42 noise-free ANDES FLoad windows the
instantaneous law left a median 23 % (9–48 %) of the plain model's held-out residual, the lagged one 4 %
(2–25 %), with Tf = 0.11–0.13 s on all but one scenario (docs/diagnosis.md, fifth round).

Signature: the plain-model residual is coherent with Δf in the ambient band (0.1–2 Hz), more than with
V or dV/dt.  The induction motor of eq. 4 already responds to Δf (it is driven in the synchronous frame),
so only a frequency response *in addition to* the motor's is attributed here.

Plausibility: a load's per-unit frequency sensitivity max(|Kpf|, |Kqf|)·f0/|P̄| (P̄ the window's mean P)
above :data:`MAX_PU_SENSITIVITY` is not a frequency dependence: loads have 0–3, and on the independent
(ANDES) development set the FLoad cases gave at most 2.8 while load steps timed by their own thermostats —
whose edges make dθ/dt bump — were fitted with 11–24.
"""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.candidates.base import Candidate, Context
from aslm_core.diagnosis.lag import lag_start, lagged
from aslm_core.diagnosis.segment import Segment

MAX_PU_SENSITIVITY = 8.0  # [-]
#: Upper bound of the lag [s]: frequency estimators and load controls answer within a few tenths of a second;
#: a slower "frequency" response is the slip dynamics of a motor, which the torque candidates describe.
TF_MAX_S = 0.5
#: Scan of Tf's start [s] (0 is the instantaneous law).
TF_GRID_S = (0.0, 0.05, 0.1, 0.2, 0.4)


class FrequencyDependence(Candidate):
    name = "frequency_dependence"
    magnitude = ("Kpf", "Kqf")
    nl_names = ("Tf",)
    nl_units = ("s",)
    lin_p = ("Kpf",)
    lin_q = ("Kqf",)
    lin_units = {"Kpf": "pu/Hz", "Kqf": "pu/Hz"}
    signature = "residual coherent with the bus frequency deviation Δf (0.1–2 Hz), possibly lagging it"
    # A torque that varies with speed also answers Δf through the slip, with a lag of its own: on the noise-free
    # ANDES windows the lagged law and the torque law are not separable in 30 of 42 torque windows at 14 dB
    # (benchmarks/diagnosis_separability.py), and with V/θ noise the lag's penalty left the torque law out of
    # the rivals while it fitted as well.
    confusable = ("speed_dependent_torque",)

    def bounds(self, seg: Segment, ctx: Context):
        return np.array([0.0]), np.array([TF_MAX_S])

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        # The instantaneous law is always tried too: the scan, with D frozen at the plain fit, chose 0.4 s on a
        # self-test case whose truth is instantaneous, and the fit from there stayed at Tf = 0.48 s with Kqf a
        # tenth of the truth (the torque law then ranked first and explained too little: `unexplained`).
        t = lag_start(seg, ctx, seg.dfreq, TF_GRID_S, 0.0)
        return [np.array([t])] if t == 0.0 else [np.array([t]), np.array([0.0])]

    def extra_columns(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        col = lagged(seg.dfreq, float(z[0]), seg.dt)[:, None]
        return col, col

    def implausible(self, params: dict[str, float], seg: Segment, ctx: Context) -> str | None:
        k = max(abs(params.get("Kpf", 0.0)), abs(params.get("Kqf", 0.0))) * seg.f0 / max(abs(float(np.mean(seg.P))), 1e-9)
        if k > MAX_PU_SENSITIVITY:
            return f"per-unit frequency sensitivity {k:.1f} > {MAX_PU_SENSITIVITY:g}: not a load's frequency response"
        return None


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = FrequencyDependence()
