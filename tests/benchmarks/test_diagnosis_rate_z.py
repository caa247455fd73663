"""``benchmarks.diagnosis_rate_z``: the right candidate's z per case, P/Q-noise cases only."""

from __future__ import annotations

from benchmarks.diagnosis_rate_z import candidate_z


def _rec(expected, verdict, cause, input_noise, cands):
    return {"expected": expected, "verdict": verdict, "cause": cause, "input_noise": input_noise, "candidates": cands}


def test_candidate_z_counts_names_and_reads_the_effects_own_candidate():
    recs = [
        _rec("second_motor", "explained", "second_motor", False,
             [{"name": "second_motor", "tested": True, "z": 5.0}, {"name": "double_cage_rotor", "tested": True, "z": 9.0}]),
        _rec("second_motor", "consistent", None, False, [{"name": "second_motor", "tested": True, "z": 1.5}]),
        _rec("second_motor", "explained", "double_cage_rotor", False, [{"name": "second_motor", "tested": False}]),
        _rec("second_motor", "explained", "second_motor", True, [{"name": "second_motor", "tested": True, "z": 7.0}]),
        _rec("frequency_dependence", "explained", "frequency_dependence", False,
             [{"name": "frequency_dependence", "tested": True, "z": 20.0}]),
    ]
    assert candidate_z(recs, "second_motor") == (1, 3, [5.0, 1.5])
    assert candidate_z(recs, "frequency_dependence") == (1, 1, [20.0])
