"""benchmarks.input_interpolation: both interpolations on the same windows, the core's switch restored."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from aslm_core import motor  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks import input_interpolation as ii  # noqa: E402


def test_a_cell_compares_both_interpolations_on_the_same_windows_and_restores_the_core():
    cases = common.cases(3, level=None, seed=7, fs=25.0)
    c = ii.cell(cases)
    assert motor.SPLINE_INPUTS is True
    assert c["n"] == 3
    # At 25 frames/s the step is split: the two answers differ, and the difference is the paired one.
    assert not np.allclose(c["bias_lagrange"], c["bias_spline"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.array(c["bias_spline"]) - np.array(c["bias_lagrange"]), c["paired_diff"], atol=1e-12)
    assert all(0.0 <= x <= 1.0 for x in c["cover_lagrange"] + c["cover_spline"])
    at_100 = ii.cell(common.cases(2, level=None, seed=7, fs=100.0))
    np.testing.assert_array_equal(at_100["bias_lagrange"], at_100["bias_spline"])  # one step, the midpoint either way
