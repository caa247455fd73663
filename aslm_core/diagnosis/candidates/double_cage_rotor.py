"""``double_cage_rotor``: a second rotor circuit (double-cage or deep-bar rotor) sharing the motor's slip.

Notes
-----
A double-cage motor (ANDES ``Motor5``; PSLF ``motorw`` with Lpp, Tppo) has two rotor circuits.  With the
stator resistance neglected, as in the paper, the rotor equations are linear in the two rotor flux
states with the same −j·s·ω0 rotation on both, so they diagonalise into two modes of the paper's form
that share the slip (:mod:`aslm_core.diagnosis.motor_variants`)::

    dF1/dt = −b·F1 + a·V − j·s·ω0·F1,      dF2/dt = −b2·F2 + a2·V − j·s·ω0·F2
    H2·ds/dt = Tm − Te,     Te = P_im(F1 + F2),     P, Q = P_im, Q_im of F = F1 + F2 (eq. 5)

(the subtransient V²/X'' joins the static Qz as X' does in the paper's model).  b, b2 are the rotor
modes' decay rates [1/s] (for Motor5 the negatives of the eigenvalues of its (E', E'') equations),
a, a2 their residues [1/s]; the conversion from Motor5/motorw data is
``benchmarks.andes_crosscheck.rotor_modes``.  Two nonlinear parameters fitted in the upper stage with D:
g2 = a2/b2 [1/pu], the second mode's steady-state admittance (its share of the motor's response at low
frequency, which ambient data determine far better than a2 itself: a2 and b2 trade off), bounded to
±5·a/b of the plain fit (g2 = 0: one cage; negative allowed so that an absent cage is fitted about zero),
and b2 [1/s] in [0.2, 400] (at 100 frames/s modes faster than ~1/(2.5·dt) are not resolved as
dynamics, only through their slip dependence).  Derived: a2 = g2·b2 [1/s].  Magnitude: g2.

Signature: unlike ``second_motor`` (its own slip and inertia), the second mode rides on the same slip:
the torque–slip curve and the motor's response to V are those of one motor with a second time constant;
on P and Q alike.
"""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.candidates.base import Candidate, Context
from aslm_core.diagnosis.motor_variants import variant_power
from aslm_core.diagnosis.segment import Segment

B2_BOUNDS = (0.2, 400.0)  # [1/s]


class DoubleCageRotor(Candidate):
    name = "double_cage_rotor"
    motor_form = True
    magnitude = ("g2",)
    nl_names = ("g2", "b2")
    nl_units = ("1/pu", "1/s")
    signature = "a second rotor time constant on the same slip: the motor's V response with a second lag, P and Q"
    max_nfev = 30

    def starts(self, seg: Segment, ctx: Context) -> list[np.ndarray]:
        # One start with a faster and one with a slower second circuit, each a fifth of the first's admittance.
        g, b = float(ctx.d0[0] / ctx.d0[1]), float(ctx.d0[1])
        return [np.array([0.2 * g, min(3.0 * b, 0.9 * B2_BOUNDS[1])]), np.array([0.2 * g, max(0.3 * b, 0.5)])]

    def bounds(self, seg: Segment, ctx: Context):
        g = 5.0 * float(ctx.d0[0] / ctx.d0[1])
        return np.array([-g, B2_BOUNDS[0]]), np.array([g, B2_BOUNDS[1]])

    def motor_power(self, seg: Segment, d: np.ndarray, z: np.ndarray):
        return variant_power(seg, d, a2=float(z[0] * z[1]), b2=float(z[1]))

    def describe(self, params: dict[str, float], seg: Segment, ctx: Context) -> dict[str, float]:
        return {"a2": float(params.get("g2", 0.0) * params.get("b2", 0.0))}


#: The library entry (registered by module name in :mod:`aslm_core.diagnosis.candidates`).
CANDIDATE = DoubleCageRotor()
