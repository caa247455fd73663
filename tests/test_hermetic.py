"""The suite is hermetic: a developer's ``ASLM_*`` environment never changes a result."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_developer_environment_does_not_leak_into_tests():
    env = {**os.environ, "ASLM_PERIOD_S": "60", "ASLM_WORKERS": "7", "ASLM_OBJECTIVE": "ml"}
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        "tests/service/test_service_settings.py::test_defaults"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "1 passed" in r.stdout


def test_every_slow_module_exists():
    # A misspelt name would silently put a real-time module into the quick inner loop.
    from conftest import SLOW_MODULES

    stems = {p.stem for p in (ROOT / "tests").rglob("test_*.py")}
    assert SLOW_MODULES <= stems, sorted(SLOW_MODULES - stems)


def test_the_pytest_command_imports_the_real_packages_not_the_mirroring_test_folders():
    # `pytest` (the console script) does not put the working directory on sys.path as `python -m pytest`
    # does; tests/aslm_core etc. would then shadow the packages (pyproject's pythonpath prevents it).
    exe = Path(sys.executable).with_name("pytest")
    r = subprocess.run([str(exe), "-q", "--co", "-p", "no:cacheprovider", "tests/aslm_core/test_public_api.py"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]


def test_a_benchmark_imported_after_a_parallel_kernel_does_not_break_the_next_compile():
    # Benchmark modules set NUMBA_NUM_THREADS=1 by setdefault as they load; once a parallel kernel has launched
    # numba's threads at its default, the next compile would raise "Cannot set NUMBA_NUM_THREADS ... once the
    # threads have been launched" unless conftest pinned the variable first.  A fresh interpreter without it.
    code = (
        "import sys; sys.path.insert(0, 'tests'); import conftest\n"
        "import numba as nb, numpy as np\n"
        "@nb.njit(parallel=True)\n"
        "def total(x):\n"
        "    s = 0.0\n"
        "    for i in nb.prange(x.size):\n"
        "        s += x[i]\n"
        "    return s\n"
        "total(np.ones(8))\n"
        "import benchmarks.rate_cell\n"
        "@nb.njit\n"
        "def one(x):\n"
        "    return x + 1\n"
        "print(one(1))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"}
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip().endswith("2")
