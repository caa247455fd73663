"""The oracle-detectability tally (benchmarks/diagnosis_detectability.py) and the fourth confirmation set."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import diagnosis_detectability as dd  # noqa: E402
from benchmarks import diagnosis_independent as di  # noqa: E402


def _case(kind: str, level: int, z: float, outcome: str, z_form: float | None = None) -> dict:
    return {"kind": kind, "level": level, "z_oracle": z, "z_form": z_form, "outcome": outcome,
            "expected": "second_motor" if kind == "second_motor" else "consistent"}


def test_cases_are_split_at_the_critical_value_and_right_names_counted_on_each_side():
    rows = [_case("second_motor", 1, 1.0, "consistent"), _case("second_motor", 1, 3.5, "second_motor", 3.4),
            _case("second_motor", 1, 5.0, "consistent", 2.0), _case("second_motor", 1, 4.0, "ambiguous", 3.9),
            _case("second_motor", 2, 9.0, "second_motor", 8.0)]
    tab = {(t["kind"], t["level"]): t for t in dd.table(rows, 3.06)}
    l1 = tab[("second_motor", 1)]
    assert (l1["cases"], l1["detectable"], l1["right_det"], l1["consistent_det"], l1["ambiguous_det"]) == (4, 3, 1, 1, 1)
    assert (l1["undet_with_verdict"], l1["right_undet"], l1["form_below"]) == (1, 0, 1)
    assert tab[("second_motor", 2)]["right_det"] == 1
    assert "| second_motor | L1 | 4 | 3 | 1/4 | 1/3 | 1 | 1 | 0/1 | 1 |" in dd.markdown(dd.table(rows, 3.06), 3.06)


def test_the_fourth_confirmation_set_has_the_third_ones_size():
    assert len(di.SETS["confirm4"]["clean"]) >= 10 and len(di.SETS["confirm4"]["effect"]) >= 4
