"""The independent-simulator benchmark's bookkeeping (benchmarks/diagnosis_independent.py): sets and scores."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import diagnosis_independent as di  # noqa: E402


def test_the_sets_are_disjoint_and_the_confirmation_set_has_the_issues_size():
    dev = {s for v in di.SETS["dev"].values() for s in v}
    confirm = {s for v in di.SETS["confirm"].values() for s in v}
    assert not dev & confirm
    per_scenario = len(di.WINDOWS) * len(di.LEVELS)
    assert len(di.SETS["confirm"]["clean"]) * per_scenario >= 60
    assert len(di.SETS["confirm"]["effect"]) * per_scenario >= 20


def test_every_confirmation_set_uses_seeds_no_other_set_uses_and_the_third_round_has_its_sizes():
    seeds = {name: {s for v in sets.values() for s in v} for name, sets in di.SETS.items()}
    for name in (n for n in di.SETS if n.startswith("confirm")):
        others = set().union(*(v for n, v in seeds.items() if n != name))
        assert not seeds[name] & others, name
    assert len(di.SETS["dev3"]["effect"]) >= 6 and len(di.SETS["dev3"]["clean"]) >= 10
    assert len(di.SETS["confirm3"]["effect"]) >= 4 and len(di.SETS["confirm3"]["clean"]) >= 10
    assert not seeds["dev3"] & (seeds["dev"] | seeds["confirm"] | seeds["confirm2"])


def test_jobs_are_seed_major_so_that_a_partial_run_covers_every_kind():
    jobs = di.jobs("confirm")
    first = jobs[: len(di.KINDS)]
    assert {k for k, _ in first} == set(di.KINDS) and {s for _, s in first} == {9001}
    assert sum(k == "clean" for k, _ in jobs) == len(di.SETS["confirm"]["clean"])


def _rec(kind: str, verdict: str, cause: str | None, level: int = 1) -> dict:
    return {"kind": kind, "expected": di.KINDS[kind].expected, "seed": 1, "window": [2.0, 12.0], "level": level,
            "verdict": verdict, "cause": cause, "cpu_s": 1.0}


def test_scores_count_wrong_names_ambiguous_and_unknown_verdicts_apart():
    recs = [
        _rec("second_motor", "explained", "second_motor"),
        _rec("second_motor", "explained", "inverter_der"),  # a wrong name
        _rec("double_cage", "ambiguous", None),  # a verdict of another branch
        _rec("double_cage", "explained", "double_cage_rotor"),  # a cause not in today's library
        _rec("clean", "consistent", None),
        _rec("clean", "explained", "measurement_skew"),  # a wrong name on a clean case
        _rec("noisy_load", "unexplained", None),
        _rec("thermostatic_cycling", "explained", "second_motor"),  # outside the library: never explained
        _rec("stator_resistance", "undecided", None),  # unknown verdict
    ]
    s = di.summarise(recs, known_causes=("second_motor", "measurement_skew"))
    assert s["wrong_named_rate"] == pytest.approx(3 / 9)
    assert s["clean_consistent"] == 0.5 and s["n_clean"] == 2
    assert s["outside_explained"] == 1 and s["n_outside"] == 2
    assert s["ambiguous"]["double_cage"] == 1 and s["unknown_verdicts"] == ["undecided"]
    assert s["right_named"][1]["share"] == pytest.approx(2 / 5)  # second_motor ×2, double_cage ×2, stator
    assert s["right_named_where_the_cause_is_a_candidate"][1] == 0.5  # only the second motors count
    assert s["confusion"]["double_cage"] == {"ambiguous": 1, "double_cage_rotor": 1}
    assert "double_cage_rotor" in di.markdown(s, "test")


def test_config_overrides_reach_the_diagnosis_and_a_wrong_name_is_a_clear_error():
    from benchmarks import diagnosis as selftest

    over = selftest.config_overrides(["cross_fit=false", "mirror_gap_s=0.5", "candidates=[\"second_motor\"]"])
    assert over == {"cross_fit": False, "mirror_gap_s": 0.5, "candidates": ["second_motor"]}
    selftest._init(over)
    try:
        cfg = selftest.diagnosis_config()
        assert (cfg.cross_fit, cfg.mirror_gap_s, cfg.alpha) == (False, 0.5, 0.01)
    finally:
        selftest._init(None)
    assert selftest.diagnosis_config().cross_fit is True
    for bad in ("crossfit=true", "cross_fit"):
        with pytest.raises(SystemExit, match="NAME=VALUE"):
            selftest.config_overrides([bad])


def test_the_self_test_samples_its_cases_at_the_rate_it_is_given():
    from benchmarks import diagnosis as selftest

    selftest._init(None, 25.0)
    try:
        base, ec, _, _ = selftest.case(("none", 2, 0))
        assert base.window.dt == pytest.approx(0.04) and ec.window.V.size == base.window.V.size == 250
    finally:
        selftest._init(None)
    base, _, _, _ = selftest.case(("none", 2, 0))
    assert base.window.V.size == 1000  # the cache of the 25 frames/s cases is not reused at 100


def test_a_window_at_a_lower_rate_is_every_step_th_sample_of_the_same_noisy_window():
    t = np.arange(0.0, 22.0 + 1e-9, 0.01)
    rng = np.random.default_rng(1)
    rec = {"t": t, "V": 1.0 + 0.01 * rng.standard_normal(t.size), "theta": 0.01 * rng.standard_normal(t.size),
           "P": 0.5 + 0.01 * rng.standard_normal(t.size), "Q": 0.2 + 0.01 * rng.standard_normal(t.size)}
    full, snr = di._window(rec, 2.0, 12.0, 2, True, "clean/1")
    quarter, snr4 = di._window(rec, 2.0, 12.0, 2, True, "clean/1", step=4)
    assert snr4 == snr and quarter.V.size == 251 and full.V.size == 1001
    for ch in ("t", "V", "theta", "P", "Q"):
        np.testing.assert_array_equal(getattr(quarter, ch), getattr(full, ch)[::4])


def test_the_pmu_rule_compares_the_measured_run_with_the_white_one():
    def summary(clean=60, wrong=2, right=(30, 30, 30)):
        return {"summary": {"input": {
            "clean_consistent": clean / 60, "n_clean": 60, "wrong_named": [None] * wrong, "n_cases": 300,
            "right_named": {lvl: {"share": r / 56, "n": 56} for lvl, r in zip((1, 2, 3), right, strict=True)}}}}

    def reader(**measured):
        runs = {"white": summary(), "pmu_fs5_measured": summary(**measured), "pmu_fs5_auto": summary(clean=0)}
        return lambda name: runs[name.split("confirm22_")[1]]

    assert di.pmu_verdict(reader())["met"] == {"clean": True, "wrong": True, "power": True}
    assert di.pmu_verdict(reader(clean=56))["met"]["clean"] is False
    assert di.pmu_verdict(reader(wrong=6))["met"]["wrong"] is False
    assert di.pmu_verdict(reader(right=(28, 27, 26)))["met"]["power"] is False
    assert di.pmu_verdict(reader(right=(28, 27, 27)))["met"]["power"] is True


def test_a_pmu_window_carries_the_input_modes_stds_through_the_filter_at_the_reporting_rate():
    """``--pmu fs5``: a clean record (a slow sine, nothing above 1 Hz) gets noise whose density in the passband is the
    white input mode's on every channel, drawn at the decimated rate, and whose band near Nyquist falls."""

    t = np.arange(0.0, 22.0 + 1e-9, 0.01)
    s = np.sin(2 * np.pi * 0.3 * t)
    rec = {"t": t, "V": 1.0 + 0.01 * s, "theta": 0.02 * s, "P": 0.5 + 0.05 * s, "Q": 0.2 + 0.02 * s}
    w, snr = di._window(rec, 2.0, 12.0, 2, True, "clean/1", step=2, pmu="fs5")
    assert w.V.size == 501 and np.allclose(np.diff(w.t), 0.02)
    clean = {k: rec[k][(t >= 2.0 - 1e-9) & (t <= 12.0 + 1e-9)][::2] for k in ("V", "theta", "P", "Q")}
    std = {"V": di.INPUT_NOISE["V"] * np.mean(clean["V"]), "theta": di.INPUT_NOISE["theta"],
           **{k: np.std(clean[k]) * 10 ** (-snr / 20) for k in ("P", "Q")}}
    fs = 50.0
    for k in ("V", "theta", "P", "Q"):
        f, p = signal.welch(getattr(w, k) - clean[k], fs, nperseg=250)
        white = 2 * std[k] ** 2 / fs
        assert 0.6 < np.mean(p[(f > 2) & (f < 8)]) / white < 1.5, k
        assert np.mean(p[f > 22]) < 0.1 * white, k
