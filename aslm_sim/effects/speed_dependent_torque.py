"""Speed-dependent load torque: the case's motor again in original form with Tm(s) = Tm·((1−s)/(1−s0))^k,
minus the same motor with constant torque.

Magnitude: the exponent k [-].  It is not shrunk for concealment: k stays physical, and the effect is
small anyway.
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput
from aslm_sim.motors import original_motor_power, truth_motor


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and {k} [-] (see :class:`~aslm_sim.effects.base.Effect`); draws nothing from rng."""
    w = case.clean
    m = truth_motor(case.truth)
    pk, qk = original_motor_power(w.t, w.V, w.theta, **m, k=magnitude, f0=w.f0)
    p0_, q0_ = original_motor_power(w.t, w.V, w.theta, **m, k=0.0, f0=w.f0)
    return pk - p0_, qk - q0_, {"k": magnitude}


EFFECT = Effect(name="speed_dependent_torque", generate=generate, magnitude=(2.0, 5.0), channels="P",
                in_library=True, label="T(s)", main_parameter="k", concealable=False)
