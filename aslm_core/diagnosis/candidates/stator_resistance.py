"""``stator_resistance``: the third-order motor with a stator resistance Rs > 0 (the paper's transform sets Rs = 0).

Notes
-----
The third-order motor (ANDES ``Motor3``, PSLF ``motor1``) with its stator algebra V − E' = (Rs + jX')·I.
The transformed model (eq. 4–5) divides by jX' and so needs Rs = 0; with Rs the current is the Rs = 0
current times κ = 1/(1 − jρ), ρ = Rs/X', and in the transformed states F = E'/X'
(:mod:`aslm_core.diagnosis.motor_variants`)::

    dF/dt  = −(b − c + c·κ)·F + a·κ·V − j·s·ω0·F,      c = a·X' = b − 1/T0'
    H2·ds/dt = Tm − Te,      Te = Re(κ*·(S_F* − j·X'·|F|²))
    P + jQ = κ*·S_F + (κ* − 1)·j·|V|²/X',      S_F = P_im + j·Q_im (eq. 5)

i.e. to first order in ρ the stator loss moves ρ·Q_im into P and −ρ·P_im into Q, rotates the rotor's
driving voltage by ρ and brakes it by ρ·(Q_im + X'|F|²).  Unlike the paper's model it needs X' itself,
not only a and b: X' = γ·b/a with γ = 1 − X'/X ∈ [0.5, 0.99] (X the open-circuit reactance; ≈ 0.9–0.97
for real motors).  Two nonlinear parameters fitted in the upper stage with D: Rs [pu, system base]
(bounded to ±0.3·X', negative values allowed so that an absent resistance is fitted about zero) and
γ [-]; derived: ρ = Rs/X' [-] (the same on every base) and X' [pu].  Magnitude: Rs.

Signature: a P residual in phase with the motor's reactive fluctuation and a Q residual against its
active one (a fixed rotation of the motor's response by ≈ ρ), plus a static P–V² share the ZIP
regression absorbs.
"""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.candidates.base import Candidate, Context
from aslm_core.diagnosis.motor_variants import variant_power
from aslm_core.diagnosis.segment import Segment

GAMMA_BOUNDS = (0.5, 0.99)
GAMMA_START = 0.9
RHO_MAX = 0.3  # |Rs|/X' bound [-]


class StatorResistance(Candidate):
    name = "stator_resistance"
    motor_form = True
    magnitude = ("Rs",)
    nl_names = ("Rs", "gamma")
    nl_units = ("pu", "-")
    signature = "P residual ∝ the motor's Q response and Q residual ∝ −its P response (rotation by Rs/X')"

    def _xp0(self, ctx: Context) -> float:
        return GAMMA_START * float(ctx.d0[1] / ctx.d0[0])

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        return [np.array([0.03 * self._xp0(ctx), GAMMA_START])]

    def bounds(self, seg: Segment, ctx: Context):
        r = RHO_MAX * self._xp0(ctx) / GAMMA_START
        return np.array([-r, GAMMA_BOUNDS[0]]), np.array([r, GAMMA_BOUNDS[1]])

    def motor_power(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        return variant_power(seg, d, rs=float(z[0]), xp=float(z[1] * d[1] / d[0]))

    def describe(self, params: dict[str, float], seg: Segment, ctx: Context) -> dict[str, float]:
        xp = params.get("gamma", GAMMA_START) * params.get("D.b", ctx.d0[1]) / params.get("D.a", ctx.d0[0])
        return {"Xp": float(xp), "rho": float(params.get("Rs", 0.0) / xp)}


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = StatorResistance()
