"""``frequency_dependence``: load power sensitive to the bus frequency deviation.

Notes
-----
A linear extra term on each channel (lower stage)::

    P = P_ZIP(V) + P_im(D) + Kpf·Δf
    Q = Q_ZIP(V) + Q_im(D) + Kqf·Δf

with Δf = f − f0 [Hz] the bus frequency deviation (the recorded ``f``, else dθ/dt/2π), low-passed at
5 Hz.  Parameters: Kpf [pu/Hz], Kqf [pu/Hz] (on the system base; divide by the static P or Q and
multiply by f0 for the usual per-unit sensitivity, e.g. Kpf·f0/P0 ≈ 0–3 for mixed loads).

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
from aslm_core.diagnosis.segment import Segment

MAX_PU_SENSITIVITY = 8.0  # [-]


class FrequencyDependence(Candidate):
    name = "frequency_dependence"
    magnitude = ("Kpf", "Kqf")
    lin_p = ("Kpf",)
    lin_q = ("Kqf",)
    lin_units = {"Kpf": "pu/Hz", "Kqf": "pu/Hz"}
    signature = "residual coherent with the bus frequency deviation Δf (0.1–2 Hz)"

    def extra_columns(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        col = seg.dfreq[:, None]
        return col, col

    def implausible(self, params: dict[str, float], seg: Segment, ctx: Context) -> str | None:
        k = max(abs(params.get("Kpf", 0.0)), abs(params.get("Kqf", 0.0))) * seg.f0 / max(abs(float(np.mean(seg.P))), 1e-9)
        if k > MAX_PU_SENSITIVITY:
            return f"per-unit frequency sensitivity {k:.1f} > {MAX_PU_SENSITIVITY:g}: not a load's frequency response"
        return None


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = FrequencyDependence()
