"""The time-domain joint likelihood's parts (``benchmarks.input_noise_kalman``): the filter's likelihood against the
dense Gaussian one, the hold's discretisation, the linearised motor against records of the independent generator, and
the accelerated EM against the plain one."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from benchmarks import common
from benchmarks.input_noise import CONFIRM_SEED
from benchmarks.input_noise_kalman import (
    JointModel,
    _nuisance,
    _nuisance_vector,
    em_fit,
    em_step,
    first_order_hold,
    kalman_nll,
    motor_response,
    static_slopes,
)


def _dense_nll(F, Gq, H, r, y, p0) -> float:
    """½(log det C + yᵀC⁻¹y) of the stacked observations, C built from the state covariances directly."""
    N = y.shape[0]
    sig = [p0]
    for _ in range(1, N):
        sig.append(F @ sig[-1] @ F.T + Gq)
    C = np.zeros((4 * N, 4 * N))
    for i in range(N):
        for j in range(i + 1):
            cov = np.linalg.matrix_power(F, i - j) @ sig[j]  # Cov(s_i, s_j)
            blk = H @ cov @ H.T + (np.diag(r) if i == j else 0.0)
            C[4 * i:4 * i + 4, 4 * j:4 * j + 4] = blk
            C[4 * j:4 * j + 4, 4 * i:4 * i + 4] = blk.T
    v = y.ravel()
    _, logdet = np.linalg.slogdet(C)
    return 0.5 * (logdet + v @ np.linalg.solve(C, v))


def test_the_filter_is_the_gaussian_likelihood_and_k0_conditions_on_the_first_samples():
    rng = np.random.default_rng(3)
    n, N = 5, 24
    F = rng.normal(size=(n, n))
    F *= 0.8 / max(abs(np.linalg.eigvals(F)))
    g = rng.normal(size=(n, 2))
    Gq = g @ g.T
    H = rng.normal(size=(4, n))
    r = rng.uniform(0.1, 0.5, 4)
    p0 = np.eye(n) * 2.0
    y = rng.normal(size=(N, 4))
    full = _dense_nll(F, Gq, H, r, y, p0)
    assert kalman_nll(F, Gq, H, r, y, 0, p0, N) == pytest.approx(full, rel=1e-9)
    # From k0 on: the likelihood of the later samples given the first k0.
    first = _dense_nll(F, Gq, H, r, y[:6], p0)
    assert kalman_nll(F, Gq, H, r, y, 6, p0, N) == pytest.approx(full - first, rel=1e-9)


def test_the_hold_is_exact_for_a_ramp_and_a_constant():
    A = np.array([[-3.0, 1.0], [-1.0, -2.0]])
    B = np.array([[1.0], [0.5]])
    dt = 0.04
    phi, g0, g1 = first_order_hold(A, B, dt)
    # u(t) = t from z(0) = 0: z(dt) = ∫ e^{A(dt−τ)}·B·τ dτ, by quadrature.
    tau = np.linspace(0.0, dt, 4001)
    vals = np.stack([linalg.expm(A * (dt - s)) @ B[:, 0] * s for s in tau])
    exact = np.trapezoid(vals, tau, axis=0)
    assert np.allclose(g1[:, 0] * dt, exact, rtol=1e-6, atol=1e-12)
    # A constant input: z(dt) = ∫ e^{A(dt−τ)}·B dτ = (Γ0 + Γ1)·u.
    step = np.trapezoid(np.stack([linalg.expm(A * (dt - s)) @ B[:, 0] for s in tau]), tau, axis=0)
    assert np.allclose((g0 + g1)[:, 0], step, rtol=1e-6, atol=1e-12)
    assert np.allclose(phi, linalg.expm(A * dt))


def test_the_linear_motor_explains_the_generators_clean_records():
    """The motor linearised at the truth, with least-squares static slopes, leaves under 0.5 % of P's and Q's ambient
    variance on clean records of the project's generator (aslm_sim integrates the motor in its original form)."""
    for c in common.cases(3, level=3, seed=CONFIRM_SEED):
        w = c.clean
        dt = float(np.median(np.diff(w.t)))
        jm = JointModel(w.V, w.theta, w.P, w.Q, dt, w.f0, 4, 1.0)
        assert np.all(_unexplained(jm, c.truth.d) < 5e-3)
        # The check discriminates: b half again as large leaves far more.
        assert np.max(_unexplained(jm, c.truth.d * np.array([1.0, 1.5, 1.0, 1.0]))) > 2e-2


def _unexplained(jm: JointModel, d: np.ndarray) -> np.ndarray:
    """Share of P's and Q's variance after the skipped second that the linear motor at d and the least-squares static
    slopes leave, driven by the record's own inputs."""
    cp, cq = static_slopes(jm, d)
    out = motor_response(jm, d) + np.outer(jm.y[:, 0], [cp, cq])
    res = jm.y[jm.k0:, 2:] - out[jm.k0:]
    res -= res.mean(axis=0)
    return res.var(axis=0) / jm.y[jm.k0:, 2:].var(axis=0)


def test_accelerated_em_climbs_at_least_as_far_as_plain_em_in_as_many_steps():
    c = common.cases(1, level=3, seed=CONFIRM_SEED)[0]
    rng = np.random.default_rng(0)
    w = c.window
    V = w.V + 1e-3 * float(np.mean(w.V)) * rng.standard_normal(w.V.size)
    th = w.theta + 1e-3 * rng.standard_normal(w.V.size)
    jm = JointModel(V, th, w.P, w.Q, float(np.median(np.diff(w.t))), w.f0, 6, 1.0)
    d = c.truth.d
    cp, cq = static_slopes(jm, d)
    A, sw = jm.var_start()
    u0 = _nuisance_vector(A, sw, jm.r0.copy())

    def nll(u):
        return jm.nll(jm.pack(d, cp, cq, *_nuisance(u, jm.p)))

    plain = u0
    for _ in range(60):
        plain = em_step(jm, d, cp, cq, plain, True)
    fast = em_fit(jm, d, cp, cq, u0, 20)  # three EM steps a cycle
    assert nll(plain) < nll(u0)
    # Where plain EM crawls (a VAR(6) under input noise), the extrapolation gets further in as many steps.
    assert nll(fast) < nll(plain) - 1.0, (nll(fast), nll(plain))
