"""The transformed induction motor against the paper's equations (eq. 4–5) and exact sensitivities."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from aslm_core import IdentifyConfig, NoEquilibriumError, motor
from aslm_core.identify import Problem
from aslm_core.preprocess import prepare
from tests.conftest import D_TRUE

W0 = motor.omega0_of(50.0)


def rhs(x, vd, vq, d):
    a, b, h2, tm = d
    fd, fq, s = x
    return np.array([
        -b * fd + s * W0 * fq + a * vd,
        -b * fq - s * W0 * fd + a * vq,
        (tm - vq * fd + vd * fq) / h2,
    ])


@pytest.mark.parametrize("d", [D_TRUE, np.array([75.0, 4.0, 0.6, 5.0]), np.array([12.0, 28.0, 2.9, 0.0])])
def test_steady_state_is_equilibrium_with_low_slip(d):
    v, th = 0.97, 0.3
    x0 = motor.steady_state(v, th, d, W0)
    vd, vq = v * np.cos(th), v * np.sin(th)
    np.testing.assert_allclose(rhs(x0, vd, vq, d), 0.0, atol=1e-9)
    # Low-slip root: below the slip of maximum torque, s·ω0 < b.
    assert 0.0 <= x0[2] * W0 <= d[1]
    # At equilibrium the motor draws P = Tm (eq. 5 with Te = Tm).
    assert x0[0] * vq - x0[1] * vd == pytest.approx(d[3], abs=1e-9)


def test_no_equilibrium_is_a_clear_error():
    with pytest.raises(NoEquilibriumError, match="must exceed"):
        motor.steady_state(1.0, 0.0, np.array([10.0, 30.0, 1.0, 1.0]), W0)  # a·V² = 10 < 2b·Tm = 60


def test_rk4_matches_adaptive_reference(eq_window):
    """RK4 at the sample step vs a tight adaptive solution of eq. 4 with spline-interpolated inputs."""
    w = eq_window
    d = D_TRUE
    p, q, x = motor.simulate(w.V, w.theta, d, w.dt, W0)
    t = w.t - w.t[0]

    v_spline, th_spline = CubicSpline(t, w.V), CubicSpline(t, w.theta)

    def u(tt):
        return v_spline(tt), th_spline(tt)

    def f(tt, xx):
        v, th = u(tt)
        return rhs(xx, v * np.cos(th), v * np.sin(th), d)

    ref = solve_ivp(f, (0, t[-1]), x[0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=w.dt / 2)
    vd, vq = w.V * np.cos(w.theta), w.V * np.sin(w.theta)
    p_ref = ref.y[0] * vq - ref.y[1] * vd
    q_ref = -vd * ref.y[0] - vq * ref.y[1]
    assert np.max(np.abs(p - p_ref)) < 2e-4 * np.ptp(p_ref)
    assert np.max(np.abs(q - q_ref)) < 2e-4 * np.ptp(q_ref)


def test_euler_mode_is_the_papers_explicit_step(eq_window):
    w = eq_window
    p, q, x = motor.simulate(w.V, w.theta, D_TRUE, w.dt, W0, integrator="euler")
    vd, vq = w.V * np.cos(w.theta), w.V * np.sin(w.theta)
    for k in (0, 10, 500):
        np.testing.assert_allclose(x[k + 1], x[k] + w.dt * rhs(x[k], vd[k], vq[k], D_TRUE), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
def test_exact_jacobian_matches_finite_differences(eq_window, integrator):
    prep = prepare(eq_window)
    problem = Problem(prep, 50.0, IdentifyConfig(integrator=integrator))
    d = np.array([35.0, 12.0, 1.1, 1.0])
    rp, rq, jp, jq = problem.residuals(d)
    for j in range(4):
        h = 1e-6 * d[j]
        dp_, dm_ = d.copy(), d.copy()
        dp_[j] += h
        dm_[j] -= h
        rpp, rqp, _, _ = problem.residuals(dp_, jacobian=False)
        rpm, rqm, _, _ = problem.residuals(dm_, jacobian=False)
        fd_p = (rpp - rpm) / (2 * h)
        fd_q = (rqp - rqm) / (2 * h)
        np.testing.assert_allclose(jp[:, j], fd_p, rtol=1e-5, atol=1e-6 * np.abs(fd_p).max())
        np.testing.assert_allclose(jq[:, j], fd_q, rtol=1e-5, atol=1e-6 * np.abs(fd_q).max())


def test_residual_is_the_papers_regression_residual(eq_window):
    """The projected residual equals the residual of an explicit OLS of P − P_im on [1, V, V²] (eq. 6–7)."""
    prep = prepare(eq_window)
    cfg = IdentifyConfig()
    problem = Problem(prep, 50.0, cfg)
    d = np.array([30.0, 10.0, 2.0, 0.8])
    rp, rq, _, _ = problem.residuals(d, jacobian=False)
    p_im, q_im, _ = motor.simulate(prep.V, prep.theta, d, prep.dt, W0)
    k0 = problem.k0
    V = prep.V[k0:]
    X = np.column_stack([np.ones_like(V), V, V**2])
    for meas, im, r in ((prep.P, p_im, rp), (prep.Q, q_im, rq)):
        y = meas[k0:] - im[k0:]
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        np.testing.assert_allclose(r, y - X @ beta, atol=1e-9)
    of = (np.linalg.norm(rp) + np.linalg.norm(rq)) / problem.l
    assert problem.cost(rp, rq) == pytest.approx(of, rel=1e-12)


def test_fused_normal_equations_match_explicit_projection(eq_window):
    """The optimiser's one-pass normal equations equal those of the explicitly projected residuals."""
    from aslm_core import optimize

    prep = prepare(eq_window)
    problem = Problem(prep, 50.0, IdentifyConfig())
    d = np.array([30.0, 10.0, 2.0, 0.8])
    rp, rq, jp, jq = problem.residuals(d)
    l = problem.l
    out = [np.empty((4, 4)), np.empty((4, 4)), np.empty(4), np.empty(4)]
    ok, rr_p, rr_q = optimize._evaluate(
        d, problem.vd, problem.vq, problem.vdm, problem.vqm, problem.dt, problem.omega0, True, problem.k0,
        problem.p_meas, problem.q_meas, problem.basis2, np.empty((l, 10)), np.empty((10, 10)),
        *out, np.empty(1), np.empty((1, 4)),
    )
    Ap, Aq, gp, gq = out
    assert ok
    assert rr_p == pytest.approx(rp @ rp, rel=1e-8)
    assert rr_q == pytest.approx(rq @ rq, rel=1e-8)
    np.testing.assert_allclose(gp, jp.T @ rp, rtol=1e-7, atol=1e-9 * np.abs(jp.T @ rp).max())
    np.testing.assert_allclose(gq, jq.T @ rq, rtol=1e-7, atol=1e-9 * np.abs(jq.T @ rq).max())
    np.testing.assert_allclose(Ap, jp.T @ jp, rtol=1e-7)
    np.testing.assert_allclose(Aq, jq.T @ jq, rtol=1e-7)


def test_initial_state_turns_with_an_off_nominal_frequency():
    """A window 0.05 Hz off nominal, constant |V|: RK4 mode starts in the turning steady state (no transient)."""
    t = np.arange(1001) * 0.01
    V = np.ones_like(t)
    theta = 2 * np.pi * 0.05 * t
    d = np.array([40.0, 15.0, 1.3, 1.0])
    w0 = motor.omega0_of(50.0)
    p, q, x = motor.simulate(V, theta, d, 0.01, w0)
    assert np.ptp(p) < 1e-6 and np.ptp(q) < 1e-6
    # Slip relative to ω0 shifted by −Δω/ω0 from the steady state at nominal frequency.
    s_nominal = motor.steady_state(1.0, 0.0, d, w0)[2]
    assert x[0, 2] == pytest.approx(s_nominal - 2 * np.pi * 0.05 / w0, rel=1e-6)
    # The paper's Euler mode keeps the ω0 steady state, so the same window starts with a transient.
    pe, _, _ = motor.simulate(V, theta, d, 0.01, w0, integrator="euler")
    assert np.ptp(pe) > 1e-3


def test_slowest_time_constant_is_the_decay_of_an_initial_state_error():
    """A perturbed initial state, integrated finely at constant voltage, returns at the stated rate."""
    d = np.array([19.4, 27.9, 2.63, 0.19])  # a slow motor: large b and H2, small a
    v0, w0 = 1.0, motor.omega0_of(50.0)
    tau = motor.slowest_time_constant(v0, 0.0, d, w0)
    x_ss = motor.steady_state(v0, 0.0, d, w0)

    def rhs(x):
        fd, fq, s = x
        return np.array([-d[1] * fd + s * w0 * fq + d[0] * v0, -d[1] * fq - s * w0 * fd, (d[3] + v0 * fq) / d[2]])

    x, h = x_ss * np.array([1.0, 1.0, 1.2]), 1e-4
    dev = []
    for k in range(int(6 * tau / h)):
        k1 = rhs(x)
        k2 = rhs(x + 0.5 * h * k1)
        k3 = rhs(x + 0.5 * h * k2)
        k4 = rhs(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if k % int(tau / h) == 0:
            dev.append(np.abs(x - x_ss).max())
    rates = -np.diff(np.log(dev[2:]))  # per τ, after the faster modes have gone
    np.testing.assert_allclose(rates, 1.0, atol=0.1)
