"""The Levinson whitener against the dense covariance it factors."""

import numpy as np
import pytest

from aslm_core import input_weighting as iw
from aslm_core.levinson import interleaved, whitened, whitening_matrix


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
    """W is lower-triangular and W·Σ·Wᵀ = I for Σ the time-major covariance over l samples (:func:`temporal_covariance`'s
    channel-major one, interleaved), and the quadratic form ‖W·x‖² through :func:`whitened` equals xᵀ·Σ⁻¹·x."""
    s = _spectrum(l, 0.01)
    order = [ch * l + t for t in range(l) for ch in range(2)]  # time-major row → channel-major row
    sigma = iw.temporal_covariance(s, l)[np.ix_(order, order)]
    w = whitening_matrix(iw.temporal_lags(s, l)[:l])
    assert w is not None and w.shape == (2 * l, 2 * l)
    assert np.all(np.triu(w, 1) == 0.0)
    np.testing.assert_allclose(w @ sigma @ w.T, np.eye(2 * l), atol=1e-8)
    x = np.random.default_rng(3).standard_normal((l, 6)) * 1e-3
    stacked = interleaved(x[:, :3], x[:, 3:])
    np.testing.assert_array_equal(stacked, np.vstack([x[:, :3], x[:, 3:]])[order])
    z = whitened(w, stacked)
    np.testing.assert_allclose(z, w @ stacked, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(np.sum(z**2, axis=0),
                               np.einsum("ij,ij->j", stacked, np.linalg.solve(sigma, stacked)), rtol=1e-8)


def test_a_covariance_that_is_not_positive_definite_is_refused():
    """Lag 1 larger than lag 0 (a correlation above one), a singular lag 0 and a NaN lag give None, not a whitener."""
    c = np.zeros((4, 2, 2))
    c[0] = np.eye(2)
    c[1] = 1.5 * np.eye(2)
    assert whitening_matrix(c) is None
    c = np.zeros((3, 2, 2))
    c[0] = [[1.0, 1.0], [1.0, 1.0]]
    assert whitening_matrix(c) is None
    c = np.zeros((3, 2, 2))
    c[0] = np.eye(2)
    c[1, 0, 0] = np.nan
    assert whitening_matrix(c) is None
