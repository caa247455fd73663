"""benchmarks/input_noise_gls_form.py: each replaced ingredient is what it says it is."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import linalg

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from aslm_core.information import input_jacobian  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise_bound import MODEL, static_coefficients  # noqa: E402
from benchmarks.input_noise_gls_form import lti_jacobian, stationary_posterior, welch_posterior  # noqa: E402


def test_lti_jacobian_is_the_sample_by_sample_jacobian_to_two_per_cent():
    """The mid-window impulse response as a Toeplitz matrix against the central differences of every input sample."""
    case = common.cases(1, level=3, seed=43)[0]
    a = input_jacobian(case.clean, case.truth.d, *static_coefficients(case.truth), config=MODEL)
    lti = lti_jacobian(case, a.shape)
    assert np.linalg.norm(lti - a) / np.linalg.norm(a) < 0.02


def test_stationary_posterior_keeps_a_toeplitz_matrix_and_removes_the_edges():
    """A banded Toeplitz covariance comes back unchanged; a posterior whose edges carry more variance comes back with
    the middle's variance everywhere."""
    n = 40
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    t = np.where(lags <= 3, 0.5 ** lags, 0.0)
    block = np.block([[t, 0.3 * t], [0.3 * t, 2.0 * t]])
    np.testing.assert_allclose(stationary_posterior(block, n), block, atol=1e-12)
    prior = np.block([[linalg.toeplitz(0.9 ** np.arange(n)), np.zeros((n, n))],
                      [np.zeros((n, n)), linalg.toeplitz(0.8 ** np.arange(n))]])
    post = prior - prior @ np.linalg.solve(prior + 0.5 * np.eye(2 * n), prior)
    assert post[0, 0] > 1.2 * post[n // 2, n // 2]  # the edge is less certain
    stat = stationary_posterior(post, n)
    np.testing.assert_allclose(np.diag(stat)[:n], post[n // 2, n // 2], rtol=0.02)


def test_welch_posterior_of_white_inputs_is_the_scalar_wiener_error():
    """White signal of variance s in white noise of variance r: P_x = s·r/(s + r) at lag 0, nothing at the others."""
    rng = np.random.default_rng(0)
    n = 50
    v, th = rng.standard_normal(400 * n) * 2.0, rng.standard_normal(400 * n)
    px = welch_posterior(v, th, n, (1.0, 1.0))
    np.testing.assert_allclose(px[0, 0], 4.0 / 5.0, rtol=0.05)
    np.testing.assert_allclose(px[n, n], 1.0 / 2.0, rtol=0.05)
    assert abs(px[0, 1]) < 0.05 and abs(px[0, n]) < 0.05
