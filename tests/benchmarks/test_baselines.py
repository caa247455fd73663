"""The paper baselines (benchmarks/baselines.py): interpreted and compiled, against each other, the fast path and eq. 7."""

from __future__ import annotations

import dataclasses
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


@pytest.fixture(scope="module")
def model_window(case):
    """A noise-free window whose P and Q are exactly the paper's model: Euler motor at the case's D + a ZIP load."""
    w = case.window
    problem = baselines.PaperProblem.from_window(w)
    p_im, q_im = baselines.euler_py(problem.vd, problem.vq, case.truth.d, problem.dt, problem.w0)
    v = problem.V
    return dataclasses.replace(w, P=np.asarray(p_im) + 0.3 + 0.2 * v + 0.1 * v * v,
                               Q=np.asarray(q_im) + 0.1 - 0.05 * v + 0.2 * v * v)


def test_compiled_recovers_known_d_and_agrees_with_interpreted(case, model_window):
    start = _start(case.truth.d)
    compiled = baselines.compiled_identify(model_window, starts=[start])
    interpreted = baselines.faithful_identify(model_window, starts=[start])
    assert compiled.runs[0]["success"]
    assert np.max(np.abs(compiled.d / case.truth.d - 1)) < 1e-5
    assert np.max(np.abs(compiled.d / interpreted.d - 1)) < 1e-6
    # The lower stage finds the ZIP load the window was made with.
    assert compiled.static["Pp"] == pytest.approx(0.3, abs=1e-4)
    assert compiled.static["Qz"] == pytest.approx(0.2, abs=1e-4)


def test_compiled_same_optimum_as_interpreted_on_a_noisy_window(case):
    start = _start(case.truth.d)
    compiled = baselines.compiled_identify(case.window, starts=[start])
    interpreted = baselines.faithful_identify(case.window, starts=[start])
    assert np.max(np.abs(compiled.d / interpreted.d - 1)) < 1e-4
    assert compiled.of == pytest.approx(interpreted.of, rel=1e-9)


def test_compiled_objective_matches_interpreted(case):
    w = case.window
    plain = baselines.PaperProblem.from_window(w)
    compiled = baselines.CompiledPaperProblem.from_window(w)
    rng = np.random.default_rng(3)
    points = [plain.random_start(rng) for _ in range(20)]
    values = [(plain.of(d), compiled.of(d)) for d in points]
    assert any(math.isinf(a) for a, _ in values), "no start where Euler diverges: the inf branch is untested"
    for a, b in values:
        assert (math.isinf(a) and math.isinf(b)) or b == pytest.approx(a, rel=1e-9)


def test_compiled_gradient_is_scipys_forward_difference(case):
    from scipy.optimize import approx_fprime

    compiled = baselines.CompiledPaperProblem.from_window(case.window)
    lo, span = compiled.lower, compiled.upper - compiled.lower
    jac, _ = compiled.slsqp_jacobians(lo, span, 1.0)
    x = (_start(case.truth.d) - lo) / span
    expected = approx_fprime(x, lambda z: compiled.of(lo + span * z), baselines.FD_STEP)
    compiled.of(lo + span * x)
    assert np.allclose(jac(x), expected, rtol=1e-9, atol=0)
