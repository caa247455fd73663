"""Stator transients: the case's motor as a FIFTH-order model (stator flux states, stator resistance Rs)
minus the same motor third-order with the same Rs.

Magnitude: Rs/X' [-].
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput
from aslm_sim.motors import original_motor_power, truth_motor


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and {inv_Xp [1/pu], Xp, Rs [pu]}; draws nothing from rng."""
    w, tr = case.clean, case.truth
    m = truth_motor(tr)
    rs = magnitude * tr.Xp
    p5, q5 = original_motor_power(w.t, w.V, w.theta, **m, Rs=rs, fifth=True, f0=w.f0)
    p3, q3 = original_motor_power(w.t, w.V, w.theta, **m, Rs=rs, fifth=False, f0=w.f0)
    return p5 - p3, q5 - q3, {"inv_Xp": 1.0 / tr.Xp, "Xp": tr.Xp, "Rs": rs}


EFFECT = Effect(name="motor_stator_dynamics", generate=generate, magnitude=(0.05, 0.2), channels="PQ",
                in_library=True, label="stator", main_parameter="inv_Xp")
