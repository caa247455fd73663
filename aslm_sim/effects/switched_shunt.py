"""In the library since the ``switched_shunt`` candidate: a capacitor bank switched by a voltage relay.

The relay (own code, not the candidate's): dead band ±0.5 std(V) about the window's mean V, and a delay of
a whole number of samples drawn in 0–0.3 s, counted only while V stays beyond the threshold (an excursion
shorter than the delay does not switch).  Before the candidate existed this was the outside-library
effect ``hysteresis`` (no delay).

Magnitude: the switched susceptance's Q / std(Q) [-].
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP = 0, ΔQ [pu] and {B [pu], delay [s]}."""
    w = case.clean
    vm, sv = float(np.mean(w.V)), float(np.std(w.V))
    dt = float(np.median(np.diff(w.t)))
    delay_n = int(rng.integers(0, int(0.3 / dt) + 1))
    on, beyond_n = False, 0
    state = np.zeros(w.V.size)
    for i, v in enumerate(w.V):
        beyond = v > vm + 0.5 * sv if on else v < vm - 0.5 * sv
        beyond_n = beyond_n + 1 if beyond else 0
        if beyond_n > delay_n:
            on, beyond_n = not on, 0
        state[i] = 1.0 if on else 0.0
    bq = magnitude * float(np.std(w.Q))
    return np.zeros_like(w.P), -bq * state * w.V**2, {"B": bq, "delay": delay_n * dt}


EFFECT = Effect(name="switched_shunt", generate=generate, magnitude=(0.2, 0.5), channels="Q", in_library=True,
                label="shunt", main_parameter="B")
