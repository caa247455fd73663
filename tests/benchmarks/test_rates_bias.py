"""benchmarks.rates_bias: pooled default rows and the met / open / missed call of each cell."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import rates_bias as rb  # noqa: E402


def test_a_cell_is_met_open_or_missed_by_its_95_percent_interval():
    assert rb.call(0.015, 0.002, 0.02) == "met"  # [1.11, 1.89] %
    assert rb.call(0.015, 0.004, 0.02) == "open"  # reaches 2.28 %
    assert rb.call(-0.03, 0.004, 0.02) == "missed"  # [-3.78, -2.22] %
    assert rb.call(0.0, 0.02, 0.02) == "open"  # wide on both sides


def test_the_runs_default_rows_are_pooled_window_by_window():
    rng = np.random.default_rng(0)
    a, b = 1.0 + 0.01 * rng.standard_normal((300, 4)), 1.02 + 0.01 * rng.standard_normal((200, 4))
    b[0, 1] = np.nan  # a refused window is left out
    runs = [{"per_window": {"2|0.1 % / 1e-3 rad|default": a.tolist(), "2|0.1 % / 1e-3 rad|other": a.tolist()}},
            {"per_window": {"2|0.1 % / 1e-3 rad|default": b.tolist(), "2|0.1 % / 1e-3 rad|other": a.tolist()}}]
    c = rb.pooled_cells(runs)
    assert list(c) == ["2|0.1 % / 1e-3 rad"] and c["2|0.1 % / 1e-3 rad"]["n"] == 499
    both = np.concatenate([a, b[1:]])
    np.testing.assert_allclose(c["2|0.1 % / 1e-3 rad"]["bias"], both.mean(axis=0) - 1.0)
    np.testing.assert_allclose(c["2|0.1 % / 1e-3 rad"]["se"], both.std(axis=0, ddof=1) / np.sqrt(499))


def _cells(bias_a: float, se_a: float, level: str = "2") -> dict:
    cls = "0.03 % / 3e-4 rad"
    c = {"n": 1800, "bias": [bias_a, 0.0, 0.0, 0.0], "se": [se_a, 0.001, 0.001, 0.001]}
    c["calls"] = [rb.call(b, s, rb.BIAS_TARGET[cls]) for b, s in zip(c["bias"], c["se"], strict=True)]
    return {"25": {f"{level}|{cls}": c}}


def test_the_confirmation_rule_needs_every_point_inside_and_no_cell_missed():
    met, notes = rb.verdict(_cells(0.004, 0.0015))
    assert met and notes == []
    met, notes = rb.verdict(_cells(0.008, 0.0015))  # inside, its interval reaching 1.09 %: open, reported
    assert met and len(notes) == 1 and "(open)" in notes[0]
    met, notes = rb.verdict(_cells(0.0105, 0.004))  # open, but the point estimate is outside
    assert not met and "point estimate outside" in notes[0]
    met, _ = rb.verdict(_cells(-0.02, 0.002))  # missed
    assert not met
    met, notes = rb.verdict(_cells(0.05, 0.002, level="1"))  # DL 1 is stated, not judged
    assert met and notes == []


def test_the_coverage_half_of_the_rule_reads_each_cells_share():
    c = _cells(0.0, 0.001)
    c["25"]["2|0.03 % / 3e-4 rad"]["coverage_95"] = [0.95, 0.90, 0.97, 0.93]
    assert rb.coverage_verdict(c) == (True, [])
    c["25"]["2|0.03 % / 3e-4 rad"]["coverage_95"] = [0.95, 0.899, 0.975, 0.93]
    met, notes = rb.coverage_verdict(c)
    assert not met and len(notes) == 2 and " b: 89.9 %" in notes[0]


def test_pooled_coverage_counts_windows_within_196_se():
    r = np.array([[1.0, 1.0, 1.0, 1.0], [1.1, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, np.nan]])
    e = np.full((3, 4), 0.05)
    runs = [{"per_window": {"2|c|default": r.tolist()}, "per_window_se": {"2|c|default": e.tolist()}}]
    c = rb.pooled_cells(runs)["2|c"]
    assert c["n"] == 2 and c["coverage_95"] == [0.5, 1.0, 1.0, 1.0]
