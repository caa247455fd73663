"""The public surface of aslm_core: exactly the intended names, every argument documented."""

from __future__ import annotations

import inspect

import aslm_core
from aslm_core import motor, static

PUBLIC = {
    "IdentificationResult", "IdentifyConfig", "NoEquilibriumError", "Window", "WindowError",
    "identify", "identify_many", "warmup",
}


def test_exported_names_are_exactly_the_intended_ones():
    assert set(aslm_core.__all__) == PUBLIC
    for name in PUBLIC:
        assert hasattr(aslm_core, name)


def _documented(func) -> list[str]:
    doc = inspect.getdoc(func) or ""
    params = [p for p in inspect.signature(func).parameters if p not in ("self", "cls")]
    return [p for p in params if f"{p} :" not in doc and f"{p}, " not in doc]


def test_every_argument_of_public_functions_is_documented():
    funcs = [aslm_core.identify, aslm_core.identify_many, motor.simulate, motor.steady_state, motor.dq_inputs,
             motor.omega0_of, static.regressors, static.coefficients, static.static_power]
    missing = {f.__name__: _documented(f) for f in funcs if _documented(f)}
    assert not missing, f"undocumented arguments: {missing}"
