"""Concealed effects on synthetic cases: the ground truth of the diagnosis tests and benchmark.

Each effect (one module here) takes a noise-free synthetic case (ZIP + original-form induction motor in a
small network, :func:`aslm_sim.cases.make_cases`), keeps its V and θ, and adds to its P and Q the effect
computed with its *own* model code, independent of the candidate that is supposed to find it.  The noise
is the case's own realisation (``window − clean``), so the SNR is the case's.  An effect is *concealed*
when the plain ZIP + IM fit of the whole window still has FD ≥ 0.9 on P and Q; the magnitude is reduced
(×0.7 per try) until it is (:func:`apply_effect`).

Adding an effect: a module declaring ``EFFECT = Effect(...)`` and its line in :data:`EFFECTS`; the
benchmark and the tests take the names, channels, magnitudes and labels from here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from aslm_sim.effects import (
    exponential_static,
    frequency_dependence,
    inverter_der,
    load_cycling,
    measurement_skew,
    motor_stator_dynamics,
    own_noise,
    second_motor,
    speed_dependent_torque,
    switched_shunt,
)
from aslm_sim.effects.base import Effect, EffectCase

if TYPE_CHECKING:
    from aslm_sim.effects.apply import apply_effect, make_effect_cases

__all__ = ["EFFECTS", "LIBRARY_EFFECTS", "OUTSIDE_EFFECTS", "Effect", "EffectCase", "apply_effect",
           "make_effect_cases"]

#: Effect name → declaration, in the benchmark's order (library effects first).
EFFECTS: dict[str, Effect] = {e.name: e for e in (
    frequency_dependence.EFFECT,
    second_motor.EFFECT,
    speed_dependent_torque.EFFECT,
    motor_stator_dynamics.EFFECT,
    measurement_skew.EFFECT,
    inverter_der.EFFECT,
    exponential_static.EFFECT,
    switched_shunt.EFFECT,
    load_cycling.EFFECT,
    own_noise.EFFECT,
)}
#: Effects a candidate of the diagnosis library models, and effects outside it.
LIBRARY_EFFECTS: tuple[str, ...] = tuple(n for n, e in EFFECTS.items() if e.in_library)
OUTSIDE_EFFECTS: tuple[str, ...] = tuple(n for n, e in EFFECTS.items() if not e.in_library)


def __getattr__(name: str):
    # apply_effect needs the registry above, so its module is loaded on first use, not here (no cycle).
    if name in ("apply_effect", "make_effect_cases"):
        from aslm_sim.effects import apply

        return getattr(apply, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
