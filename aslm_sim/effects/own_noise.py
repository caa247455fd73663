"""Outside the library: a load block with its own random fluctuation (not driven by V or f).

ΔP is white noise low-passed (first order) at a cut-off drawn in 0.5–2 Hz, scaled to the magnitude;
ΔQ is half of it.  No candidate has an exogenous input, so nothing should be named.

Magnitude: std(ΔP) / std(P) [-].
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and {fc [Hz], std [pu]}."""
    w = case.clean
    fc = rng.uniform(0.5, 2.0)
    dt = float(np.median(np.diff(w.t)))
    a = np.exp(-2 * np.pi * fc * dt)
    x = signal.lfilter([1.0 - a], [1.0, -a], rng.standard_normal(w.P.size))
    x = (x - x.mean()) / max(float(np.std(x)), 1e-12)
    sd = magnitude * float(np.std(w.P))
    return sd * x, 0.5 * sd * x, {"fc": fc, "std": sd}


EFFECT = Effect(name="own_noise", generate=generate, magnitude=(0.3, 0.8), channels="PQ", in_library=False,
                label="own noise")
