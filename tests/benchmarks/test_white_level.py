"""benchmarks/white_level.py: stop 57's rule judges the runs it names, and each criterion fails on its own count."""

from __future__ import annotations

import copy

import numpy as np

from benchmarks import white_level as wl
from benchmarks.input_noise_gain import RATES, run_name


def andes_runs(cover=0.94, sigma=0.05, bias=0.005) -> dict:
    cells = [{"class": c, "fs": fs, "cover": [cover] * 4, "sigma": [sigma] * 4, "bias": [bias] * 4}
             for c in ("exact", "pmu003", "pmu01") for fs in (100.0, 50.0, 25.0)]
    return {"cells": cells}


def generator_run(scale: float, rng: np.random.Generator) -> dict:
    """A run with every noisy cell's D/D_real drawn at σ 0.02 × ``scale`` and SEs of 0.02 (coverage ~95 %)."""
    per, per_se = {}, {}
    for level in "123":
        for cls in ("0.03 % / 3e-4 rad", "0.1 % / 1e-3 rad"):
            per[f"{level}|{cls}|default"] = (1.0 + 0.02 * scale * rng.standard_normal((300, 4))).tolist()
            per_se[f"{level}|{cls}|default"] = np.full((300, 4), 0.02).tolist()
    return {"per_window": per, "per_window_se": per_se}


def store(andes_new, andes_old, gen_new, gen_old, second=False):
    at, ab, gt, gb, seed = wl.tags(second)
    runs = {f"andes_rates_{at}": andes_new, f"andes_rates_{ab}": andes_old}
    for fs in RATES:
        runs[run_name(seed, gt, fs)], runs[run_name(seed, gb, fs)] = gen_new[fs], gen_old[fs]
    return runs.__getitem__


def test_the_rule_is_met_by_equal_runs_and_each_criterion_fails_on_its_own():
    rng = np.random.default_rng(0)
    gen = {fs: generator_run(1.0, rng) for fs in RATES}
    read = store(andes_runs(), andes_runs(), gen, gen)
    assert all(wl.andes_verdict(read)["met"].values())
    assert all(wl.generator_verdict(read)["met"].values())
    # (A1): one cell outside 90-97 %; (A2): σ 5 % above the before's; (A3): |bias| 0.6 points above.
    bad = andes_runs()
    bad["cells"][3]["cover"][2] = 0.975
    assert wl.andes_verdict(store(bad, andes_runs(), gen, gen))["met"] == {"A1": False, "A2": True, "A3": True}
    assert not wl.andes_verdict(store(andes_runs(sigma=0.0525), andes_runs(), gen, gen))["met"]["A2"]
    assert not wl.andes_verdict(store(andes_runs(bias=0.0111), andes_runs(bias=0.005), gen, gen))["met"]["A3"]
    # The exact rows are not judged.
    exact = andes_runs()
    exact["cells"][0]["cover"] = [0.5] * 4
    assert all(wl.andes_verdict(store(exact, andes_runs(), gen, gen))["met"].values())
    # (B2): every σ 5 % above the before's; (B1): SEs a third of the spread in three cells.
    wide = {fs: generator_run(1.05, np.random.default_rng(0)) for fs in RATES}
    assert not wl.generator_verdict(store(andes_runs(), andes_runs(), wide, gen))["met"]["B2"]
    narrow = copy.deepcopy(gen)
    for fs in RATES[:3]:
        narrow[fs]["per_window_se"]["2|0.1 % / 1e-3 rad|default"] = np.full((300, 4), 0.007).tolist()
    v = wl.generator_verdict(store(andes_runs(), andes_runs(), narrow, gen))
    assert v["coverage_outside"][0] >= v["coverage_outside"][1] + 3 and not v["met"]["B1"]
    # (B3): a DL 3 cell's mean moved 3 % off at 0.1 % (target 2 %).
    off = copy.deepcopy(gen)
    off[25.0]["per_window"]["3|0.1 % / 1e-3 rad|default"] = (np.array(off[25.0]["per_window"][
        "3|0.1 % / 1e-3 rad|default"]) + 0.03).tolist()
    assert not wl.generator_verdict(store(andes_runs(), andes_runs(), off, gen))["met"]["B3"]


def test_the_second_confirmation_reads_its_own_runs():
    rng = np.random.default_rng(1)
    gen = {fs: generator_run(1.0, rng) for fs in RATES}
    read = store(andes_runs(), andes_runs(), gen, gen, second=True)
    assert all(wl.andes_verdict(read, second=True)["met"].values())
    assert all(wl.generator_verdict(read, second=True)["met"].values())
    assert wl.tags(True)[4] == wl.SEED_SECOND != wl.SEED
