"""The gated estimator's confirmation counts (``benchmarks.own_gate.confirm_row``) on a hand-made run."""

from benchmarks.own_gate import confirm_row


def test_confirm_row_counts_the_flag_target_and_the_good_windows_it_flags():
    off_iv, good_iv, good_iv_other, off_oe = [0.3, 0, 0, 0], [0.05, 0, 0, 0], [0.1, 0, 0, 0], [0.4, 0, 0, 0]
    run = {"ratio": 0.5, "shape": "lowpass",
           "errors": {"gated": [off_iv, good_iv, good_iv_other, off_oe, good_iv],
                      "output error": [[0.2, 0, 0, 0]] * 4 + [[0.1, 0, 0, 0]]},
           "quality": {"gated": [{"gated_ar_iv": 1.0}] * 4 + [{"gated_ar_iv": 0.0}]},
           "flags": {"gated": [["iv_error_may_exceed_20pct"], ["static_split_unidentifiable", "iv_error_may_exceed_20pct"],
                               ["uncertain:a", "iv_error_may_exceed_20pct"], [], []]}}
    row, c = confirm_row(run, "lowpass, none")
    assert c["to_iv"] == 4 and row[2] == "4 / 5"
    # Windows 1 and 4 are off by more than 20 %: window 4 (no flag) is the unflagged one.
    assert (c["off"], c["off_unflagged"]) == (2, 1) and row[6] == "2 (1)"
    # IV windows within 20 %: 2 and 3, both carry the flag, window 2 only it (static_split_unidentifiable is
    # no warning), window 3 also uncertain:a.
    assert (c["iv_within"], c["iv_within_flagged"], c["iv_within_flagged_only_by_it"]) == (2, 2, 1)
    assert c["median_gated"][0] == 0.1 and c["median_output_error"][0] == 0.2
