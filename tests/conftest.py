"""Shared fixtures: hermetic settings, and deterministic data built from the paper's equations."""

from __future__ import annotations

import os

# Benchmark modules the tests import set NUMBA_NUM_THREADS=1 by setdefault as they load (their timings are one
# core's).  Once a parallel kernel (aslm_sim's network) has launched numba's threads, the next compile that reads a
# different value raises "Cannot set NUMBA_NUM_THREADS ... once the threads have been launched": the order-dependent
# failure seen on cold numba caches.  Pinned here to numba's own default before numba loads, those setdefaults
# change nothing.
os.environ.setdefault("NUMBA_NUM_THREADS", str(len(os.sched_getaffinity(0))))

import numpy as np
import pytest
from scipy import signal

from aslm_core import Window, motor

# Real-time end-to-end modules: real Zenoh sessions, uvicorn, spawned workers, seconds of waiting for
# periods.  `scripts/test --quick` leaves them out for an inner loop; CI runs everything.  A new module of
# this kind either joins this list or marks itself with `pytestmark = pytest.mark.slow`.
SLOW_MODULES = frozenset({
    "test_andes_crosscheck", "test_records_andes", "test_service_cli", "test_service_diagnosis", "test_service_e2e",
    "test_service_pool", "test_service_runtime",
})


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.stem in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True)
def hermetic_settings(monkeypatch):
    """No ``ASLM_*`` variable of the developer's environment reaches a test (or the processes it starts).

    Tests that need one set it themselves with ``monkeypatch.setenv`` after this has run.
    """
    for key in list(os.environ):
        if key.startswith("ASLM_"):
            monkeypatch.delenv(key)


D_TRUE = np.array([40.0, 15.0, 1.3, 1.2])
ZIP_P = (2.0, 1.0, 3.0)  # Pz, Pi, Pp
ZIP_Q = (-1.0, 0.5, 1.0)  # Qz, Qi, Qp


def equation_window(d=D_TRUE, *, seed: int = 1, fs: float = 100.0, fine: int = 10, duration: float = 10.0,
                    f0: float = 50.0, v_std: float = 0.03) -> Window:
    """V/θ: 2 Hz low-passed noise; P/Q: eq. 4–5 integrated at fs·fine (RK4) plus a ZIP part, sampled at fs."""
    rng = np.random.default_rng(seed)
    ff = fs * fine
    nf = int(round(duration * ff)) + 1
    t = np.arange(nf) / ff
    b, a = signal.butter(2, 2.0, fs=ff)
    V = 1.0 + signal.lfilter(b, a, rng.standard_normal(nf)) * v_std
    theta = 0.1 + np.cumsum(signal.lfilter(b, a, rng.standard_normal(nf)) * 5e-4)
    p_im, q_im, _ = motor.simulate(V, theta, np.asarray(d, float), 1.0 / ff, motor.omega0_of(f0))
    P = p_im + ZIP_P[0] * V**2 + ZIP_P[1] * V + ZIP_P[2]
    Q = q_im + ZIP_Q[0] * V**2 + ZIP_Q[1] * V + ZIP_Q[2]
    sl = slice(0, nf, fine)
    return Window(t[sl], V[sl], theta[sl], P[sl], Q[sl], f0=f0, bus="eq")


@pytest.fixture(scope="session")
def eq_window() -> Window:
    return equation_window()
