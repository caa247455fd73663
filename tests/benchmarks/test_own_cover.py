"""benchmarks.own_cover: the coverage diagnosis read from per-window records."""

import math

import pytest

from aslm_core import instrumental
from benchmarks import own_cover


def _run(errors: list, stderr: list, quality: list) -> dict:
    name = own_cover.DEFAULT
    return {"ratio": 0.5, "shape": "lowpass", "input_noise": "none", "errors": {name: errors},
            "stderr": {name: stderr}, "quality": {name: quality}, "flags": {name: [[] for _ in errors]}}


def test_paths_are_told_apart_by_the_quality_entries():
    assert own_cover.path_of({"gated_ar_iv": 1.0, "weighted_chi2": math.nan}) == "iv"
    assert own_cover.path_of({"gated_ar_iv": 0.0, "weighted_chi2": 1.1}) == "weighted"
    assert own_cover.path_of({"gated_ar_iv": 0.0, "weighted_chi2": math.nan}) == "oe"


def test_a_cell_of_50_with_exact_intervals_is_inside_the_target_two_times_in_three():
    assert own_cover.chance_in_target(50) == pytest.approx(0.683, abs=1e-3)
    assert own_cover.chance_in_target(100) == pytest.approx(0.870, abs=1e-3)


def test_unscaled_and_scaled_undo_and_apply_the_reduced_chi2_on_iv_answers_only():
    overid = 2.5 * instrumental.OVERID_EXPECTED
    run = _run([[0.2, 0.0, 0.0, 0.0]] * 2, [[0.1, 0.1, 0.1, 0.1]] * 2,
               [{"gated_ar_iv": 1.0, "iv_overid": overid}, {"gated_ar_iv": 0.0, "iv_overid": overid}])
    k = math.sqrt(2.5)
    recorded, unscaled, scaled = (own_cover.windows(run, own_cover.DEFAULT, s) for s in ("recorded", "unscaled", "scaled"))
    assert recorded[0][0][0] == pytest.approx(2.0)
    assert unscaled[0][0][0] == pytest.approx(2.0 * k) and scaled[0][0][0] == pytest.approx(2.0 / k)
    assert unscaled[1][0][0] == scaled[1][0][0] == pytest.approx(2.0)  # output error's answer: never scaled
