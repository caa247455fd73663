"""benchmarks/andes_history.py: the history's windows, their noise, and the cells' statistics (no ANDES run)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from aslm_sim import make_cases  # noqa: E402
from benchmarks import andes_history as ah  # noqa: E402


@pytest.fixture(scope="module")
def record():
    """A 72 s clean record of the project's generator at 60 Hz nominal, shaped as ``scenario_record``'s."""
    c = make_cases(1, seed=5, level=None, duration_s=ah.TF + 0.01, input_noise=False, f0=60.0)[0]
    w = c.clean
    return {"t": w.t - w.t[0], "V": w.V, "theta": w.theta, "P": w.P, "Q": w.Q}, c.truth.d


def test_each_of_the_seven_windows_gets_its_own_noise_and_the_history_is_the_minute_before(record):
    rec, _ = record
    target, hist = ah.draw(rec, 22.0, "pmu01", [1, 220, 1, 0])
    np.testing.assert_allclose([(h.t[0], h.t[-1]) for h in hist], ah.HISTORY, atol=1e-6)
    np.testing.assert_allclose((target.t[0], target.t[-1]), ah.TARGET, atol=1e-6)
    clean = ah.noisy_window(rec, *ah.TARGET, None, None)
    dv = target.V - clean.V
    assert 0.5e-3 < np.std(dv) / np.mean(clean.V) < 1.5e-3  # the class's 0.1 % on V
    assert np.std(target.P - clean.P) > 0.0
    noise = [h.V - ah.noisy_window(rec, *span, None, None).V for h, span in zip(hist, ah.HISTORY, strict=True)]
    assert abs(np.corrcoef(noise[0], noise[1])[0, 1]) < 0.2 and abs(np.corrcoef(noise[-1], dv)[0, 1]) < 0.2
    again, _ = ah.draw(rec, 22.0, "pmu01", [1, 220, 1, 1])
    assert not np.allclose(again.V, target.V)


def test_the_run_identifies_the_window_alone_and_with_its_six_windows(record, monkeypatch):
    rec, truth = record
    monkeypatch.setattr(ah, "scenario_record", lambda *a, **k: (rec, {"truth": np.asarray(truth)}))
    out = ah.run("model", [1], [28.0], 2, 0.01, 0.15)
    assert len(out["rows"]) == 4  # two classes × two draws
    for r in out["rows"]:
        assert r["alone"]["windows"] == 0 and r["history"]["windows"] == 6
        assert r["alone"]["d"] != r["history"]["d"]
    res = ah.cells(out)
    assert [(c["snr_db"], c["class"]) for c in res] == [(28.0, "pmu003"), (28.0, "pmu01")]
    c = res[1]
    ratio = np.array([r["history"]["d"] for r in out["rows"] if r["class"] == "pmu01"]) / np.asarray(truth)
    np.testing.assert_allclose(c["history"]["sigma"], ratio.std(axis=0, ddof=1))
    np.testing.assert_allclose(c["sigma_ratio"], np.array(c["history"]["sigma"]) / np.array(c["alone"]["sigma"]))
