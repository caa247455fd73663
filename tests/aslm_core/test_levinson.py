"""The Levinson whitener against the dense covariance it factors."""

import numpy as np
import pytest

from aslm_core import input_weighting as iw
from aslm_core.levinson import whitening_matrix


def _spectrum(l: int, dt: float) -> np.ndarray:
    """A [P; Q] disturbance spectrum as the temporal form builds it on the doubled grid: a coherent two-channel
    VAR(2) input error through a 2×2 response, white P, Q floors, and the band above 5 Hz multiplied by
    ``BAND_DOWNWEIGHT`` (a dynamic range of ~1e7 across frequency)."""
    f = np.fft.rfftfreq(2 * l, dt)
    z = np.exp(-2j * np.pi * f * dt)[:, None, None]
    a1 = np.array([[1.2, 0.3], [-0.2, 0.9]])
    a2 = np.array([[-0.4, 0.0], [0.1, -0.3]])
    g = np.linalg.inv(np.eye(2) - a1 * z - a2 * z**2)
    s = 1e-6 * g @ np.array([[1.0, 0.6], [0.6, 0.5]]) @ np.conj(np.swapaxes(g, 1, 2))
    s[:, 0, 0] += 1e-8
    s[:, 1, 1] += 4e-9
    s[f > 5.0] *= iw.BAND_DOWNWEIGHT
    return s


@pytest.mark.parametrize("l", [1, 2, 7, 300])
def test_the_whitener_whitens_the_window_covariance(l):
    """W·Σ·Wᵀ = I for Σ the channel-major covariance over l samples (:func:`temporal_covariance`), and the quadratic
    form ‖W·x‖² equals xᵀ·Σ⁻¹·x."""
    s = _spectrum(l, 0.01)
    sigma = iw.temporal_covariance(s, l)
    w = whitening_matrix(iw.temporal_lags(s, l)[:l])
    assert w is not None and w.shape == (2 * l, 2 * l)
    np.testing.assert_allclose(w @ sigma @ w.T, np.eye(2 * l), atol=1e-8)
    x = np.random.default_rng(3).standard_normal((2 * l, 3)) * 1e-3
    np.testing.assert_allclose(np.sum((w @ x) ** 2, axis=0), np.einsum("ij,ij->j", x, np.linalg.solve(sigma, x)),
                               rtol=1e-8)


def test_a_covariance_that_is_not_positive_definite_is_refused():
    """Lag 1 larger than lag 0 (a correlation above one) and a singular lag 0 give None, not a whitener."""
    c = np.zeros((4, 2, 2))
    c[0] = np.eye(2)
    c[1] = 1.5 * np.eye(2)
    assert whitening_matrix(c) is None
    c = np.zeros((3, 2, 2))
    c[0] = [[1.0, 1.0], [1.0, 1.0]]
    assert whitening_matrix(c) is None
