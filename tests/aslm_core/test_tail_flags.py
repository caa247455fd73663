"""The flags of stop 28 that catch the tail (docs/numerics.md, "Flags that catch the tail").

Each unflagged kind is rebuilt from the own-fluctuation bench (``benchmarks.own_fluctuation``, seed 245, the
stop-27 confirmation, now development data): a window whose default answer was off by more than 20 % with no
warning flag now gets its flag, D unchanged; a well-excited window of the same row whose answer is within 5 %
gets none of them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from aslm_core import IdentifyConfig, identify, input_weighting, motor, noise
from aslm_core.identify import HALVES_Z_MAX, IV_SE_MAX, WEIGHTED_SHIFT_Z_MAX
from aslm_sim.cases import make_cases
from benchmarks.own_fluctuation import LEVEL
from benchmarks.own_fluctuation import bench_window as own_bench_window

DEFAULT = IdentifyConfig()  # the library default
#: The default before the spectrum's tail (stop 41), which answered the two weighted windows below far off: the flags
#: are tested on those answers; the default answers them within 11 % and 8 % (checked in each test).
NO_TAIL = replace(DEFAULT, input_spectrum_tail=False)
NEW_FLAGS = ("input_noise_correction_large", "error_may_exceed_20pct", "halves_disagree")


def bench_window(i: int, ratio: float, shape: str, noise: int, seed: int = 245):
    """Window ``i`` of the own bench's row and its true D."""
    w, case = own_bench_window(i, ratio, shape, noise, seed)
    return w, case.truth.d


def test_weighted_answer_moved_far_from_output_error_is_flagged(monkeypatch):
    """Seed 245, own ratio 0, 0.1 % / 1e-3 rad, window 28: Tm +25 % at 3.5 SE, SE under 6 %, no warning flag at
    stop 27; the input-noise correction moved D by 2.7 of its SEs from output error's, so it is flagged now
    (without the spectrum's tail and the band's 4 Hz cap of stop 49: with both, the default, the window is answered
    within 11 %: Tm −10 %, −1 % before the cap)."""
    w, truth = bench_window(28, 0.0, "lowpass", 2)
    assert np.abs(identify(w, config=DEFAULT).d / truth - 1).max() < 0.11
    monkeypatch.setattr(input_weighting, "MAX_BAND_HZ", float("inf"))  # as the answer below was made
    monkeypatch.setattr(noise, "WHITE_LEVEL_LR_MIN", float("inf"))  # and P's floor as stop 27 read it
    r = identify(w, config=NO_TAIL)
    assert r.d[3] / truth[3] - 1 == pytest.approx(0.252, abs=0.002)  # the stop-27 answer
    assert r.quality["weighted_shift_z"] > WEIGHTED_SHIFT_Z_MAX
    assert "input_noise_correction_large" in r.flags and "input_noise_too_large" not in r.flags


def test_weighted_answer_with_a_wide_standard_error_is_flagged(monkeypatch):
    """Window 53 of the same row: Tm −37 % with an SE 20 % of the estimate (under ``uncertain``'s 25 %), without the
    spectrum's tail and the band's cap (the default: Tm −7 %, −3 % before the cap)."""
    w, truth = bench_window(53, 0.0, "lowpass", 2)
    assert np.abs(identify(w, config=DEFAULT).d / truth - 1).max() < 0.08
    monkeypatch.setattr(input_weighting, "MAX_BAND_HZ", float("inf"))  # as the answer below was made
    monkeypatch.setattr(noise, "WHITE_LEVEL_LR_MIN", float("inf"))  # and P's floor as stop 27 read it
    r = identify(w, config=NO_TAIL)
    assert r.d[3] / truth[3] - 1 == pytest.approx(-0.368, abs=0.002)
    assert r.stderr["Tm"] > IV_SE_MAX * abs(r.dynamic["Tm"])
    assert "error_may_exceed_20pct" in r.flags


def test_iv_answer_whose_halves_disagree_is_flagged():
    """Seed 245, 1/f own fluctuation at 0.5, window 22: the gated IV answered Tm +22 % at 3.6 SE with every SE
    under ``IV_SE_MAX``; its two half-window IV fits are 3.8 combined SEs apart.  That answer is the IV's with the
    channels as measured (the default until stop 34, ``couple_channels=False``); with Q − k·P as its second channel
    the same window is answered within a few per cent (checked below), so the flag is tested on the uncoupled fit."""
    w, truth = bench_window(22, 0.5, "pink", 0)
    coupled = identify(w, config=DEFAULT)
    assert np.abs(coupled.d / truth - 1).max() < 0.05
    r = identify(w, config=replace(DEFAULT, couple_channels=False))
    assert r.quality["gated_ar_iv"] == 1.0
    assert r.d[3] / truth[3] - 1 == pytest.approx(0.222, abs=0.002)
    assert "iv_error_may_exceed_20pct" not in r.flags
    assert r.quality["halves_z"] > HALVES_Z_MAX and "halves_disagree" in r.flags


@pytest.mark.parametrize("spline, tm_error", [(False, 0.227), (True, 0.259)])
def test_output_error_answer_with_a_wide_standard_error_is_flagged(monkeypatch, spline, tm_error):
    """The rates bench (development seed 46) at 30 frames/s with exact inputs, window 98: output error's Tm +23 %
    at 1.6 SE, the SE 11 % of the estimate, no warning flag at stop 27; the SE rule now covers every path.  With the
    spline inside the sample step (stop 50, the default) the window is answered Tm +26 %, the SE 10 %: flagged too."""
    monkeypatch.setattr(motor, "SPLINE_INPUTS", spline)
    c = make_cases(99, level=LEVEL, seed=46 * 1000, input_noise=False, fs=30.0)[98]  # common.cases' first chunk
    r = identify(c.window, config=DEFAULT)
    assert r.quality["gated_ar_iv"] == 0.0 and "weighted_shift_z" not in r.quality
    assert r.d[3] / c.truth.d[3] - 1 == pytest.approx(tm_error, abs=0.002)
    assert r.stderr["Tm"] > IV_SE_MAX * abs(r.dynamic["Tm"])
    assert "error_may_exceed_20pct" in r.flags


@pytest.mark.parametrize("i, ratio, shape, noise, path", [
    (0, 0.0, "lowpass", 2, "weighted"),  # input noise 0.1 % / 1e-3 rad, V 5× its noise
    (4, 0.5, "pink", 0, "iv"),  # the gate's IV answer, exact inputs
    (0, 0.0, "lowpass", 0, "oe"),  # grid-excited, exact inputs: output error
])
def test_well_excited_windows_within_5_percent_get_none_of_the_flags(i, ratio, shape, noise, path):
    w, truth = bench_window(i, ratio, shape, noise)
    r = identify(w, config=DEFAULT)
    assert np.max(np.abs(r.d / truth - 1)) < 0.05
    assert (r.quality["gated_ar_iv"] == 1.0) == (path == "iv")
    assert ("weighted_shift_z" in r.quality) == (path == "weighted")
    assert not any(f in r.flags for f in NEW_FLAGS)
