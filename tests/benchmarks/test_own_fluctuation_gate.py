"""The gated composite of the own-fluctuation bench picks each window's estimator by output error's own_ratio_p."""

import pytest

pytest.importorskip("andes")  # the bench module imports the ANDES scenario

from benchmarks.own_fluctuation_andes import gated_row  # noqa: E402


def test_gate_takes_iv_only_above_the_threshold():
    run = {"ratio": 0.5, "shape": "switching",
           "own_ratio_p": {"output error": [0.0, 0.5, 0.31]},
           "errors": {"output error": [[0.01, 0.0, 0.0, 0.0], [0.30, 0.0, 0.0, 0.0], [0.02, 0.0, 0.0, 0.0]],
                      "AR disturbance (IV)": [[0.05, 0.0, 0.0, 0.0], [-0.03, 0.0, 0.0, 0.0], [0.04, 0.0, 0.0, 0.0]]},
           "stderr": {"output error": [[0.02] * 4] * 3, "AR disturbance (IV)": [[0.02] * 4] * 3},
           "flags": {"output error": [[], ["own_fluctuation_unmodelled"], []], "AR disturbance (IV)": [[], [], []]}}
    row = gated_row(run)
    assert row[2] == "2 / 3"  # windows 2 and 3 switched, window 1 kept output error
    assert row[3].split(" / ")[0] == "3.0"  # |errors| of a: 1 (OE), 3 (IV), 4 (IV) → median 3
    assert row[4] == "4"  # worst: IV's 4 %, not output error's 30 %
    assert row[7] == "0 (0)"


def test_second_gate_falls_back_where_the_iv_rejects_its_instruments():
    run = {"ratio": 0.9, "shape": "switching",
           "own_ratio_p": {"output error": [0.8, 0.9]},
           "quality": {"AR disturbance (IV)": [{"iv_overid": 1.2}, {"iv_overid": 7.0}]},
           "errors": {"output error": [[0.10, 0.0, 0.0, 0.0], [0.12, 0.0, 0.0, 0.0]],
                      "AR disturbance (IV)": [[0.02, 0.0, 0.0, 0.0], [-0.40, 0.0, 0.0, 0.0]]},
           "stderr": {"output error": [[0.1] * 4] * 2, "AR disturbance (IV)": [[0.02] * 4] * 2},
           "flags": {"output error": [["own_fluctuation_unmodelled"]] * 2,
                     "AR disturbance (IV)": [[], ["iv_instruments_rejected"]]}}
    assert gated_row(run)[2] == "2 / 2"
    row = gated_row(run, overid_max=3.0)
    assert row[2] == "1 / 2"  # window 2's instruments rejected: output error's answer
    assert row[4] == "12"  # worst: output error's 12 %, not the IV's 40 %
