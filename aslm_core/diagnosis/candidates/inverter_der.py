"""``inverter_der``: power-electronic load or DER with Q–V droop (and P–V response) through a voltage lag.

Notes
-----
The converter measures the voltage through a first-order transducer/controller lag T [s] and responds
linearly to it::

    T·dVf/dt = V − Vf,        P_der = Kp·Vf + const,    Q_der = Kq·Vf + const

For a given T the extra columns Vf enter the lower-stage regression (Kp [pu/pu] on P, Kq [pu/pu] on Q;
droop: Kq < 0 for a DER injecting Q when V drops, as a load convention); T is one nonlinear parameter of
the upper stage, bounded to [0.02, 10] s, started from the best of a logarithmic scan with D held at the
plain fit.  Vf is integrated with the trapezoidal rule at the sample step from Vf(0) = V(0).

Signature: a residual coherent with V but lagging it (phase −atan(2πfT)), strongest in Q; with T → 0 it
is indistinguishable from ZIP's linear term, so only lags of ~0.1 s and more are detectable.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from aslm_core.diagnosis.candidates.base import Candidate, Context, simulate_motor, static_part
from aslm_core.diagnosis.segment import Segment

T_GRID_S = (0.1, 0.2, 0.4, 0.8, 1.6, 3.2)


def lagged(V: np.ndarray, T: float, dt: float) -> np.ndarray:
    """First-order lag of V with time constant T [s] (trapezoidal rule), starting at rest at V[0]."""
    a = (2.0 * T - dt) / (2.0 * T + dt)
    b = (1.0 - a) / 2.0
    zi = signal.lfiltic([b, b], [1.0, -a], y=[V[0]], x=[V[0]])
    return signal.lfilter([b, b], [1.0, -a], V, zi=zi)[0]


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

    def bounds(self, seg: Segment, ctx: Context):
        return np.array([0.02]), np.array([10.0])

    def extra_columns(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        col = lagged(seg.V, float(z[0]), seg.dt)[:, None]
        return col, col

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        m = simulate_motor(seg, ctx.d0)
        if m is None:
            return [np.array([0.5])]
        fp, fq, sx = static_part(seg, ctx)
        tr = seg.train
        yp, yq = (seg.P - m[0] - fp)[tr], (seg.Q - m[1] - fq)[tr]
        best, best_t = np.inf, 0.5
        for T in T_GRID_S:
            x = np.hstack([sx, lagged(seg.V, T, seg.dt)[:, None]])[tr]
            ssr = 0.0
            for y in (yp, yq):
                beta, *_ = np.linalg.lstsq(x / np.linalg.norm(x, axis=0), y, rcond=None)
                r = y - (x / np.linalg.norm(x, axis=0)) @ beta
                ssr += float(r @ r) / max(float(np.var(y)) * y.size, 1e-300)
            if ssr < best:
                best, best_t = ssr, T
        return [np.array([best_t])]


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = InverterDER()
