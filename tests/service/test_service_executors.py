"""The executors package: the registry behind the ``executor`` setting, a light worker boot, lean tasks."""

from __future__ import annotations

import importlib
import pickle

import numpy as np
import pytest
from fresh_interpreter import run_python

from aslm_core.window import Window
from service.executors import EXECUTORS, executor_module, make_executor
from service.executors.base import WindowTask
from service.executors.local import LocalPool


@pytest.mark.parametrize(("setting", "module"), [
    ("local", "service.executors.local"),
    ("tcp://scheduler:8786", "service.executors.dask"),
    ("tls://10.0.0.1:8786", "service.executors.dask"),
    ("inproc://x", "service.executors.dask"),
    ("yarn", None),
    ("tcp://", None),
    ("tcp://host 8786", None),
    ("localhost", None),
])
def test_settings_map_to_their_executor_module(setting, module):
    assert executor_module(setting) == module


def test_every_registered_module_has_a_factory():
    for module in EXECUTORS:
        assert callable(importlib.import_module(module).create), module


def test_make_executor_builds_the_local_pool_and_refuses_unknown_settings():
    with pytest.raises(ValueError, match="no executor for 'yarn'"):
        make_executor("yarn", 1, "service.worker:identify_window", 10.0)
    pool = make_executor("local", 1, "service_helpers:fake_identify", 10.0)
    try:
        assert isinstance(pool, LocalPool) and len(pool.pids()) == 1
    finally:
        pool.close()


def test_worker_boot_imports_without_numpy():
    # A spawned worker imports these before boot.main sets its thread limits: numpy must not load first.
    assert run_python("import sys, service.executors.boot; print('numpy' in sys.modules)") == "False"


def test_the_worker_side_never_imports_the_pool():
    code = ("import sys, service.executors.child\n"
            "print(sorted(m for m in ('service.executors.local', 'service.executors.boot') if m in sys.modules))")
    assert run_python(code) == "[]"


def test_a_pickled_task_is_its_arrays_and_little_else():
    n = 500
    t = np.arange(n) / 50.0
    block = np.stack([t, 1 + 0 * t, 0 * t, 0.5 + 0 * t, 0.1 + 0 * t, 50 + 0 * t])
    task = WindowTask(Window(*block, f0=50.0, bus="bus-0001"), warm_start=[40.0, 15.0, 1.3, 0.5],
                      options={"n_starts": 1})
    data = pickle.dumps(task, protocol=pickle.HIGHEST_PROTOCOL)
    assert block.nbytes < len(data) < block.nbytes + 1200
    back = pickle.loads(data)
    assert back.bus == "bus-0001" and back.window.f0 == 50.0 and back.window.meta == {}
    np.testing.assert_array_equal(back.window.f, block[5])
