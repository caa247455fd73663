"""Frequency-dependent load: ΔP = Kpf·Δf, ΔQ = Kqf·Δf with Δf from the simulator's bus frequency.

Magnitude: the per-unit sensitivity (ΔP/P0)/(Δf/f0) [-]; Kqf is half of Kpf with a random sign.
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and {Kpf, Kqf} [pu/Hz] (see :class:`~aslm_sim.effects.base.Effect`)."""
    w = case.clean
    p0 = float(np.mean(w.P))
    df = w.f - w.f0
    kp = magnitude * p0 / w.f0
    kq = 0.5 * magnitude * p0 / w.f0 * rng.choice([-1.0, 1.0])
    return kp * df, kq * df, {"Kpf": kp, "Kqf": kq}


EFFECT = Effect(name="frequency_dependence", generate=generate, magnitude=(1.0, 3.0), channels="PQ",
                in_library=True, label="freq", main_parameter="Kpf")
