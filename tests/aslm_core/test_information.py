"""The Cramér–Rao bound (aslm_core/information.py) against closed forms and against estimators' spreads."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import linalg

from aslm_core import IdentifyConfig, identify_many, motor, static
from aslm_core.information import (
    cramer_rao,
    disturbance_covariance,
    input_jacobian,
    input_noise_covariance,
    input_posterior_covariance,
    model_jacobian,
    relative_bound,
    stationary_input_covariance,
)
from aslm_sim.cases import make_cases


def _ar1_covariance(n: int, rho: float, sigma: float) -> np.ndarray:
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    return sigma**2 / (1.0 - rho**2) * rho**lags


def test_white_noise_linear_model_gives_the_least_squares_covariance():
    """y = X·θ + N·β + e, e white with variance σ²: the bound on θ is σ²·(Xᵀ·P⊥·X)⁻¹, P⊥ off N's span."""
    rng = np.random.default_rng(3)
    n, sigma = 200, 0.3
    x = rng.standard_normal((n, 2))
    nuis = np.column_stack([np.ones(n), np.linspace(-1.0, 1.0, n)])
    proj = np.eye(n) - nuis @ np.linalg.pinv(nuis)
    expected = sigma**2 * np.linalg.inv(x.T @ proj @ x)
    got = cramer_rao(x, nuis, sigma**2 * np.eye(n))
    np.testing.assert_allclose(got, expected, rtol=1e-10)


def test_coloured_noise_bound_is_the_spread_of_generalised_least_squares():
    """AR(1) noise (ρ = 0.9): the GLS estimator's Monte-Carlo spread is the bound; ordinary LS's is not below it."""
    rng = np.random.default_rng(5)
    n, rho, sigma, draws = 150, 0.9, 0.1, 2000
    x = np.column_stack([np.sin(np.arange(n) * 1.3), rng.standard_normal(n)])
    cov = _ar1_covariance(n, rho, sigma)
    bound = np.sqrt(np.diag(cramer_rao(x, None, cov)))
    chol = linalg.cholesky(cov, lower=True)
    e = (chol @ rng.standard_normal((n, draws))).T
    xw = linalg.solve_triangular(chol, x, lower=True)
    gls = np.linalg.lstsq(xw, linalg.solve_triangular(chol, e.T, lower=True), rcond=None)[0].T
    ols = np.linalg.lstsq(x, e.T, rcond=None)[0].T
    assert np.all(np.abs(gls.std(axis=0) / bound - 1.0) < 0.08), gls.std(axis=0) / bound
    # No estimator beats the bound; LS is nearly efficient on the smooth column, not on the white one.
    assert np.all(ols.std(axis=0) > 0.95 * bound) and ols.std(axis=0)[1] > 2.0 * bound[1], ols.std(axis=0) / bound


def test_a_shared_own_process_informs_more_than_each_channel_alone():
    """When Q's own fluctuation is a fixed multiple of P's, the P–Q cross-covariance is information."""
    rng = np.random.default_rng(1)
    n = 120
    own = _ar1_covariance(n, 0.95, 0.02)
    jac = rng.standard_normal((2 * n, 3))
    joint = cramer_rao(jac, None, disturbance_covariance(own, (1.0, 0.33), (1e-4, 1e-4), cross=True))
    apart = cramer_rao(jac, None, disturbance_covariance(own, (1.0, 0.33), (1e-4, 1e-4), cross=False))
    assert np.all(np.linalg.eigvalsh(apart - joint) > -1e-12)
    assert np.all(np.diag(joint) < np.diag(apart))


def test_motor_bound_is_the_spread_of_the_likelihood_estimator_in_white_noise():
    """On a synthetic window with white noise on P (20 dB) and Q (30 dB), the ``ml`` objective is the efficient
    estimator: the spread of D over 120 noise draws is the bound computed from the truth's Jacobian."""
    case = make_cases(1, level=None, seed=11)[0]
    w = case.clean
    sp, sq = 10 ** (-20 / 20) * np.std(w.P), 10 ** (-30 / 20) * np.std(w.Q)
    rng = np.random.default_rng(2)
    noisy = [dataclasses.replace(w, P=w.P + rng.normal(0, sp, w.P.size), Q=w.Q + rng.normal(0, sq, w.Q.size))
             for _ in range(120)]
    cfg = IdentifyConfig(objective="ml", transient_tau=0.0)
    d = np.array([r.d for r in identify_many(noisy, config=cfg, workers=2)])
    truth = case.truth.d
    jac, nuis = model_jacobian(w, truth, cfg)
    l = jac.shape[0] // 2
    cov = np.kron(np.diag([sp**2, sq**2]), np.eye(l))
    ratio = (d / truth).std(axis=0) / relative_bound(cramer_rao(jac, nuis, cov), truth)
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio


def _toy(rng: np.random.Generator, n: int = 25, l: int = 30):
    """A linear errors-in-variables toy: two input channels of n samples, two output channels of l samples,
    y = A·x + J·δ + N·β + v, x a smooth stationary process (AR(1), ρ = 0.9, with a cross-correlation)."""
    c = _ar1_covariance(n, 0.9, 1.0)
    prior = np.block([[c, 0.6 * c], [0.6 * c, c]])
    a = rng.standard_normal((2 * l, 2 * n)) / np.sqrt(n)
    jac = rng.standard_normal((2 * l, 3))
    nuis = np.kron(np.eye(2), np.ones((l, 1)))
    return prior, a, jac, nuis, (0.3**2, 0.5**2), (0.2**2, 0.1**2)


def _schur(info: np.ndarray, p: int) -> np.ndarray:
    """Inverse of the information's first p×p block after the rest is estimated alongside."""
    return np.linalg.inv(info[:p, :p] - info[:p, p:] @ np.linalg.solve(info[p:, p:], info[p:, :p]))


def test_structural_input_noise_bound_is_the_joint_gaussian_bound_of_measured_inputs_and_outputs():
    """x ~ N(0, Σ_x), x_m = x + n: (x_m, y) is jointly Gaussian with mean [0; J·δ + N·β]; its Fisher information
    for δ (β alongside) is the bound with S = Σ_v + A·P_x·Aᵀ, P_x the Wiener smoother's error covariance."""
    prior, a, jac, nuis, noise_var, white_var = _toy(np.random.default_rng(4))
    n, l = prior.shape[0] // 2, jac.shape[0] // 2
    sn, sv = np.diag(np.repeat(noise_var, n)), np.diag(np.repeat(white_var, l))
    joint = np.block([[prior + sn, prior @ a.T], [a @ prior, a @ prior @ a.T + sv]])
    mean = np.vstack([np.zeros((2 * n, 5)), np.hstack([jac, nuis])])
    expected = _schur(mean.T @ np.linalg.solve(joint, mean), 3)
    p_x = input_posterior_covariance(noise_var, n, prior)
    got = cramer_rao(jac, nuis, input_noise_covariance(white_var, a, p_x))
    np.testing.assert_allclose(got, expected, rtol=1e-8)


def test_functional_input_noise_bound_treats_the_true_inputs_as_unknown_parameters():
    """No prior on x: the information of (δ, β, x) from x_m and y, x then estimated alongside, is the bound
    with P_x = Σ_n (Woodbury), and it is wider than the structural bound."""
    prior, a, jac, nuis, noise_var, white_var = _toy(np.random.default_rng(6))
    n, l = prior.shape[0] // 2, jac.shape[0] // 2
    sn, sv = np.repeat(noise_var, n), np.repeat(white_var, l)
    design = np.block([[np.zeros((2 * n, 5)), np.eye(2 * n)], [jac, nuis, a]])
    info = design.T @ (design / np.r_[sn, sv][:, None])
    expected = _schur(info, 3)
    got = cramer_rao(jac, nuis, input_noise_covariance(white_var, a, input_posterior_covariance(noise_var, n)))
    np.testing.assert_allclose(got, expected, rtol=1e-8)
    structural = cramer_rao(jac, nuis, input_noise_covariance(
        white_var, a, input_posterior_covariance(noise_var, n, prior)))
    assert np.all(np.linalg.eigvalsh(got - structural) > -1e-12) and np.all(np.diag(structural) < np.diag(got))


def test_input_noise_bound_is_the_spread_of_least_squares_on_the_smoothed_inputs_weighted_by_s():
    """Monte Carlo of the toy: regress y − A·E[x | x_m] on [J, N] by GLS with the known S; its spread is the
    structural bound (within 8 % over 2,000 draws); unweighted LS on the raw x_m is not below it."""
    rng = np.random.default_rng(8)
    prior, a, jac, nuis, noise_var, white_var = _toy(rng)
    n, l, draws = prior.shape[0] // 2, jac.shape[0] // 2, 2000
    sn, sv = np.repeat(noise_var, n), np.repeat(white_var, l)
    p_x = input_posterior_covariance(noise_var, n, prior)
    s = input_noise_covariance(white_var, a, p_x)
    bound = np.sqrt(np.diag(cramer_rao(jac, nuis, s)))
    x = linalg.cholesky(prior, lower=True) @ rng.standard_normal((2 * n, draws))
    xm = x + np.sqrt(sn)[:, None] * rng.standard_normal((2 * n, draws))
    y = a @ x + np.sqrt(sv)[:, None] * rng.standard_normal((2 * l, draws))  # δ = 0, β = 0
    xhat = prior @ np.linalg.solve(prior + np.diag(sn), xm)
    chol = linalg.cholesky(s, lower=True)
    design = linalg.solve_triangular(chol, np.hstack([jac, nuis]), lower=True)
    gls = np.linalg.lstsq(design, linalg.solve_triangular(chol, y - a @ xhat, lower=True), rcond=None)[0][:3]
    ols = np.linalg.lstsq(np.hstack([jac, nuis]), y - a @ xm, rcond=None)[0][:3]
    assert np.all(np.abs(gls.std(axis=1) / bound - 1.0) < 0.08), gls.std(axis=1) / bound
    assert np.all(ols.std(axis=1) > 0.95 * bound), ols.std(axis=1) / bound


def test_input_noise_bound_without_input_noise_is_the_exact_input_bound():
    prior, a, jac, nuis, _, white_var = _toy(np.random.default_rng(9))
    n, l = prior.shape[0] // 2, jac.shape[0] // 2
    exact = cramer_rao(jac, nuis, np.diag(np.repeat(white_var, l)))
    for p_x in (input_posterior_covariance((0.0, 0.0), n), input_posterior_covariance((0.0, 0.0), n, prior)):
        np.testing.assert_allclose(cramer_rao(jac, nuis, input_noise_covariance(white_var, a, p_x)), exact,
                                   rtol=1e-10)


def test_stationary_input_covariance_holds_the_lagged_products_of_the_record():
    """Block-Toeplitz from the record's lagged products: the lag-k entries of each block are the record's
    mean products at that lag (V leading θ above the diagonal), and the level prior sits on each channel."""
    rng = np.random.default_rng(10)
    m, n = 4000, 6
    v = np.convolve(rng.standard_normal(m + 20), np.ones(20) / 20, "valid")[:m]
    th = np.roll(v, 3) + 0.1 * rng.standard_normal(m)
    cov = stationary_input_covariance(v, th, n, level_var=0.0)
    t = np.arange(m)
    x = [z - np.polyval(np.polyfit(t, z, 1), t) for z in (v, th)]
    for k in range(n):
        np.testing.assert_allclose(cov[k, 0], x[0][k:] @ x[0][: m - k] / m, rtol=1e-10)
        np.testing.assert_allclose(cov[n + k, 0], x[1][k:] @ x[0][: m - k] / m, rtol=1e-10)
        np.testing.assert_allclose(cov[0, n + k], x[0][: m - k] @ x[1][k:] / m, rtol=1e-10)
    assert np.all(np.linalg.eigvalsh(cov) > -1e-12)
    np.testing.assert_allclose(stationary_input_covariance(v, th, n, level_var=2.0) - cov,
                               2.0 * np.kron(np.eye(2), np.ones((n, n))), atol=1e-12)


def test_input_jacobian_predicts_the_model_response_to_small_input_errors():
    """On a synthetic window at the truth: the motor and static model with V and θ perturbed by white errors of
    0.1 % / 1e-3 rad moves by A·δx to within 1 % (the model is linear at PMU noise levels)."""
    case = make_cases(1, level=None, seed=12, duration_s=6.0)[0]
    w, tr = case.clean, case.truth
    st = tr.static_identifiable
    bp, bq = np.array([st["Pp"], st["Pi"], st["Pz"]]), np.array([st["Qp"], st["Qi"], st["Qz"]])
    cfg = IdentifyConfig(input_smoother="none")
    a = input_jacobian(w, tr.d, bp, bq, cfg)
    k0 = w.V.size - a.shape[0] // 2
    dt = float(w.t[1] - w.t[0])

    def model(v: np.ndarray, th: np.ndarray) -> np.ndarray:
        p, q, _ = motor.simulate(v, th, tr.d, dt, motor.omega0_of(w.f0))
        phi = static.regressors(v)
        return np.concatenate([(p + phi @ bp)[k0:], (q + phi @ bq)[k0:]])

    base = model(w.V, w.theta)
    np.testing.assert_allclose(base, np.concatenate([w.P[k0:], w.Q[k0:]]), atol=2e-3 * np.std(w.P))
    rng = np.random.default_rng(0)
    dv, dth = 1e-3 * rng.standard_normal(w.V.size), 1e-3 * rng.standard_normal(w.V.size)
    moved = model(w.V + dv, w.theta + dth) - base
    assert np.linalg.norm(moved - a @ np.r_[dv, dth]) < 0.01 * np.linalg.norm(moved)
