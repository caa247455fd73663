"""benchmarks.input_noise_cutoffs: the smoother's cut-offs on noisy windows and where the tail's spectrum ends."""

from __future__ import annotations

import pytest

from aslm_core.noise import FLOOR_FROM_HZ
from benchmarks.input_noise_cutoffs import rate_summary


def test_the_tail_runs_from_the_cut_off_to_the_floor_band():
    r = rate_summary(25.0, n=4, seed=49)
    lo, med, hi = r["cut_v"]
    # 0.1 % noise on a 25 frames/s window: the signal sinks into the floor well below Nyquist (12.5 Hz) ...
    assert 0.5 < lo <= med <= hi < FLOOR_FROM_HZ
    # ... and the tail carries every such window's spectrum on to the floor band, changing V little.
    assert r["share_tailed"] == 1.0 and r["end_v"] == pytest.approx(FLOOR_FROM_HZ)
    assert 0.9 < r["error_ratio_v"] < 1.1
