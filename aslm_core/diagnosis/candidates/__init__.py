"""The library of candidate physics (one module each); :data:`LIBRARY` maps names to instances."""

from __future__ import annotations

from aslm_core.diagnosis.candidates.base import Candidate, Context, Prediction
from aslm_core.diagnosis.candidates.exponential_static import ExponentialStatic
from aslm_core.diagnosis.candidates.frequency_dependence import FrequencyDependence
from aslm_core.diagnosis.candidates.inverter_der import InverterDER
from aslm_core.diagnosis.candidates.measurement_skew import MeasurementSkew
from aslm_core.diagnosis.candidates.motor_stator_dynamics import MotorStatorDynamics
from aslm_core.diagnosis.candidates.second_motor import SecondMotor
from aslm_core.diagnosis.candidates.speed_dependent_torque import SpeedDependentTorque

_ALL: tuple[Candidate, ...] = (
    FrequencyDependence(),
    SecondMotor(),
    SpeedDependentTorque(),
    ExponentialStatic(),
    MotorStatorDynamics(),
    MeasurementSkew(),
    InverterDER(),
)

#: Candidate name → instance, in the library's order.
LIBRARY: dict[str, Candidate] = {c.name: c for c in _ALL}

__all__ = ["LIBRARY", "Candidate", "Context", "Prediction"]
