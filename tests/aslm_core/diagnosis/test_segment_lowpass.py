"""The diagnosis's zero-phase low-pass (segment._lowpass): scipy's sosfiltfilt with its filter setup cached."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from aslm_core.diagnosis.segment import _lowpass, butter_sos


def test_lowpass_is_scipys_sosfiltfilt_bit_for_bit():
    # The cached initial state must not move a single bit: the switched shunt's scan compares paths read through it.
    rng = np.random.default_rng(7)
    for size in (16, 40, 641, 1001):  # 16: one sample beyond the padding (15 for this filter)
        for fc in (0.5, 2.5, 5.0):
            x = 1.0 + 1e-3 * rng.standard_normal(size).cumsum()
            assert np.array_equal(_lowpass(x, 100.0, fc), signal.sosfiltfilt(butter_sos(fc, 100.0), x)), (size, fc)
    x2 = rng.standard_normal((3, 200))  # not one record: scipy's own path
    assert np.array_equal(_lowpass(x2, 100.0, 2.5), signal.sosfiltfilt(butter_sos(2.5, 100.0), x2))


def test_lowpass_rejects_a_record_shorter_than_its_padding_like_scipy():
    with pytest.raises(ValueError):
        _lowpass(np.ones(15), 100.0, 2.5)
