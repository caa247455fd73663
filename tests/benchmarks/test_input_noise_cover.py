"""benchmarks.input_noise_cover: the coverage verdicts, and runs on several seeds pooled per cell."""

from __future__ import annotations

import pytest

from benchmarks import input_noise_cover as cover

PARAMS = ("a", "b", "H2", "Tm")


def _run(cov_tm: float, n: int, sigma_tm: float, level: str = "2") -> dict:
    stats = {"n": n, "coverage_95": {p: 0.95 if p != "Tm" else cov_tm for p in PARAMS},
             "sigma": {p: 0.05 if p != "Tm" else sigma_tm for p in PARAMS}}
    return {"levels": {level: {"0.1 % / 1e-3 rad": {"default": stats}}}}


def test_pooling_counts_every_runs_windows_once():
    runs = [cover.cells(_run(0.89, 300, 0.08)), cover.cells(_run(0.92, 100, 0.06))]
    [(label, cls, st)] = cover.pooled(runs)
    assert (label, cls, st["n"]) == ("DL 2", "0.1 % / 1e-3 rad", 400)
    assert st["coverage_95"]["Tm"] == pytest.approx((267 + 92) / 400)
    assert st["coverage_95"]["a"] == pytest.approx(0.95)
    assert st["sigma"]["Tm"] == pytest.approx(((299 * 0.08**2 + 99 * 0.06**2) / 398) ** 0.5)


def test_runs_of_other_cells_are_not_pooled():
    with pytest.raises(ValueError, match="cells"):
        cover.pooled([cover.cells(_run(0.9, 300, 0.08)), cover.cells(_run(0.9, 300, 0.08, level="3"))])
