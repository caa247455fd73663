"""The library of candidate physics (one module each); :data:`LIBRARY` maps names to instances.

Adding a candidate is one new module here (a :class:`Candidate` subclass whose ``name`` is the module's
name, and ``CANDIDATE = TheClass()`` at its end) plus its name on :data:`MODULES`.
"""

from __future__ import annotations

import importlib

from aslm_core.diagnosis.candidates.base import Candidate, Context, Prediction

#: The library's modules in its order: ties in the ranking and the report's listing follow it.
MODULES: tuple[str, ...] = (
    "frequency_dependence",
    "second_motor",
    "speed_dependent_torque",
    "exponential_static",
    "motor_stator_dynamics",
    "measurement_skew",
    "inverter_der",
    "stator_resistance",
    "double_cage_rotor",
    "switched_shunt",
)


def _load(module: str) -> Candidate:
    cand = importlib.import_module(f"{__name__}.{module}").CANDIDATE
    # The JSON names a candidate by ``name``; tying it to the module keeps one name per physics.
    if not isinstance(cand, Candidate) or cand.name != module:
        raise TypeError(f"{__name__}.{module}.CANDIDATE must be a Candidate named {module!r}")
    return cand


#: Candidate name → instance, in the library's order.
LIBRARY: dict[str, Candidate] = {m: _load(m) for m in MODULES}

__all__ = ["LIBRARY", "MODULES", "Candidate", "Context", "Prediction"]
