"""benchmarks.diagnosis_rates: one job's row, and the tally per rate and level."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import diagnosis_rates as dr  # noqa: E402


def test_a_job_diagnoses_the_window_of_its_rate_and_compares_the_plain_model_with_the_truth():
    row = dr.diagnosed((30.0, 3, 0, 5, False, None, {}))
    assert row["fs"] == 30.0 and row["level"] == 3 and row["verdict"] in {"consistent", "explained", "ambiguous",
                                                                             "unexplained"}
    assert len(row["d_ratio"]) == 4 and max(abs(x - 1.0) for x in row["d_ratio"]) < 0.2


def test_the_tally_counts_verdicts_causes_and_the_named_effect_per_cell():
    rows = [{"fs": 25.0, "level": 2, "verdict": "explained", "cause": "second_motor", "d_ratio": [1.1, 1, 1, 1]},
            {"fs": 25.0, "level": 2, "verdict": "consistent", "cause": None, "d_ratio": [0.9, 1, 1, 1]},
            {"fs": 25.0, "level": 2, "verdict": "explained", "cause": "measurement_skew", "d_ratio": [1.0, 1, 1, 1.2]},
            {"fs": 100.0, "level": 2, "verdict": "consistent", "cause": None, "d_ratio": [1, 1, 1, 1]}]
    cells = dr.summary(rows, "second_motor")
    assert [(c["fs"], c["n"]) for c in cells] == [(25.0, 3), (100.0, 1)]
    c = cells[0]
    assert c["verdicts"] == {"explained": 2, "consistent": 1}
    assert c["causes"] == {"second_motor": 1, "measurement_skew": 1}
    assert c["named_effect"] == 1
    np.testing.assert_allclose(c["median_abs_error"], [0.1, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(c["max_abs_error"], [0.1, 0, 0, 0.2], atol=1e-12)
