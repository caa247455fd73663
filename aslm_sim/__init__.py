"""ASLM simulation: the test bench, and the physics behind ``aslm replay`` and ``aslm demo``.

Synthetic composite loads with known truth (:mod:`~aslm_sim.truth`) in a small simulated network
(:mod:`~aslm_sim.network`): ambient PMU cases (:mod:`~aslm_sim.cases`, noise per :mod:`~aslm_sim.noise`),
fault events (:mod:`~aslm_sim.faults`), a live fleet (:mod:`~aslm_sim.fleet`) and the concealed effects
of the diagnosis benchmark (:mod:`aslm_sim.effects`).  Used by the tests, the benchmarks, replay and demo;
never imported by :mod:`aslm_core` or by the service outside replay and demo.

The names below are loaded on first use, so ``import aslm_sim`` does not load numba.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aslm_sim.cases import SyntheticCase, make_case, make_cases
    from aslm_sim.faults import disturbance_inputs, large_disturbance
    from aslm_sim.fleet import SyntheticFleet
    from aslm_sim.noise import NOISE_LEVELS, channel_snr_db
    from aslm_sim.truth import LoadTruth, random_truth

#: Public name → the module that defines it.
_HOME: dict[str, str] = {
    "LoadTruth": "truth",
    "random_truth": "truth",
    "SyntheticCase": "cases",
    "make_case": "cases",
    "make_cases": "cases",
    "NOISE_LEVELS": "noise",
    "channel_snr_db": "noise",
    "disturbance_inputs": "faults",
    "large_disturbance": "faults",
    "SyntheticFleet": "fleet",
}

__all__ = [
    "NOISE_LEVELS",
    "LoadTruth",
    "SyntheticCase",
    "SyntheticFleet",
    "channel_snr_db",
    "disturbance_inputs",
    "large_disturbance",
    "make_case",
    "make_cases",
    "random_truth",
]


def __getattr__(name: str):
    if name in _HOME:
        return getattr(import_module(f"aslm_sim.{_HOME[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
