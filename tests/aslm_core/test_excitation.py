"""The own fluctuation's spectrum as one number (aslm_core.excitation.own_median_hz)."""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from aslm_core.excitation import own_median_hz

FS = 100.0
N = 1000


def _band_noise(rng: np.random.Generator, lo: float, hi: float) -> np.ndarray:
    """Zero-mean noise with a flat spectrum from lo to hi Hz (8th-order Butterworth band-pass), unit std."""
    sos = signal.butter(8, [lo, hi], btype="bandpass", fs=FS, output="sos")
    x = signal.sosfiltfilt(sos, rng.standard_normal(N + 400))[200:-200]
    return x / x.std()


def _band_median(lo: float, hi: float) -> float:
    """Where half of the band noise's power lies: its filter's |H|⁴ (forward and back) accumulated [Hz]."""
    sos = signal.butter(8, [lo, hi], btype="bandpass", fs=FS, output="sos")
    f = np.linspace(0.0, 5.0, 50001)
    _, h = signal.sosfreqz(sos, worN=f, fs=FS)
    cum = np.cumsum(np.abs(h) ** 4)
    return float(f[np.searchsorted(cum, 0.5 * cum[-1])])


def test_median_of_a_band_over_a_white_floor_is_where_half_its_power_lies():
    rng = np.random.default_rng(7)
    floor = 0.3
    got = [own_median_hz(_band_noise(rng, 0.5, 1.5) + floor * rng.standard_normal(N), FS, floor) for _ in range(20)]
    # The truth from the filter (0.99 Hz); one 10 s draw has ~10 periodogram bins in the band, hence the per-draw
    # spread (0.71–1.10 Hz here), while the median of 200 draws is 0.98 Hz.
    truth = _band_median(0.5, 1.5)
    assert abs(np.median(got) - truth) < 0.05 and max(abs(g - truth) for g in got) < 0.3


def test_slow_and_fast_own_processes_read_apart():
    rng = np.random.default_rng(8)
    slow = [own_median_hz(_band_noise(rng, 0.05, 0.4) + 0.3 * rng.standard_normal(N), FS, 0.3) for _ in range(10)]
    fast = [own_median_hz(_band_noise(rng, 1.5, 3.0) + 0.3 * rng.standard_normal(N), FS, 0.3) for _ in range(10)]
    assert max(slow) < 0.4 < 1.5 < min(fast)


def test_a_white_residual_at_its_floor_mostly_reads_nothing():
    # Clipping the floor bin by bin would keep its positive scatter and read ~2.5 Hz on every draw.
    rng = np.random.default_rng(9)
    got = [own_median_hz(0.3 * rng.standard_normal(N), FS, 0.3) for _ in range(20)]
    assert sum(math.isnan(g) for g in got) >= 6


def test_the_low_pass_shapes_the_floor_that_is_removed():
    # A low-passed white residual with a small own part (0.5–1.5 Hz): the floor shaped by the low-pass leaves the own
    # part, read where half its power lies; a flat floor over-removes above the cut-off and reads nothing.  Without the
    # own part the shaped floor reads nothing on most draws (its scatter about zero stays within OWN_MEDIAN_Z).
    rng = np.random.default_rng(10)
    b, a = signal.butter(2, 1.0, fs=FS)
    truth = _band_median(0.5, 1.5)
    residual = [signal.lfilter(b, a, 0.3 * rng.standard_normal(N)) for _ in range(20)]
    own = [0.08 * _band_noise(rng, 0.5, 1.5) for _ in range(20)]
    got = [own_median_hz(r + o, FS, 0.3, lowpass_hz=1.0) for r, o in zip(residual, own, strict=True)]
    flat = [own_median_hz(r + o, FS, 0.3) for r, o in zip(residual, own, strict=True)]
    alone = [own_median_hz(r, FS, 0.3, lowpass_hz=1.0) for r in residual]
    assert sum(abs(g - truth) < 0.3 for g in got) >= 16 and all(math.isnan(g) for g in flat)
    assert sum(math.isnan(g) for g in alone) >= 17
