"""benchmarks/input_noise_bound.py on one window: the bounds' order and the oracle GLS's fit."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import INPUT_NOISE  # noqa: E402
from benchmarks.input_noise_bound import KINDS, LEVELS, window_bounds  # noqa: E402


def test_one_window_bound_orders_exact_structural_functional_and_the_oracle_fits():
    """More input noise never informs more: exact ≤ structural ≤ functional, 0.03 % ≤ 0.1 %; more P, Q noise
    (lower DL) never either; the default and the oracle GLS land near the truth on a clean-ish window."""
    cases = {level: common.cases(1, level=level, seed=43)[0] for level in LEVELS}
    rngs = {(level, k): np.random.default_rng([43, level, k]) for level in LEVELS for k in range(len(INPUT_NOISE))}
    bounds, ests = window_bounds(cases, rngs, long_s=60.0)
    low, high = INPUT_NOISE[1][0], INPUT_NOISE[2][0]
    for level in LEVELS:
        b = bounds[level]
        for cls in (low, high):
            assert np.all(b["exact"] <= b[f"{cls}|structural"] * (1 + 1e-9))
            assert np.all(b[f"{cls}|structural"] <= b[f"{cls}|functional"] * (1 + 1e-9))
        for kind in KINDS:
            assert np.all(b[f"{low}|{kind}"] <= b[f"{high}|{kind}"])
        for cls, _, _ in INPUT_NOISE:
            default, gls = ests[level][cls]
            assert np.all(np.abs(default - 1) < 0.3) and np.all(np.abs(gls - 1) < 0.3), (level, cls, default, gls)
    for key in bounds[1]:
        assert np.all(bounds[1][key] >= bounds[3][key])


def test_weighting_part_runs_both_estimators_on_the_same_windows():
    """``--weighting`` on one window per level: every level and class for both estimators, the exact-input
    rows the same D for both (the option leaves exact inputs alone), and the summary against a bound."""
    from benchmarks.input_noise_bound import WEIGHTING, weighting_run, weighting_summary, weighting_targets

    per = weighting_run(1, 1)
    assert len(per) == len(LEVELS) * len(INPUT_NOISE) * len(WEIGHTING)
    for level in LEVELS:
        assert per[f"{level}|none|none"]["ratio"] == per[f"{level}|none|spectral"]["ratio"]  # estimator "none": no weighting
    var = {str(level): {"exact": [1e-4] * 4, **{f"{c}|structural": [1e-3] * 4 for c, _, _ in INPUT_NOISE[1:]}}
           for level in LEVELS}
    per2 = {k: {f: v[f] * 2 for f in v} for k, v in per.items()}  # two windows: σ needs more than one
    summ = weighting_summary(per2, [var, var])
    assert all(row["n"] == 2 and len(row["sigma_over_bound"]) == 4 for row in summ.values())
    assert len(weighting_targets(summ)) == len(LEVELS) * 2 * len(WEIGHTING)
