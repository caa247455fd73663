"""The Cramér–Rao bound (aslm_core/information.py) against closed forms and against estimators' spreads."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import linalg

from aslm_core import IdentifyConfig, identify_many
from aslm_core.information import cramer_rao, disturbance_covariance, model_jacobian, relative_bound
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
