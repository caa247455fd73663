"""The look-alike pair measurement's bookkeeping (benchmarks/diagnosis_pairs.py): the two-way outcomes."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import diagnosis_pairs as dp  # noqa: E402


def _rec(kind: str, truth: str | None, zab: float, zba: float, fits: bool = True) -> dict:
    a, b = "second_motor", "double_cage_rotor"
    return {"pair": [a, b], "kind": kind, "truth": truth, "seed": 1, "window": [2.0, 12.0], "level": 3,
            "input_noise": False, "separation_z": {f"{a}>{b}": zab, f"{b}>{a}": zba},
            "members": {a: {"fits": fits}, b: {"fits": False}}}


def test_outcomes_are_counted_from_the_true_members_side_and_windows_nobody_fits_are_left_out():
    recs = [
        _rec("second_motor", "second_motor", 3.0, 0.0),          # right
        _rec("second_motor", "second_motor", 0.0, 3.0),          # wrong
        _rec("double_cage", "double_cage_rotor", 0.0, 3.0),      # the double cage beats: right on its data
        _rec("double_cage", "double_cage_rotor", 3.0, 3.0),      # both ways
        _rec("double_cage", "double_cage_rotor", 0.0, 0.0),      # neither
        _rec("double_cage", "double_cage_rotor", 9.0, 0.0, fits=False),  # no member fits: not counted
        {"kind": "double_cage", "seed": 2, "failed": "ValueError()"},
    ]
    s = dp.summarise(recs)["second_motor / double_cage_rotor"]
    assert s["second_motor"]["pq"]["3"] == {"x-": 1, "-y": 1, "xy": 0, "--": 0}
    assert s["double_cage"]["pq"]["3"] == {"x-": 1, "-y": 0, "xy": 1, "--": 1}
