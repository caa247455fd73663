"""``second_motor``: a second induction-motor group with its own D2 = [a2, b2, H22, Tm2].

Notes
-----
Two transformed third-order motors (eq. 4–5) driven by the same voltage, each from its own steady state::

    P = P_ZIP(V) + P_im(D) + P_im(D2),    Q = Q_ZIP(V) + Q_im(D) + Q_im(D2)

(the second motor's V²/X'2 joins the static Qz like the first one's).  D2 has the units and box of D:
a2 [1/s], b2 [1/s], H22 [s], Tm2 [pu], with a2·V² > 2·b2·Tm2.  Four nonlinear parameters, fitted in the
upper stage together with D from a few starts that split the load torque between a faster and a slower
group.

Signature: the residual of a single-motor fit is coherent with V and dV/dt with a frequency response that
no single (a, b, H2) reproduces — typically a second resonance/lag in the 0.2–3 Hz band, on P and Q.
"""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.candidates.base import Candidate, Context, simulate_motor
from aslm_core.diagnosis.segment import Segment
from aslm_core.params import dynamic_bounds


class SecondMotor(Candidate):
    name = "second_motor"
    nl_names = ("a2", "b2", "H22", "Tm2")
    nl_units = ("1/s", "1/s", "s", "pu")
    signature = "single-motor residual coherent with V/dV/dt with a second dynamic (lag/resonance), P and Q"
    max_nfev = 20

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        a, b, h, tm = ctx.d0
        lo, hi = dynamic_bounds(float(np.mean(seg.P)))
        out = []
        for fb, fh in ((2.5, 0.4), (0.4, 2.5)):
            z = np.array([a, np.clip(b * fb, lo[1], hi[1]), np.clip(h * fh, lo[2], hi[2]), 0.3 * max(tm, 1e-3)])
            z[3] = min(z[3], 0.45 * z[0] * float(np.min(seg.V)) ** 2 / z[1])
            out.append(z)
        return out

    def bounds(self, seg: Segment, ctx: Context):
        lo, hi = dynamic_bounds(float(np.mean(seg.P)))
        return lo, np.maximum(hi, lo + 1e-6)

    def motor_power(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        m1 = simulate_motor(seg, d)
        m2 = simulate_motor(seg, z)
        if m1 is None or m2 is None:
            return None
        return m1[0] + m2[0], m1[1] + m2[1]
