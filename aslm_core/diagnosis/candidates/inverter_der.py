"""``inverter_der``: power-electronic load or DER with Q–V droop (and P–V response) through a voltage lag.

Notes
-----
The converter measures the voltage through a first-order transducer/controller lag T [s] and responds
linearly to it::

    T·dVf/dt = V − Vf,        P_der = Kp·Vf + const,    Q_der = Kq·Vf + const

For a given T the extra columns Vf enter the lower-stage regression (Kp [pu/pu] on P, Kq [pu/pu] on Q,
load convention: P, Q consumed); T is one nonlinear parameter of the upper stage, bounded to [0.02, 10] s,
started from the best of a logarithmic scan with D held at the plain fit.  Vf is integrated with the
trapezoidal rule at the sample step from Vf(0) = V(0).

Sign: a Q–V droop (volt-var) injects Q when V drops and absorbs it when V rises, so the Q it consumes rises
with V: Kq > 0.  A fit with Kq < 0 is implausible (never significant, no rival): a lagged Q that falls as V
rises is what a load's own Q switching looks like through the network (its step pulls V down, so the consumed
Q and the lagged V move against each other), not a droop.  Kp has no such constraint: a volt-watt DER gives
Kp > 0, a power-electronic load whose controller restores its power after a voltage change Kp < 0.

Breadth: a droop responds to V at every frequency, so a real one improves the held-out fit across V's ambient band;
a load's own oscillation at one frequency moves V through the network at that frequency only, and a lagged droop
reproduces a response to one sinusoid at any gain and phase.  The candidate declares ``broadband``: its held-out gain
outside the narrow band where its correction peaks must be positive (:func:`aslm_core.diagnosis.pipeline.off_peak_gain`).

Signature: a residual coherent with V but lagging it (phase −atan(2πfT)), strongest in Q; with T → 0 it
is indistinguishable from ZIP's linear term, so only lags of ~0.1 s and more are detectable.
"""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.candidates.base import Candidate, Context
from aslm_core.diagnosis.lag import lag_start, lagged
from aslm_core.diagnosis.segment import Segment

T_GRID_S = (0.1, 0.2, 0.4, 0.8, 1.6, 3.2)


class InverterDER(Candidate):
    name = "inverter_der"
    magnitude = ("Kp", "Kq")
    nl_names = ("T",)
    nl_units = ("s",)
    lin_p = ("Kp",)
    lin_q = ("Kq",)
    lin_units = {"Kp": "pu/pu", "Kq": "pu/pu"}
    signature = "residual coherent with V but lagging it by a first-order lag T (mostly Q)"
    # A small, fast motor group and a relay-switched bank also add a lagged, V-driven Q response: on the
    # independent (ANDES) development data both were named as a droop before this rule.
    confusable = ("second_motor", "switched_shunt")
    broadband = True

    def bounds(self, seg: Segment, ctx: Context):
        return np.array([0.02]), np.array([10.0])

    def extra_columns(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        col = lagged(seg.V, float(z[0]), seg.dt)[:, None]
        return col, col

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        return [np.array([lag_start(seg, ctx, seg.V, T_GRID_S, 0.5)])]

    def implausible(self, params: dict[str, float], seg: Segment, ctx: Context) -> str | None:
        if params.get("Kq", 0.0) < 0.0:
            return (f"Kq = {params['Kq']:.3g} pu/pu < 0: the consumed Q falls as V rises, which no Q–V droop does "
                    "(a load's own Q switching seen through the network does)")
        return None


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = InverterDER()
