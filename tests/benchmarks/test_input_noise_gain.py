"""The verdict of stop 49's rule from per-window records (benchmarks.input_noise_gain)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import input_noise_gain as ig  # noqa: E402

CLASSES = ("0.03 % / 3e-4 rad", "0.1 % / 1e-3 rad")


def _rows(shift: dict, spread: float = 0.05, n: int = 400, far: int = 0, seed: int = 0) -> tuple[dict, dict]:
    """Per-window D/D_real of rows ``gain49`` (the candidate) and ``default`` at DL 1–3 and both classes: each row's
    windows centred on 1 + shift[row] (exactly: the draws are centred), ``far`` windows of the candidate at 0.1 % moved
    30 % off."""
    rng = np.random.default_rng(seed)
    per, per_se = {}, {}
    for level in (1, 2, 3):
        for cls in CLASSES:
            base = rng.standard_normal((n, 4))
            base = (base - base.mean(axis=0)) / base.std(axis=0, ddof=1)
            for row in ("gain49", "default"):
                r = 1.0 + shift[row] + spread * base
                if row == "gain49" and cls.startswith("0.1") and far:
                    r[:far, 0] = 1.3 + shift[row]
                per[f"{level}|{cls}|{row}"] = r.tolist()
                per_se[f"{level}|{cls}|{row}"] = np.full((n, 4), spread).tolist()
    return per, per_se


def _verdict(shift: dict, **kw) -> dict:
    per, per_se = _rows(shift, **kw)
    candidate, default = ig.rows_of(per)
    cells = {"candidate": ig.cells(per, per_se, candidate), "default": ig.cells(per, per_se, default)}
    return ig.verdict({25.0: cells, 100.0: cells}, ig.RULES["gain49"])


def test_the_rows_of_a_run_and_of_the_runs_of_record():
    per, _ = _rows({"gain49": 0.0, "default": 0.0}, n=5)
    assert ig.rows_of(per) == ("gain49", "default")
    record = {k.replace("|default", "|before49").replace("|gain49", "|default"): v for k, v in per.items()}
    assert ig.rows_of(record) == ("default", "before49")


def test_cells_give_the_mean_spread_coverage_and_far_off_windows_of_each_row():
    per, per_se = _rows({"gain49": 0.0, "default": 0.015}, far=3)
    c = ig.cells(per, per_se, "default")["2|0.1 % / 1e-3 rad"]
    assert np.allclose(c["mu"], 1.015) and np.allclose(c["sigma"], 0.05) and c["n"] == 400 and c["off_20pct"] == 0
    d = ig.cells(per, per_se, "gain49")["2|0.1 % / 1e-3 rad"]
    assert d["off_20pct"] == 3
    assert all(0.92 < x < 0.98 for x in d["coverage"])  # ±1.96 SE with the SE the spread


def test_the_rule_is_met_when_the_candidate_is_inside_the_target_and_the_default_was_not():
    v = _verdict({"gain49": 0.0, "default": 0.015})  # 0.015 is outside 0.01 at 0.03 %, inside 0.02 at 0.1 %
    assert all(x["met"] for x in v.values())
    assert v["2 cells outside the target over DL 1-3, at most the default's"]["default"] == 2 * 3 * 4
    assert v["1 bias inside the target at DL 2-3"]["outside"] == 0


def test_each_criterion_fails_on_its_own_failure():
    v = _verdict({"gain49": 0.012, "default": 0.0})  # outside at 0.03 %: DL 2-3 on both rates
    assert not v["1 bias inside the target at DL 2-3"]["met"]
    assert v["1 bias inside the target at DL 2-3"]["outside"] == 2 * 2 * 4
    assert not v["2 cells outside the target over DL 1-3, at most the default's"]["met"]
    far = _verdict({"gain49": 0.0, "default": 0.0}, far=20)  # 20 of 400 windows 30 % off in every 0.1 % cell
    assert not far["5 off by more than 20 % at 0.1 %"]["met"]
    assert far["5 off by more than 20 % at 0.1 %"]["default"] == 0
    assert not far["3 sigma over the default's"]["met"]  # a's spread grows with them


def test_the_rules_thresholds_decide():
    """The same figures meet one rule's σ threshold and not a stricter one's."""
    per, per_se = _rows({"gain49": 0.0, "default": 0.0})
    wide = {k: ((np.array(v) - 1.0) * (1.02 if k.endswith("|gain49") else 1.0) + 1.0).tolist() for k, v in per.items()}
    cells = {"candidate": ig.cells(wide, per_se, "gain49"), "default": ig.cells(wide, per_se, "default")}
    assert ig.verdict({100.0: cells}, ig.RULES["gain49"])["3 sigma over the default's"]["met"]  # 1.02 <= 1.03
    assert not ig.verdict({100.0: cells}, ig.RULES["cap4"])["3 sigma over the default's"]["met"]  # 1.02 > 1.01
    assert ig.rows_of(per, "cap4") == ("cap4", "default")


def test_without_the_bias_gate_criterion_1_compares_the_dl_2_3_cells_with_the_defaults():
    """``spline50``'s rule: a candidate outside the target where the default is too meets criterion 1; one outside
    where the default is not does not."""
    per, per_se = _rows({"gain49": 0.012, "default": 0.012})
    cells = {"candidate": ig.cells(per, per_se, "gain49"), "default": ig.cells(per, per_se, "default")}
    v = ig.verdict({25.0: cells}, ig.RULES["spline50"])
    assert v["1 bias inside the target at DL 2-3"]["outside"] == 2 * 4 and v["1 bias inside the target at DL 2-3"]["met"]
    assert not ig.verdict({25.0: cells}, ig.RULES["gain49"])["1 bias inside the target at DL 2-3"]["met"]
    per, per_se = _rows({"gain49": 0.012, "default": 0.0})
    cells = {"candidate": ig.cells(per, per_se, "gain49"), "default": ig.cells(per, per_se, "default")}
    assert not ig.verdict({25.0: cells}, ig.RULES["spline50"])["1 bias inside the target at DL 2-3"]["met"]


def test_the_exact_input_check_fails_on_a_growth_over_a_tenth_of_a_point_or_a_25_frames_sum_that_does_not_fall():
    def run(lag: list, spl: list, fs: str = "25") -> dict:
        return {"cells": {f"{fs}|DL 2": {"bias_lagrange": lag, "bias_spline": spl}}}

    assert ig.exact_check(run([0.006, 0.0, 0.007, -0.007], [0.001, 0.0009, 0.0, -0.001]))["met"]
    assert not ig.exact_check(run([0.006, 0.0, 0.007, -0.007], [0.001, 0.0011, 0.0, -0.001]))["met"]  # b grew 0.11
    rose = ([0.001, 0.0, 0.0, 0.0], [0.0005, 0.0, 0.0, 0.0009])  # no growth over 0.1 point, the sum 0.10 -> 0.14 %
    assert not ig.exact_check(run(*rose))["met"]
    assert ig.exact_check(run(*rose, fs="100"))["met"]  # the sum is not checked from 50 frames/s up
