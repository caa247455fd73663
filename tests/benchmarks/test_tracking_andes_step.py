"""The ANDES step of the tracking benchmark (benchmarks/tracking.py, part ``andes_step``): its load and truth.

No ANDES run here (tests/aslm_sim/test_andes_scenarios.py runs a toggled motor); these check that the
second motor is the first one scaled, off until its toggle, and that the truth after is their sum.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import tracking  # noqa: E402


def test_the_second_motor_is_the_first_scaled_and_off_until_its_toggle():
    load = tracking.andes_step_load(7, 0.2, 82.0)
    (m1, d1), (m2, d2) = load.motors
    assert m1 == m2 == "Motor3"
    assert load.toggles == ((1, 82.0),)
    assert d2["u"] == 0 and "u" not in d1
    assert d2["Sn"] == pytest.approx(0.2 * d1["Sn"]) and d2["c1"] == pytest.approx(0.2 * d1["c1"])
    assert {k: v for k, v in d2.items() if k not in ("Sn", "c1", "u")} == {k: v for k, v in d1.items()
                                                                          if k not in ("Sn", "c1")}


def test_the_truth_after_is_one_motor_of_the_summed_size():
    d1 = [30.0, 25.0, 1.6, 0.2]
    before, after = tracking.andes_step_truth([{"d": d1}, {"d": [6.0, 25.0, 0.32, 0.04]}])
    np.testing.assert_allclose(before, d1)
    np.testing.assert_allclose(after, [36.0, 25.0, 1.92, 0.24])
    with pytest.raises(ValueError, match="per unit"):
        tracking.andes_step_truth([{"d": d1}, {"d": [6.0, 20.0, 0.32, 0.04]}])
