"""benchmarks.input_noise_cutoffs: the smoother's cut-offs on noisy windows and where the tail's spectrum ends."""

from __future__ import annotations

import pytest

from aslm_core.noise import FLOOR_FROM_HZ
from benchmarks.input_noise_cutoffs import edge_profile, rate_summary


def test_the_tail_runs_from_the_cut_off_to_the_floor_band():
    r = rate_summary(25.0, n=4, seed=49)
    lo, med, hi = r["cut_v"]
    # 0.1 % noise on a 25 frames/s window: the signal sinks into the floor well below Nyquist (12.5 Hz) ...
    assert 0.5 < lo <= med <= hi < FLOOR_FROM_HZ
    # ... and the tail carries every such window's spectrum on to the floor band, changing V little.
    assert r["share_tailed"] == 1.0 and r["end_v"] == pytest.approx(FLOOR_FROM_HZ)
    assert 0.9 < r["error_ratio_v"] < 1.1


def test_the_smoothed_inputs_error_is_larger_only_in_the_windows_last_and_first_tenth_of_a_second():
    """100 windows at 100 frames/s (measured: error² over mid-window's 1.75 / 2.04 in the first 0.1 s, V / θ, 2.02 /
    1.96 in the last; 0.86–1.08 from 0.25 s in): the smoother's error is stationary but for ~10 samples at each end."""
    r = edge_profile(100.0, n=100, seed=49)
    assert min(r["start"][0] + r["end"][0]) > 1.4
    for span in r["start"][2:] + r["end"][2:]:
        assert 0.75 < min(span) and max(span) < 1.3
