"""Pooled identification (aslm_core.pooled) on windows of one simulated bus with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from aslm_core import IdentifyConfig, identify
from aslm_core.pooled import identify_pooled
from aslm_sim.cases import make_cases
from aslm_sim.network import draw_network
from aslm_sim.truth import random_truth

PARAMS = ("a", "b", "H2", "Tm")


def _bus(bus: int, n: int, snr_db: float = 14.0) -> tuple[list, np.ndarray]:
    rng = np.random.default_rng([77, bus])
    truth = random_truth(rng)
    net = draw_network(rng, truth, 50.0)
    cases = make_cases(n, snr_db=snr_db, seed=7700 + bus, input_noise=False, truths=[truth] * n,
                       networks=[net] * n)
    return [c.window for c in cases], truth.d


@pytest.fixture(scope="module")
def buses():
    return [_bus(b, 8) for b in range(5)]


def test_pooled_sigma_falls_with_k(buses):
    # Relative errors of the pooled D over 5 buses: 8 windows one at a time, or 2 pools of 4, or 1 of 8.
    err = {1: [], 4: [], 8: []}
    for windows, d_true in buses:
        for k in err:
            for g in range(0, 8, k):
                err[k].append(identify_pooled(windows[g:g + k]).d / d_true - 1.0)
    rms = {k: np.sqrt(np.mean(np.square(v), axis=0)) for k, v in err.items()}
    # Information predicts 1/√k; allow the target's 1.2 and the small sample's scatter in the mean.
    assert np.mean(rms[4] / rms[1]) < 1.2 / 2.0
    assert np.mean(rms[8] / rms[1]) < 1.2 / np.sqrt(8.0)


def test_one_window_pooled_matches_the_window_fit_and_se_shrink(buses):
    windows, d_true = buses[0]
    one = identify_pooled(windows[:1])
    alone = identify(windows[0])
    assert one.d == pytest.approx(alone.d, rel=0.02)
    assert [one.stderr[k] for k in PARAMS] == pytest.approx([alone.stderr[k] for k in PARAMS], rel=0.3)
    four = identify_pooled(windows[:4], start=one.d)
    assert four.status == "converged" and four.n_windows == 4 and len(four.static) == 4
    for k in PARAMS:
        assert four.stderr[k] < 0.7 * one.stderr[k]
    assert np.all(np.abs(four.d / d_true - 1.0) < 5 * np.array([four.stderr[k] for k in PARAMS]) / d_true)


def test_pooled_standard_errors_read_the_residuals_spectrum_as_the_window_fits_do(buses):
    """After a 2 Hz low-pass the residuals are coloured well beyond their first lag: a one-window pool's spectral SEs
    are the window fit's (within 15 %), where the lag-1 rule's are over 1.2 × them."""
    from dataclasses import replace

    config = IdentifyConfig(lowpass_hz=2.0, input_weighting="none", disturbance="none")
    for w in buses[0][0][:2]:
        alone = identify(w, config=config)
        se = np.array([alone.stderr[k] for k in PARAMS])
        pooled = identify_pooled([w], config=config, start=alone.d)
        lag1 = identify_pooled([w], config=replace(config, stderr_method="ar1"), start=alone.d)
        np.testing.assert_allclose([pooled.stderr[k] for k in PARAMS], se, rtol=0.15)
        assert np.all(np.array([lag1.stderr[k] for k in PARAMS]) > 1.2 * se)


def test_shared_static_gives_one_static_part_close_to_the_per_window_pool(buses):
    windows, _ = buses[1]
    per = identify_pooled(windows[:4])
    shared = identify_pooled(windows[:4], start=per.d, shared_static=True)
    assert len(shared.static) == 1 and set(shared.static[0]) == {"Pz", "Pi", "Pp", "Qz", "Qi", "Qp"}
    assert shared.d == pytest.approx(per.d, rel=0.05)


def test_no_window_is_an_error():
    with pytest.raises(ValueError):
        identify_pooled([])


def _own_bus(own_sigma: float) -> tuple[list, np.ndarray]:
    """Four windows of one bus whose load's own constant-power part fluctuates (2 Hz low-passed, std ``own_sigma``)."""
    rng = np.random.default_rng([78, 0])
    truth = random_truth(rng)
    net = draw_network(rng, truth, 50.0)
    cases = make_cases(4, level=2, seed=7800, input_noise=False, truths=[truth] * 4, networks=[net] * 4,
                       own_sigma=own_sigma)
    return [c.window for c in cases], truth.d


@pytest.fixture(scope="module")
def own_bus():
    """The own fluctuation ~0.6 of P's std (own ratio ~0.24 at the white pool)."""
    return _own_bus(0.0015)


def test_pooled_iv_is_the_window_fit_for_one_window_and_shrinks_its_errors_with_more(own_bus):
    windows, d_true = own_bus
    iv = IdentifyConfig(disturbance="ar_iv")
    alone = identify(windows[0], config=iv)
    one = identify_pooled(windows[:1], disturbance="ar_iv", iv_estimator="2sls", iv_whitening="residual")
    # The same estimator (the pool starts at the window's output-error optimum, as identify does).
    assert one.d == pytest.approx(alone.d, rel=0.03)
    assert [one.stderr[k] for k in PARAMS] == pytest.approx([alone.stderr[k] for k in PARAMS], rel=0.3)
    four = identify_pooled(windows, disturbance="ar_iv", start=one.d, iv_estimator="2sls", iv_whitening="residual")
    se = np.array([four.stderr[k] for k in PARAMS])
    assert np.all(se < 0.8 * np.array([one.stderr[k] for k in PARAMS]))
    assert np.all(np.abs(four.d - d_true) < 4 * se)


def test_pooled_iv_takes_no_shared_static_part(own_bus):
    with pytest.raises(ValueError):
        identify_pooled(own_bus[0][:2], disturbance="ar_iv", shared_static=True)
    with pytest.raises(ValueError):
        identify_pooled(own_bus[0][:2], disturbance="ar")
    with pytest.raises(ValueError, match="iv_estimator"):
        identify_pooled(own_bus[0][:2], iv_estimator="gmm")


@pytest.mark.parametrize("options", [{"iv_estimator": "2sls"}, {"iv_whitening": "residual"}, {}])
def test_pooled_iv_options_reach_the_pooled_fit_and_stay_within_the_errors(own_bus, options, monkeypatch):
    """The pool's IV options (default LIML with the own fluctuation's AR models; 2SLS, the residual's AR models)
    reach the pooled fit, and the four windows' pool with them is within 4 SE of the truth."""
    from aslm_core import instrumental

    seen = []
    fit_pooled = instrumental.fit_pooled

    def spy(*args, **kwargs):
        seen.append((kwargs["estimator"], kwargs["whitening"]))
        return fit_pooled(*args, **kwargs)

    monkeypatch.setattr(instrumental, "fit_pooled", spy)
    windows, d_true = own_bus
    four = identify_pooled(windows, disturbance="ar_iv", **options)
    assert seen == [(options.get("iv_estimator", "liml"), options.get("iv_whitening", "own"))]
    se = np.array([four.stderr[k] for k in PARAMS])
    assert np.all(np.abs(four.d - d_true) < 4 * se)


@pytest.fixture(scope="module")
def own_dominated_bus():
    """The own fluctuation dominating P's ambient variation (own ratio ~0.8)."""
    return _own_bus(0.008)


def test_the_gated_pool_takes_the_iv_where_the_own_fluctuation_dominates(own_dominated_bus):
    """The default pool reads the own ratio at the white-noise optimum and, above the single window's gate, returns
    the pooled IV's answer: within 3 SE of the truth, where the white-noise pool is off by more than 10 % in a."""
    windows, d_true = own_dominated_bus
    white = identify_pooled(windows, disturbance="none")
    iv = identify_pooled(windows, disturbance="ar_iv")
    gated = identify_pooled(windows)
    assert gated.disturbance == "ar_iv" and white.disturbance == "none"
    assert gated.own_ratio_p > 0.6 and gated.own_ratio_p == white.own_ratio_p
    np.testing.assert_array_equal(gated.d, iv.d)
    se = np.array([gated.stderr[k] for k in PARAMS])
    assert np.all(np.abs(gated.d - d_true) < 3 * se)
    assert abs(white.d[0] / d_true[0] - 1.0) > 0.1


def test_the_gated_pool_keeps_the_white_answer_without_own_fluctuation(buses):
    windows, _ = buses[2]
    white = identify_pooled(windows[:4], disturbance="none")
    gated = identify_pooled(windows[:4])
    assert gated.disturbance == "none" and gated.own_ratio_p < 0.1 and gated.flags == white.flags
    np.testing.assert_array_equal(gated.d, white.d)
    assert gated.stderr == white.stderr


def test_the_gated_pool_with_one_static_part_flags_the_own_fluctuation_it_cannot_model(own_dominated_bus):
    """The IV keeps a static part per window, so a shared one leaves the white-noise answer, flagged."""
    windows, _ = own_dominated_bus
    shared = identify_pooled(windows[:2], shared_static=True)
    assert shared.disturbance == "none" and "own_fluctuation_unmodelled" in shared.flags
