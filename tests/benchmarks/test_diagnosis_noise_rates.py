"""``benchmarks.diagnosis_noise_rates`` on ANDES's cached development record: at 25 frames/s the default takes the
exact inputs' own content as noise, the option does not."""

from __future__ import annotations


def test_the_default_inflates_p_floor_at_25_frames_per_second_and_the_option_does_not():
    from benchmarks.diagnosis_noise_rates import main

    default = {(r["level"], r["fs"]): r for r in main([])}
    quiet = {(r["level"], r["fs"]): r for r in main(["--quiet"])}
    assert default[(3, 25)]["p_floor_over_injected"] > 3.0 > default[(3, 100)]["p_floor_over_injected"]
    assert quiet[(3, 25)]["sigma_v"] == 0.0 and quiet[(3, 25)]["p_floor_over_injected"] < 2.0
