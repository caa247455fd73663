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


def _stand_in_record() -> dict:
    """A 72 s record in ANDES's form (t, V, θ, P, Q at 100 Hz) from the project's generator: the ``--andes --pmu``
    path's protocol is tested without an ANDES run (its runs of record are in docs/results)."""
    from aslm_sim import make_cases

    c = make_cases(1, level=3, seed=5, duration_s=72.0, fs=100.0, input_noise=False)[0].clean
    return {"t": c.t - c.t[0], "V": c.V, "theta": c.theta, "P": c.P, "Q": c.Q}


def test_the_andes_pmu_job_puts_a_pmus_noise_on_every_channel_at_its_rate(monkeypatch):
    """``andes_diagnosed`` with (shape, class): the window at the rate (every fourth sample at 25 frames/s), every
    channel's noise a PMU's of that shape drawn after the decimation (V at the class × its mean, θ at the class in rad,
    P and Q at 22 dB), the same draw for the same job; without a PMU, P and Q noisy and V, θ as simulated."""
    rec = _stand_in_record()
    monkeypatch.setattr(dr, "andes_record", lambda seed: (rec, np.ones(4)))
    seen = []
    monkeypatch.setattr(dr, "_row", lambda window, model, truth, config, **key: seen.append(window) or key)
    from benchmarks.andes_crosscheck import noisy_window
    from benchmarks.andes_rates import WINDOWS, decimated

    base = decimated(noisy_window(rec, *WINDOWS[2], None, None), 4)
    key = dr.andes_diagnosed((31, 2, 25.0, 22.0, {}, ("white", 1e-3)))
    assert key == {"fs": 25.0, "level": "andes 22 dB", "i": 3102}
    w = seen[-1]
    np.testing.assert_array_equal(w.t, base.t)
    assert 0.85e-3 < np.std(w.V - base.V) / np.mean(base.V) < 1.15e-3
    assert 0.85e-3 < np.std(w.theta - base.theta) < 1.15e-3
    for x, x0 in ((w.P, base.P), (w.Q, base.Q)):
        assert 0.85 < np.std(x - x0) / (np.std(x0) * 10 ** (-22 / 20)) < 1.15
    dr.andes_diagnosed((31, 2, 25.0, 22.0, {}, ("white", 1e-3)))
    np.testing.assert_array_equal(seen[-1].V, w.V)  # the same draw for the same job
    # fs5: the noise falls above a fifth of the rate, so its total std is below the class's.
    dr.andes_diagnosed((31, 2, 25.0, 22.0, {}, ("fs5", 1e-3)))
    assert np.std(seen[-1].theta - base.theta) < 0.9e-3
    # Without a PMU: V and θ exact, P and Q at 22 dB.
    dr.andes_diagnosed((31, 2, 25.0, 22.0, {}))
    np.testing.assert_array_equal(seen[-1].V, base.V)
    assert 0.8 < np.std(seen[-1].P - base.P) / (np.std(base.P) * 10 ** (-22 / 20)) < 1.2


def test_the_andes_pmu_rule_counts_false_findings_per_class():
    def run(n, consistent):
        return {"cells": [{"n": n, "verdicts": {"consistent": consistent, "unexplained": n - consistent}}]}

    stored = {f"diagnosis_rates_andes_pmu_{k}_{c}_x": run(210, 210 - f) for c in ("1e-3", "3e-4")
              for k, f in (("white_auto", 1), ("fs5_measured", 4), ("fs5_auto", 210))}
    v = dr.andes_pmu_verdict(stored.__getitem__, "_x")
    assert v["met"] and v["classes"]["1e-3"]["fs5_measured"]["false_findings"] == 4
    stored["diagnosis_rates_andes_pmu_fs5_measured_3e-4_x"] = run(210, 205)
    assert not dr.andes_pmu_verdict(stored.__getitem__, "_x")["met"]  # 5 > 1 + 3
