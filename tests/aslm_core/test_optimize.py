"""The upper stage's step and stopping rule: the LM subproblem with bounds and the equilibrium constraint."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from aslm_core import IdentifyConfig
from aslm_core.identify import EQUILIBRIUM_MARGIN, Problem, levenberg_marquardt
from aslm_core.optimize import qp_step
from aslm_core.preprocess import prepare
from aslm_sim.cases import make_cases
from benchmarks.lm_stops import kkt_residual

LOWER = np.array([10.0, 3.0, 0.5, 0.0])
UPPER = np.array([80.0, 30.0, 3.0, 4.0])
VMIN = 0.97


def _constraint(d):
    """gc and c(d) of a·Vmin²·(1 − margin) − 2b·Tm ≥ 0, as the kernel linearises it."""
    gc = np.array([VMIN**2 * (1 - EQUILIBRIUM_MARGIN), -2 * d[3], 0.0, -2 * d[1]])
    return gc, gc[0] * d[0] - 2 * d[1] * d[3]


def _random_instance(rng):
    """A convex model at a feasible d, often on bounds and on the constraint (the hard cases)."""
    m = rng.normal(size=(4, 4)) * np.array([0.05, 0.05, 1.0, 1.0])
    M = m @ m.T + np.diag(rng.uniform(1e-4, 1e-2, 4))
    d = LOWER + (UPPER - LOWER) * rng.random(4)
    for u in range(4):  # some variables on a bound
        r = rng.random()
        d[u] = LOWER[u] if r < 0.25 else (UPPER[u] if r < 0.5 else d[u])
    tm_max = (1 - EQUILIBRIUM_MARGIN) * d[0] * VMIN**2 / (2 * d[1])
    d[3] = min(tm_max * (1 - 1e-12) if rng.random() < 0.5 else tm_max * rng.random(), UPPER[3])
    g = rng.normal(size=4) * np.sqrt(np.diag(M)) * 20
    return M, g, d


def _scipy_qp(M, g, d, gc, c_d):
    """The same convex QP by SciPy's SLSQP: (model value function, its minimiser)."""
    def q(x):
        return g @ x + 0.5 * x @ M @ x

    ref = minimize(q, np.zeros(4), jac=lambda x: g + M @ x, method="SLSQP",
                   bounds=list(zip(LOWER - d, UPPER - d, strict=True)),
                   constraints=[{"type": "ineq", "fun": lambda x: gc @ x + c_d, "jac": lambda x: gc}],
                   options={"ftol": 1e-15, "maxiter": 500})
    return q, ref.x


def test_qp_step_is_the_constrained_minimiser_of_the_model():
    """Against SciPy's SLSQP on the same convex QP: same model value, and the step is feasible."""
    rng = np.random.default_rng(3)
    worse, n_active = [], 0
    for _ in range(300):
        M, g, d = _random_instance(rng)
        gc, c_d = _constraint(d)
        s = np.empty(4)
        assert qp_step(M, g, d, LOWER, UPPER, gc, c_d, s, np.empty((4, 4)), np.empty((3, 4)),
                       np.empty((3, 4), dtype=np.int64))
        assert np.all(d + s >= LOWER - 1e-9) and np.all(d + s <= UPPER + 1e-9)
        assert gc @ s >= -c_d - 1e-9 * (abs(c_d) + gc[0] * d[0])
        n_active += bool(gc @ s + c_d < 1e-9 * gc[0] * d[0])
        q, x_ref = _scipy_qp(M, g, d, gc, c_d)
        assert q(s) <= 0.0  # s = 0 is feasible
        if q(s) > q(x_ref) + 1e-7 * abs(q(x_ref)) + 1e-12:
            worse.append((q(s), q(x_ref), d, g))
    assert not worse, worse[:3]
    assert n_active > 30  # the constraint binds in a good share of the instances


def test_lm_stops_only_at_kkt_points_on_the_equilibrium_boundary():
    """Starts that used to stop on the constraint a·Vmin² = 2b·Tm with a descent direction along it.

    Freezing a variable by the sign of its gradient and projecting the step on the constraint's tangent
    ended these three starts at non-stationary points (KKT residual 0.3–0.7, costs above the optimum);
    the active-set step slides along the boundary to the optimum.
    """
    c = make_cases(1, level=1, seed=58, input_noise=False)[0]
    problem = Problem(prepare(c.window), c.window.f0, IdentifyConfig())
    rng = np.random.default_rng(5)
    starts = [problem.random_start(rng) for _ in range(20)]
    runs = [levenberg_marquardt(problem, starts[k]) for k in (9, 16, 19)]
    best = levenberg_marquardt(problem, starts[0])
    for r in runs:
        assert r["status"] == "converged"
        assert kkt_residual(problem, r["d"]) < 1e-3
        assert r["cost"] <= best["cost"] * (1 + 1e-6), (r["d"], best["d"])


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
def test_converged_starts_end_at_kkt_points(integrator):
    config = IdentifyConfig(integrator=integrator)
    for seed in (58, 61, 62):
        c = make_cases(1, level=1, seed=seed, input_noise=False)[0]
        problem = Problem(prepare(c.window), c.window.f0, config)
        rng = np.random.default_rng(7)
        for _ in range(12):
            r = levenberg_marquardt(problem, problem.random_start(rng))
            if r["status"] == "converged":
                assert kkt_residual(problem, r["d"]) < 1e-3, (seed, r)
