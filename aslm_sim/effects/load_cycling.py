"""Outside the library: an exogenous load block switched on and off periodically (smoothly, 0.2–0.6 Hz).

Magnitude: the block's amplitude / std(P) [-]; its Q is half its P.
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and {f_cycle [Hz], amplitude [pu]} (see :class:`~aslm_sim.effects.base.Effect`)."""
    w = case.clean
    fc = rng.uniform(0.2, 0.6)
    ph = rng.uniform(0, 2 * np.pi)
    sq = np.tanh(4.0 * np.sin(2 * np.pi * fc * w.t + ph))  # smooth on/off
    amp = magnitude * float(np.std(w.P))
    return amp * sq, 0.5 * amp * sq, {"f_cycle": fc, "amplitude": amp}


EFFECT = Effect(name="load_cycling", generate=generate, magnitude=(0.3, 0.8), channels="PQ", in_library=False,
                label="cycling")
