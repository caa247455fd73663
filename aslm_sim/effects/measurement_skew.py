"""Measurement skew: P and Q delayed by τ against V and θ, through a band-limited (FFT) shift.

Magnitude: |τ| [s]; τ is negative (P and Q early) in 15 % of the draws.
"""

from __future__ import annotations

import numpy as np

from aslm_sim.cases import SyntheticCase
from aslm_sim.effects.base import Effect, EffectOutput


def _band_limited_shift(y: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """y(t − τ) by an FFT phase shift of the mirror-extended record (no wrap-around jump)."""
    ext = np.concatenate([y, y[::-1]])
    f = np.fft.rfftfreq(ext.size, dt)
    out = np.fft.irfft(np.fft.rfft(ext) * np.exp(-2j * np.pi * f * tau), n=ext.size)
    return out[: y.size]


def generate(case: SyntheticCase, magnitude: float, rng: np.random.Generator) -> EffectOutput:
    """ΔP, ΔQ [pu] and {tau} [s] (see :class:`~aslm_sim.effects.base.Effect`)."""
    w = case.clean
    tau = magnitude * rng.choice([-1.0, 1.0]) if rng.random() < 0.3 else magnitude
    return (_band_limited_shift(w.P, tau, w.dt) - w.P, _band_limited_shift(w.Q, tau, w.dt) - w.Q, {"tau": tau})


EFFECT = Effect(name="measurement_skew", generate=generate, magnitude=(0.015, 0.04), channels="PQ",
                in_library=True, label="skew", main_parameter="tau")
