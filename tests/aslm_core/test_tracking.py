"""The tracker of aslm_core.tracking: threshold, pool, two-window change detection, state round trip."""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
import pytest

from aslm_core.tracking import Tracker, TrackerConfig, combine, threshold

D = np.array([40.0, 12.0, 1.5, 0.5])
SE = 0.02 * D  # 2 % per window, about a 22 dB window's


def _draws(rng: np.random.Generator, n: int, scale: np.ndarray = D) -> np.ndarray:
    return scale + SE * rng.standard_normal((n, 4))


def test_threshold_gives_the_false_alarm_rate_per_period():
    h = threshold(0.1, 900.0)
    alpha = 0.1 * 900.0 / 86400.0
    assert 8 * NormalDist().cdf(-h) ** 2 == pytest.approx(alpha, rel=1e-9)  # independent innovations
    assert threshold(0.1, 900.0, 16) > h and threshold(0.1, 900.0, 2) > threshold(0.1, 900.0, 16)
    assert threshold(1.0, 900.0) < h < threshold(0.01, 900.0)  # rarer alarms, higher threshold


def test_combine_is_the_information_weighted_mean_and_ignores_windows_without_se():
    from aslm_core.tracking import Estimate

    pool = [Estimate(0.0, [1.0] * 4, [1.0] * 4), Estimate(1.0, [3.0] * 4, [0.5] * 4),
            Estimate(2.0, [100.0] * 4, [math.inf] * 4)]
    mean, se = combine(pool)
    assert mean == pytest.approx([(1 + 3 * 4) / 5.0] * 4)
    assert se == pytest.approx([1 / math.sqrt(5.0)] * 4)


def test_a_step_is_confirmed_at_the_second_window_and_the_pool_restarts():
    tr = Tracker(TrackerConfig(pool_windows=8))
    rng = np.random.default_rng(3)
    for i, d in enumerate(_draws(rng, 12)):
        assert tr.update(i, d, SE) is None
    assert tr.model()["n_windows"] == 8  # capped at k
    after = D * np.array([1.2, 1.0, 1.2, 1.2])  # 20 % more motors: a, H2, Tm scale, b does not
    steps = _draws(rng, 3, after)
    assert tr.update(12, steps[0], SE) is None and tr.model()["suspect"]
    event = tr.update(13, steps[1], SE)
    assert event is not None and event.t == 12 and event.detected_t == 13
    assert event.evidence["param"] in ("a", "H2", "Tm") and min(abs(z) for z in event.evidence["z"]) > 2.0
    assert event.before["n_windows"] == 8 and event.after["n_windows"] == 2
    model = tr.model()
    assert model["n_windows"] == 2 and model["last_change"] == 12 and model["since"] == 12
    assert model["dynamic"]["Tm"] == pytest.approx(after[3], rel=0.05)
    assert tr.update(14, steps[2], SE) is None
    assert tr.model()["n_windows"] + tr.model()["suspect"] == 3  # pooled, or held out as a suspect


@pytest.mark.parametrize("scatter", [False, True])
def test_a_single_outlying_window_raises_no_alarm_and_rejoins_the_pool_winsorised(scatter):
    # At 0.1 per day (h = 2.35) and unscaled innovations window 7 of these draws is itself held as a suspect, so the
    # pool ends at the outlier; with the pool's scatter it joins the pool.
    tr = Tracker(TrackerConfig(pool_windows=16, false_alarms_per_day=0.1, pool_scatter=scatter))
    rng = np.random.default_rng(4)
    draws = _draws(rng, 10)
    for i, d in enumerate(draws[:6]):
        tr.update(i, d, SE)
    assert tr.update(6, D * 1.3, SE) is None and tr.model()["suspect"]
    assert tr.update(7, draws[7], SE) is None
    # The outlier rejoined winsorised: in the pool, but pulling it by < 1.5 % where it would have pulled 4 %.
    assert [e.t for e in tr.pool][6] == 6 and len(tr.pool) == (8 if scatter else 7)
    assert np.max(np.abs(combine(tr.pool[:7])[0] / combine(tr.pool[:6])[0] - 1.0)) < 0.015


def test_no_alarm_on_a_stationary_sequence_of_fixed_seeds():
    # 500 periods ≈ 5 bus-days at T = 15 min: ~0.26 alarms expected at the default design rate (0.05 per day).
    tr = Tracker(TrackerConfig())
    assert [i for i, d in enumerate(_draws(np.random.default_rng(100), 500)) if tr.update(i * 900.0, d, SE)] == []


def test_false_alarm_rate_on_gaussian_estimates_is_the_design_rate():
    # 20,000 periods ≈ 30 bus-weeks: the two innovations' correlation through the pool is in the threshold.
    alarms = 0
    for seed in range(40):
        tr = Tracker(TrackerConfig(false_alarms_per_day=0.1))
        alarms += sum(tr.update(i * 900.0, d, SE) is not None for i, d in enumerate(_draws(np.random.default_rng(seed), 500)))
    expected = 20_000 * 0.1 * 900.0 / 86400.0  # 20.8
    assert 0.5 * expected < alarms < 1.6 * expected


def test_the_pools_scatter_stops_alarms_from_standard_errors_too_small_and_keeps_a_step():
    """Estimates that scatter 2.5 × their standard errors (Tm under PMU noise on some buses) raise alarms without
    ``pool_scatter`` and far fewer with it; with right SEs its factor stays near 1; a 20 % step is still confirmed."""
    from aslm_core.tracking import pool_scatter

    def alarms(scatter: bool, spread: float) -> int:
        n = 0
        for seed in range(10):
            tr = Tracker(TrackerConfig(pool_scatter=scatter))
            draws = D + spread * SE * np.random.default_rng([7, seed]).standard_normal((500, 4))
            n += sum(tr.update(i * 900.0, d, SE) is not None for i, d in enumerate(draws))
        return n

    assert alarms(False, 2.5) > 20 and alarms(True, 2.5) < 0.25 * alarms(False, 2.5)
    tr = Tracker(TrackerConfig(pool_scatter=True))
    rng = np.random.default_rng(5)
    for i, d in enumerate(_draws(rng, 16)):
        tr.update(i, d, SE)
    assert np.all(pool_scatter(tr.pool, combine(tr.pool)[0]) < 1.5)
    after = D * np.array([1.2, 1.0, 1.2, 1.2])
    steps = _draws(rng, 2, after)
    assert tr.update(16, steps[0], SE) is None and tr.update(17, steps[1], SE) is not None


def test_state_round_trip_resumes_the_same_tracker():
    tr = Tracker(TrackerConfig(pool_windows=4))
    for i, d in enumerate(_draws(np.random.default_rng(5), 6)):
        tr.update(i, d, SE)
    tr.update(6, D * 1.5, SE)  # a suspect is part of the state
    back = Tracker.from_state(tr.to_state(), TrackerConfig(pool_windows=4))
    assert back.model() == tr.model() and back.suspect == tr.suspect
    assert back.update(7, D * 1.5, SE) is not None  # and confirms the change as the original would
