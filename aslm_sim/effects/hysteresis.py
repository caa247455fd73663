"""Outside the library: a capacitor bank switched by a voltage relay with a dead band (±0.5 std(V)).

Magnitude: the switched susceptance's Q / std(Q) [-].
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP = 0, ΔQ [pu] and {B} [pu]; draws nothing from rng."""
    w = case.clean
    vm, sv = float(np.mean(w.V)), float(np.std(w.V))
    on = False
    state = np.zeros(w.V.size)
    for i, v in enumerate(w.V):
        if not on and v < vm - 0.5 * sv:
            on = True
        elif on and v > vm + 0.5 * sv:
            on = False
        state[i] = 1.0 if on else 0.0
    bq = magnitude * float(np.std(w.Q))
    return np.zeros_like(w.P), -bq * state * w.V**2, {"B": bq}


EFFECT = Effect(name="hysteresis", generate=generate, magnitude=(0.2, 0.5), channels="Q", in_library=False,
                label="hysteresis")
