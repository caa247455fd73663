"""The public surface of aslm_core: exactly the intended names, every argument documented."""

from __future__ import annotations

import importlib
import inspect
from dataclasses import fields

import numpy as np
from fresh_interpreter import run_python

import aslm_core
from aslm_core import motor, static
from aslm_core.window import CHANNELS, Window

PUBLIC = {
    "IdentificationResult", "IdentifyConfig", "NoEquilibriumError", "Window", "WindowError",
    "identify", "identify_many", "warmup",
}


def test_exported_names_are_exactly_the_intended_ones():
    assert set(aslm_core.__all__) == PUBLIC
    assert PUBLIC <= set(dir(aslm_core))
    for name in PUBLIC:
        value = getattr(aslm_core, name)
        # The lazy re-export is the object its module defines (not, e.g., a submodule of that name).
        assert value is getattr(importlib.import_module(value.__module__), name)
    assert aslm_core.identify.__module__ == "aslm_core.identify" and callable(aslm_core.identify)


def test_declarations_import_without_numba_or_scipy():
    code = ("import sys, aslm_core, aslm_core.params, aslm_core.window, aslm_core.errors\n"
            "print(sorted(m for m in ('numba', 'scipy') if m in sys.modules))")
    assert run_python(code) == "[]"


def test_importing_the_identify_submodule_keeps_the_function():
    code = ("import aslm_core.identify, aslm_core.diagnosis, aslm_core\n"
            "import types; print(isinstance(aslm_core.identify, types.FunctionType))")
    assert run_python(code) == "True"


def _documented(func) -> list[str]:
    doc = inspect.getdoc(func) or ""
    params = [p for p in inspect.signature(func).parameters if p not in ("self", "cls")]
    return [p for p in params if f"{p} :" not in doc and f"{p}, " not in doc]


def test_every_argument_of_public_functions_is_documented():
    funcs = [aslm_core.identify, aslm_core.identify_many, motor.simulate, motor.steady_state, motor.dq_inputs,
             motor.omega0_of, static.regressors, static.coefficients, static.static_power]
    missing = {f.__name__: _documented(f) for f in funcs if _documented(f)}
    assert not missing, f"undocumented arguments: {missing}"


def test_window_from_rows_equals_the_constructed_window():
    rows = np.random.default_rng(0).random((len(CHANNELS), 20))
    for with_f in (True, False):
        fast = Window.from_rows(rows, with_f=with_f, f0=60.0, bus="b1")
        slow = Window(*rows[:5], f=rows[5] if with_f else None, f0=60.0, bus="b1")
        assert set(vars(fast)) == {f.name for f in fields(Window)}  # a field added later is not missed
        for name in CHANNELS:
            a, b = getattr(fast, name), getattr(slow, name)
            assert (a is None and b is None) if not with_f and name == "f" else np.array_equal(a, b)
        assert (fast.f0, fast.bus, fast.meta) == (slow.f0, slow.bus, slow.meta)
    assert Window.from_rows(rows.astype(np.float32), with_f=True).t.dtype == np.float64
