"""``frequency_dependence``: load power sensitive to the bus frequency deviation.

Notes
-----
A linear extra term on each channel (lower stage)::

    P = P_ZIP(V) + P_im(D) + Kpf·Δf
    Q = Q_ZIP(V) + Q_im(D) + Kqf·Δf

with Δf = f − f0 [Hz] the bus frequency deviation (the recorded ``f``, else dθ/dt/2π), low-passed at
5 Hz by the segment and again at 2 Hz (:data:`SMOOTH_HZ`, zero phase) by the candidate.  Parameters:
Kpf [pu/Hz], Kqf [pu/Hz] (on the system base; divide by the static P or Q and
multiply by f0 for the usual per-unit sensitivity, e.g. Kpf·f0/P0 ≈ 0–3 for mixed loads).

Signature: the plain-model residual is coherent with Δf in the ambient band (0.1–2 Hz), more than with
V or dV/dt.  The induction motor of eq. 4 already responds to Δf (it is driven in the synchronous frame),
so only a frequency response *in addition to* the motor's is attributed here.
"""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.candidates.base import Candidate
from aslm_core.diagnosis.segment import Segment, _lowpass

#: The column's own low-pass [Hz]: the ambient band's top.  dθ/dt amplifies θ's noise in proportion to
#: frequency, so with noisy θ most of Δf's noise below the segment's 5 Hz cut-off lies in 2–5 Hz, where the
#: load's frequency response carries little; without θ noise it changes the column by little.
SMOOTH_HZ = 2.0


class FrequencyDependence(Candidate):
    name = "frequency_dependence"
    magnitude = ("Kpf", "Kqf")
    lin_p = ("Kpf",)
    lin_q = ("Kqf",)
    lin_units = {"Kpf": "pu/Hz", "Kqf": "pu/Hz"}
    signature = "residual coherent with the bus frequency deviation Δf (0.1–2 Hz)"

    def extra_columns(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        col = _lowpass(seg.dfreq, seg.fs, SMOOTH_HZ)[:, None]
        return col, col


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = FrequencyDependence()
