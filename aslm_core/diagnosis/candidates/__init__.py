"""The library of candidate physics (one module each); :data:`LIBRARY` maps names to instances."""

from __future__ import annotations

from aslm_core.diagnosis.candidates.base import Candidate, Context, Prediction
from aslm_core.diagnosis.candidates.exponential_static import ExponentialStatic
from aslm_core.diagnosis.candidates.frequency_dependence import FrequencyDependence
from aslm_core.diagnosis.candidates.measurement_skew import MeasurementSkew

_ALL: tuple[Candidate, ...] = (
    FrequencyDependence(),
    MeasurementSkew(),
    ExponentialStatic(),
)

#: Candidate name → instance, in the library's order.
LIBRARY: dict[str, Candidate] = {c.name: c for c in _ALL}

__all__ = ["LIBRARY", "Candidate", "Context", "Prediction"]
