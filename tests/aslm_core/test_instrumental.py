"""The instrumental-variable prediction-error fit (``disturbance="ar_iv"``) through the algebraic loop."""

from __future__ import annotations

import numpy as np
import pytest

from aslm_core import IdentifyConfig, identify
from aslm_core.instrumental import FIRST_LAG, instruments
from aslm_sim.cases import make_cases

IV = IdentifyConfig(disturbance="ar_iv")
PARAMS = ("a", "b", "H2", "Tm")


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
def own_windows():
    """Grid-excited windows whose own fluctuation is about 0.6 of P's ambient std (2 Hz low-passed).

    The synthetic generator's loop is weak (the own fluctuation moves V by a few per cent): these windows test that
    the IV keeps the AR model's answer where that answer is right.  The algebraic loop that the IV is for is
    measured on the ANDES bench (benchmarks/own_fluctuation_andes.py; docs/numerics.md).
    """
    cases = make_cases(12, level=2, seed=21, input_noise=False, own_sigma=0.0015)
    return cases, [identify(c.window) for c in cases], [identify(c.window, config=IV) for c in cases]


def test_iv_recovers_d_within_its_stated_error_where_output_error_is_off(own_windows):
    cases, oe, iv = own_windows
    off = [i for i, (c, r) in enumerate(zip(cases, oe, strict=True)) if np.abs(r.d / c.truth.d - 1).max() > 0.1]
    assert len(off) >= 4
    inside = []
    for i in off:
        r, tr = iv[i], cases[i].truth.d
        z = np.abs(r.d - tr) / np.array([r.stderr[k] for k in PARAMS])
        inside.append(bool(np.all(z < 2.5)))
        assert r.quality["ar_order_p"] >= 2  # the coloured part is modelled
        assert 0.0 < r.quality["iv_strength_p"] <= 1.0
    assert np.mean(inside) >= 0.8
    err_oe = np.median([np.abs(oe[i].d / cases[i].truth.d - 1).max() for i in range(len(cases))])
    err_iv = np.median([np.abs(iv[i].d / cases[i].truth.d - 1).max() for i in range(len(cases))])
    assert err_iv < 0.75 * err_oe


def test_grid_excited_windows_identify_as_with_output_error():
    cases = make_cases(6, level=3, seed=12, input_noise=False)
    for c in cases:
        ro, ri = identify(c.window), identify(c.window, config=IV)
        se = np.array([ro.stderr[k] for k in PARAMS])
        assert np.all(np.abs(ri.d - ro.d) < se)
        # Without own fluctuation the lagged regressors predict today's well: a strong instrument.
        assert min(ri.quality["iv_strength_p"], ri.quality["iv_strength_q"]) > 0.5
        assert "own_fluctuation_unmodelled" not in ro.flags


def test_noise_free_window_is_unchanged(eq_window):
    ro, ri = identify(eq_window), identify(eq_window, config=IV)
    np.testing.assert_allclose(ri.d, ro.d, rtol=1e-3)


def test_output_error_flags_an_own_fluctuation_it_does_not_model(own_windows):
    cases, oe, iv = own_windows
    for ro, ri in zip(oe, iv, strict=True):
        assert ("own_fluctuation_unmodelled" in ro.flags) == (ro.quality["own_ratio_p"] > 0.3)
        assert "own_fluctuation_unmodelled" not in ri.flags  # ar_iv models it
    assert sum("own_fluctuation_unmodelled" in r.flags for r in oe) >= 6
