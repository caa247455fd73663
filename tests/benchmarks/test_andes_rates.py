"""benchmarks/andes_rates.py: the decimated windows, the same noise values at every rate, the paired shift (no ANDES run)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from aslm_sim import make_cases  # noqa: E402
from benchmarks import andes_rates as ar  # noqa: E402


@pytest.fixture(scope="module")
def window():
    """A 10 s clean window of the project's generator at 100 frames/s."""
    return make_cases(1, seed=5, level=None, input_noise=False, f0=60.0)[0].clean


def test_a_decimated_window_reports_at_the_lower_rate_with_the_same_values_at_its_instants(window):
    for fs, step in ar.STEPS.items():
        w = ar.decimated(window, step)
        assert np.median(np.diff(w.t)) == pytest.approx(1.0 / fs)
        for name in ("t", "V", "theta", "P", "Q"):
            assert np.array_equal(getattr(w, name), getattr(window, name)[::step])
        assert w.f0 == window.f0 and w.bus == window.bus


def test_the_cells_pair_each_answer_with_the_same_draw_at_100_frames_s():
    """Rows built so that 50 frames/s is 100's answer plus 0.01 in a (and noise): the paired shift finds +0.01 with a
    small SE; bias and far-off counts are the rows'; a refused answer is counted, not used."""
    rng = np.random.default_rng(0)
    truth = [60.0, 5.0, 1.0, 2.0]
    rows = []
    for k in range(200):
        base = np.array(truth) * (1.0 + 0.05 * rng.standard_normal(4))
        for cls in ar.CLASSES:
            for fs in ar.STEPS:
                d = base * (1.0 + np.array([0.01, 0.0, 0.0, 0.0]) * (fs == 50.0) + 1e-4 * rng.standard_normal(4))
                rows.append({"seed": 1, "window": 0, "draw": k, "class": cls, "fs": fs, "d": d.tolist(),
                             "stderr": (0.05 * np.array(truth)).tolist(), "flags": []})
    rows.append({"seed": 1, "window": 0, "draw": 999, "class": "pmu01", "fs": 25.0, "error": "refused"})
    res = {(c["class"], c["fs"]): c for c in ar.cells(rows, {1: truth})}
    c50 = res["pmu01", 50.0]
    assert c50["shift_vs_100"][0] == pytest.approx(0.01, abs=1e-3) and c50["shift_se"][0] < 1e-3
    assert abs(c50["shift_vs_100"][1]) < 1e-3
    assert res["pmu01", 25.0]["refused"] == 1 and res["pmu01", 25.0]["n"] == 200
    assert res["exact", 100.0]["shift_vs_100"] == [0.0] * 4
    assert 0.85 < res["exact", 100.0]["cover"][0] < 1.0


def _cover_rows(seeds, sd_over_se: float, rng) -> list[dict]:
    """Rows of every noisy class and rate whose errors are sd_over_se × their SE in std (coverage of ±1.96 SE:
    95 % at 1, about 73 % at 1.4), ten draws of each of seven windows per seed."""
    truth = np.array([60.0, 5.0, 1.0, 2.0])
    rows = []
    for seed in seeds:
        for j in range(7):
            for k in range(10):
                for cls in ar.CLASSES:
                    for fs in ar.STEPS:
                        d = truth * (1.0 + 0.05 * sd_over_se * rng.standard_normal(4))
                        rows.append({"seed": seed, "window": j, "draw": k, "class": cls, "fs": fs, "d": d.tolist(),
                                     "stderr": (0.05 * truth).tolist(), "flags": []})
    return rows


def test_the_coverage_check_passes_honest_errors_and_fails_a_run_whose_se_is_too_small():
    """Honest SEs meet the rule, 95 % inside all but a few of the 48 intervals; the fresh run with errors 1.4 × the SE fails it in every
    cell (the pooled intervals still cover the stored runs' rows)."""
    rng = np.random.default_rng(3)
    truths = {str(s): [60.0, 5.0, 1.0, 2.0] for s in range(100)}

    def runs(fresh_sd):
        out = {f"andes_rates_{t}": {"rows": _cover_rows(range(10 * i, 10 * i + 10), 1.0, rng), "truths": truths}
               for i, t in enumerate(ar.COVERAGE_POOL[:-1])}
        out["andes_rates_cover58"] = {"rows": _cover_rows(range(90, 100), fresh_sd, rng), "truths": truths}
        return out

    ok = ar.coverage_check(read=runs(1.0).__getitem__)
    assert ok["met"] and not ok["misses"] and len(ok["cells"]) == 6
    outside = sum(not lo < 0.95 < hi for c in ok["cells"] + ok["pooled"] for lo, hi in zip(c["lo"], c["hi"], strict=True))
    assert outside <= 6
    assert ok["pooled"][0]["n"] == 4 * 700 and ok["pooled"][0]["clusters"] == 4 * 70
    assert all(0.9 < x < 1.1 for c in ok["pooled"] for x in c["z_spread"])
    bad = ar.coverage_check(read=runs(1.4).__getitem__)
    assert not bad["met"] and len(bad["misses"]) == 24
    assert all(hi < 0.90 for c in bad["cells"] for hi in c["hi"])
    assert all(1.2 < x < 1.6 for c in bad["cells"] for x in c["z_spread"])


def test_intervals_prints_a_stored_runs_coverage_with_its_bootstrap_intervals(monkeypatch, capsys):
    """``--intervals TAG`` reads the stored run and gives each noisy cell's coverage and interval; SEs 1.4 × too small
    cover about 73 %, their intervals below 90 %."""
    rng = np.random.default_rng(5)
    doc = {"rows": _cover_rows(range(10), 1.4, rng), "truths": {str(s): [60.0, 5.0, 1.0, 2.0] for s in range(10)}}
    monkeypatch.setattr(ar.common, "read_json", {"andes_rates_somerun": doc}.__getitem__)
    out = ar.main(["--intervals", "somerun"])
    assert len(out["cells"]) == 6 and all(c["n"] == 700 for c in out["cells"])
    assert all(hi < 0.90 for c in out["cells"] for hi in c["hi"])
    assert "pmu01 50 frames/s (n 700, 70 windows)" in capsys.readouterr().out
