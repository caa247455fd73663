"""``benchmarks.diagnosis_band_noise``: the clean self-test case that ``exact_inputs_quiet`` turns ``unexplained`` at
25 frames/s carries, in its band tests, the injected noise's own draw."""

from __future__ import annotations

import numpy as np


def test_the_quiet_options_false_finding_is_the_noise_draws():
    from benchmarks.diagnosis_band_noise import main

    rows = {(r["quiet"], r["channel"]): r for r in main(["--cases", "none_user/2/1", "--fs", "25"])}
    assert rows[(False, "P")]["verdict"] == "consistent"
    assert rows[(True, "P")]["verdict"] == "unexplained" and rows[(True, "P")]["located"] == ["P"]
    for ch in ("P", "Q"):
        got = np.array(rows[(True, ch)]["ratio"])
        alone = np.array(rows[(True, ch)]["noise_alone_ratio"])
        assert np.all(np.abs(got / alone - 1.0) < 0.15), (ch, got, alone)
    # The noise alone, against its own floor, is 2–4 × that floor from 0.5 to 5 Hz in P.
    assert min(rows[(True, "P")]["noise_alone_ratio"][1:]) > 2.0
