"""The instrumental-variable prediction-error fit (``disturbance="ar_iv"``): its instruments and indicators.

Its accuracy beside the AR fit is in tests/aslm_core/test_disturbance.py (parametrised over both).
"""

from __future__ import annotations

import numpy as np
import pytest

from aslm_core import IdentifyConfig, identify
from aslm_core.instrumental import FIRST_LAG, instruments
from aslm_sim.cases import make_cases

IV = IdentifyConfig(disturbance="ar_iv")


def test_instruments_are_the_regressors_lagged_from_the_first_lag_on():
    zf = np.random.default_rng(0).standard_normal((50, 8))
    z = instruments(zf, 2)
    top = FIRST_LAG + 1
    assert z.shape == (50 - top, 1 + 2 * 7)
    np.testing.assert_array_equal(z[:, 0], 1.0)
    # Row j stands for time top + j; its instruments are the regressors (not the residual) at top + j − lag.
    np.testing.assert_array_equal(z[:, 1:8], zf[top - FIRST_LAG:50 - FIRST_LAG, 1:])
    np.testing.assert_array_equal(z[:, 8:], zf[0:50 - top, 1:])


@pytest.fixture(scope="module")
def grid_and_own():
    """Grid-excited windows without and with an own fluctuation (2 Hz low-passed, about 0.6 of P's std)."""
    grid = make_cases(6, level=3, seed=12, input_noise=False)
    own = make_cases(8, level=2, seed=21, input_noise=False, own_sigma=0.0015)
    return grid, own


def test_strong_valid_instruments_without_own_fluctuation(grid_and_own):
    for c in grid_and_own[0]:
        q = identify(c.window, config=IV).quality
        # The lagged regressors predict today's well, and the over-identification statistic is near its
        # expectation (valid instruments).
        assert min(q["iv_strength_p"], q["iv_strength_q"]) > 0.5
        assert 0.3 < q["iv_overid"] < 3.0


def test_output_error_flags_an_own_fluctuation_it_does_not_model(grid_and_own):
    grid, own = grid_and_own
    for c in grid:
        assert "own_fluctuation_unmodelled" not in identify(c.window).flags
    flagged = 0
    for c in own:
        ro, ri = identify(c.window), identify(c.window, config=IV)
        assert ("own_fluctuation_unmodelled" in ro.flags) == (ro.quality["own_ratio_p"] > 0.3)
        assert "own_fluctuation_unmodelled" not in ri.flags  # ar_iv models it
        flagged += "own_fluctuation_unmodelled" in ro.flags
    assert flagged >= 4
