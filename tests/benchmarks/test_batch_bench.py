"""The batch benchmarks (benchmarks/batch_ab.py, benchmarks/batch_profile.py) on a few windows."""

from __future__ import annotations

import sys
from pathlib import Path

from aslm_core import IdentifyConfig, optimize

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import batch_ab, batch_profile, common  # noqa: E402
from benchmarks.speed import SEED  # noqa: E402


def test_pools_mode_times_every_pool_each_repetition():
    out = batch_ab.batch_times(6, 2, mode="pools")
    assert list(out) == list(batch_ab.POOLS)
    for r in out.values():
        assert len(r["wall"]) == len(r["cpu"]) == 2
        assert all(t > 0.0 for t in r["wall"] + r["cpu"])


def test_kernel_timers_count_the_optimiser_and_are_removed_after():
    windows = [c.window for c in common.cases(2, level=1, seed=SEED, input_noise=False)]
    kernel = optimize.lm_kernel
    wall, acc = batch_profile.kernel_times(windows, IdentifyConfig())
    assert optimize.lm_kernel is kernel
    seconds, calls = acc["optimize.lm_kernel"]
    assert calls >= 2 * 3 and 0.0 < seconds < wall  # at least one descent per start and window
