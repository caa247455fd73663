"""The faithful paper baseline (benchmarks/baselines.py) against the fast path and eq. 7 computed independently."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from aslm_core import IdentifyConfig, identify, motor
from aslm_sim.cases import make_cases

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import baselines  # noqa: E402


@pytest.fixture(scope="module")
def case():
    return make_cases(1, level=None, seed=5)[0]  # truth where explicit Euler at 10 ms is stable


def _start(d_true: np.ndarray) -> np.ndarray:
    return d_true * np.array([1.15, 0.9, 1.1, 0.95])


def test_same_optimum_as_fast_euler_path(case):
    w = case.window
    start = _start(case.truth.d)
    base = baselines.faithful_identify(w, starts=[start])
    ours = identify(w, warm_start=start, config=IdentifyConfig(integrator="euler", n_starts=0,
                                                                        skip_s=baselines.SKIP_S, transient_tau=0.0))
    assert math.isfinite(base.of)
    assert np.max(np.abs(base.d / ours.d - 1)) < 1e-3
    assert base.of == pytest.approx(ours.quality["of_paper"], rel=1e-6)


def test_baseline_objective_is_eq7(case):
    w = case.window
    problem = baselines.PaperProblem.from_window(w)
    d = _start(case.truth.d)
    # Independently: compiled Euler simulation, ZIP by normal equations, OF = (‖r_p‖ + ‖r_q‖)/l.
    p_im, q_im, _ = motor.simulate(w.V, np.unwrap(w.theta), d, w.dt, motor.omega0_of(w.f0), integrator="euler")
    k0 = int(round(1.0 / w.dt))
    v = w.V[k0:]
    phi = np.column_stack([v * v, v, np.ones_like(v)])
    norms = []
    for y in (w.P[k0:] - p_im[k0:], w.Q[k0:] - q_im[k0:]):
        beta = np.linalg.solve(phi.T @ phi, phi.T @ y)
        r = y - phi @ beta
        norms.append(math.sqrt(float(r @ r)))
    expected = sum(norms) / v.size
    assert problem.of(d) == pytest.approx(expected, rel=1e-6)
