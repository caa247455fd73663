"""Stop 59's rule (benchmarks.output_floors.RULE): each criterion fails on its own count."""

from __future__ import annotations

import copy

import pytest

from benchmarks import output_floors as of


def _rows() -> tuple[list[dict], list[dict]]:
    """Rows of both trees that meet every criterion: the generator at every rate and DL, ANDES at three rates, own
    fluctuation windows."""
    after, before = [], []

    def add(keys: dict, noise: float, band: float, gated: float = 0.0, omh: float | None = None) -> None:
        common = {**keys, "inj_p": 1e-3, "inj_q": 1e-3, "own_ratio_p": 0.1, "d": [10.0, 5.0, 1.0, 0.5]}
        after.append({**common, "noise_p": noise * 1e-3, "noise_q": noise * 1e-3, "floor_p": band * 1e-3,
                      "floor_q": band * 1e-3, "gated": gated, "own_median_hz_p": omh})
        before.append({**common, "noise_p": band * 1e-3, "noise_q": band * 1e-3, "floor_p": None, "floor_q": None,
                       "gated": gated, "own_median_hz_p": omh})

    for fs in of.RATES:
        for level in (1, 2, 3):
            for cls in range(3):
                for i in range(50):
                    add({"set": "generator", "fs": fs, "level": level, "cls": cls, "i": i}, 0.95 + 0.002 * i, 1.3)
    for fs in (25.0, 50.0, 100.0):
        for i in range(40):
            add({"set": "andes", "seed": 91, "fs": fs, "cls": 1, "i": i, "draw": 0}, 1.5 if fs == 25.0 else 1.0, 3.0)
    for fs in of.OWN_RATES:
        for i in range(100):
            add({"set": "own", "fs": fs, "ratio": 0.5, "shape": "lowpass", "cls": 0, "i": i}, 1.0, 1.2, 1.0, 0.7)
    return after, before


def _where(rows: list[dict], **keys) -> list[dict]:
    return [r for r in rows if all(r.get(k) == v for k, v in keys.items())]


def test_the_rule_is_met_by_rows_that_meet_it():
    after, before = _rows()
    out = of.verdict(after, before)
    assert out["met"], out["criteria"]


def _fails(after: list[dict], before: list[dict], criterion: str) -> None:
    out = of.verdict(after, before)
    assert not out["criteria"][criterion] and all(v for k, v in out["criteria"].items() if k != criterion), out["criteria"]


@pytest.mark.parametrize("factor", [0.85, 1.15])
def test_c1_fails_where_one_cells_median_leaves_the_band(factor):
    after, before = _rows()
    for r in _where(after, set="generator", fs=30.0, level=2, cls=1):
        r["noise_q"] *= factor
    _fails(after, before, "C1")


def test_c1_fails_where_one_cells_tail_reads_too_high():
    after, before = _rows()
    for r in _where(after, set="generator", fs=120.0, level=3, cls=0)[-6:]:
        r["noise_p"] = 1.5e-3
    _fails(after, before, "C1")


def test_c2_fails_at_50_frames_per_second_off_the_noise_and_at_25_near_the_band_median():
    after, before = _rows()
    for r in _where(after, set="andes", fs=50.0):
        r["noise_p"] = 1.15e-3
    _fails(after, before, "C2")
    after, before = _rows()
    for r in _where(before, set="andes", fs=25.0):
        r["noise_q"] = 2.0e-3  # the band median: 1.5 is above 0.7 x of it
    _fails(after, before, "C2")


def test_c3_fails_where_answers_move_without_a_gate_change_or_too_many_move():
    after, before = _rows()
    _where(after, set="generator", fs=60.0)[0]["d"] = [10.0, 5.0, 1.0, 0.51]
    _fails(after, before, "C3")
    after, before = _rows()
    for r in _where(after, set="generator", fs=60.0)[:10]:  # 10 of 450: above 2 %, each with its gate switched
        r["d"], r["gated"] = [11.0, 5.0, 1.0, 0.5], 1.0
    _fails(after, before, "C3")
    after, before = _rows()
    for r in _where(after, set="generator", fs=60.0)[:9]:  # 9 of 450: 2 %, each with its gate switched
        r["d"], r["gated"] = [11.0, 5.0, 1.0, 0.5], 1.0
    assert of.verdict(after, before)["met"]


def test_c4_fails_where_gates_switch_or_the_own_spectrum_goes_unread():
    after, before = _rows()
    for r in _where(after, set="own")[:4]:
        r["gated"] = 0.0
    _fails(after, before, "C4")
    after, before = _rows()
    for r in _where(after, set="own")[:10]:
        r["own_median_hz_p"] = None
    _fails(after, before, "C4")


def test_c5_fails_where_exact_inputs_read_an_own_spectrum():
    after, before = _rows()
    for r in _where(after, set="generator", cls=0, fs=100.0)[:40]:
        r["own_median_hz_p"] = 2.5
    _fails(after, before, "C5")


def test_windows_missing_from_either_tree_are_left_out():
    after, before = _rows()
    extra = copy.deepcopy(after[0])
    extra["i"] = 999
    assert of.verdict(after + [extra], before)["windows"] == len(after)
