"""The aslm_sim package: its public surface, its cheap import, and that the core never depends on it."""

from __future__ import annotations

import ast
import importlib
import inspect
import subprocess
import sys
from pathlib import Path

from doc_helpers import undocumented

import aslm_sim

ROOT = Path(__file__).resolve().parents[2]
MODULES = ("truth", "network", "noise", "cases", "faults", "fleet", "motors", "effects.apply", "andes.scenario",
           "andes.effects")


def test_exported_names_resolve_lazily_to_their_modules():
    assert set(aslm_sim.__all__) == {"NOISE_LEVELS", "LoadTruth", "SyntheticCase", "SyntheticFleet", "channel_snr_db",
                                     "disturbance_inputs", "large_disturbance", "make_case", "make_cases",
                                     "random_truth"}
    for name in aslm_sim.__all__:
        obj = getattr(aslm_sim, name)
        home = importlib.import_module(f"aslm_sim.{aslm_sim._HOME[name]}")
        assert obj is getattr(home, name) and name in home.__all__, name


def test_import_loads_no_numba_and_the_core_never_loads_aslm_sim():
    code = ("import sys, aslm_sim; assert 'numba' not in sys.modules, 'aslm_sim'; "
            "import aslm_core, aslm_core.diagnosis; assert 'aslm_sim' not in {m.split('.')[0] for m in sys.modules "
            "if m != 'aslm_sim'}, 'core'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr


def test_only_replay_demo_and_simulate_import_aslm_sim_outside_tests_and_benchmarks():
    offenders = []
    for path in [*ROOT.glob("aslm_core/**/*.py"), *ROOT.glob("service/**/*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if any(n.split(".")[0] == "aslm_sim" for n in names) and path.stem not in ("replay", "demo", "simulate"):
                offenders.append(str(path.relative_to(ROOT)))
    assert not offenders


def test_every_argument_of_public_functions_is_documented():
    missing = {}
    for mod_name in MODULES:
        mod = importlib.import_module(f"aslm_sim.{mod_name}")
        for name in mod.__all__:
            obj = getattr(mod, name)
            func = getattr(obj, "py_func", obj)  # numba kernels: their Python function
            if inspect.isfunction(func) and undocumented(func):
                missing[f"{mod_name}.{name}"] = undocumented(func)
    assert not missing, f"undocumented arguments: {missing}"
