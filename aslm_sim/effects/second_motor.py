"""A second induction-motor group, in ORIGINAL form (eq. 1–3), integrated at 1 ms on the case's V and θ.

Its parameters are a random truth's, scaled to a torque of magnitude × the first motor's and redrawn until
its b or H2 differs from the first motor's by more than a factor 1.8 (otherwise the two are one motor).
Magnitude: Tm2/Tm1 [-].
"""

from __future__ import annotations

import math

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput
from aslm_sim.motors import original_motor_power
from aslm_sim.truth import random_truth


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """P, Q [pu] of the second motor and its {a2, b2 [1/s], H22 [s], Tm2 [pu]}."""
    w, tr = case.clean, case.truth
    for _ in range(100):
        t2 = random_truth(rng)
        if abs(math.log(t2.b / tr.b)) > math.log(1.8) or abs(math.log(t2.H2 / tr.H2)) > math.log(1.8):
            break
    scale = magnitude * tr.Tm / t2.Tm  # second motor torque = magnitude × first motor's
    x, xp = t2.X / scale, t2.Xp / scale  # a scaled copy of the drawn motor: same a/b ratio per unit
    p2, q2 = original_motor_power(w.t, w.V, w.theta, X=x, Xp=xp, Td0=t2.Td0, H2=t2.H2 * scale,
                                  Tm=t2.Tm * scale, f0=w.f0)
    a2 = (x / xp - 1.0) / (t2.Td0 * xp)
    b2 = x / (t2.Td0 * xp)
    return p2, q2, {"a2": a2, "b2": b2, "H22": t2.H2 * scale, "Tm2": t2.Tm * scale}


EFFECT = Effect(name="second_motor", generate=generate, magnitude=(0.4, 1.0), channels="PQ", in_library=True,
                label="2nd mot", main_parameter="Tm2")
