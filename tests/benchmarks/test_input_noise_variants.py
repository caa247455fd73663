"""benchmarks/input_noise_variants.py (stop 44): the variants reach the refinement and leave aslm_core as it was."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from aslm_core import identify, input_history, input_weighting, motor, noise, preprocess  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks import input_noise_variants as iv  # noqa: E402
from benchmarks.input_noise_bound import INPUT_NOISE, TAIL, with_input_noise  # noqa: E402


def test_each_variant_changes_the_answer_and_the_core_is_restored_afterwards():
    per, per_se, _ = iv.run(1, 41, ["pq", "wpl", "widths"])
    assert set(per_se) == set(per)
    assert input_weighting.weighted_fit is iv._WEIGHTED_FIT and noise.wiener_smooth is iv._WIENER_SMOOTH
    key = "2|0.1 % / 1e-3 rad|"
    d = np.array(per[key + "default"])
    for name in ("pq", "wpl", "widths_median", "widths_medoid"):
        v = np.array(per[key + name])
        assert v.shape == d.shape and np.all(np.isfinite(v))
    # A spectrum handed in moves the refinement's answer: the seam is reached.
    assert not np.allclose(np.array(per[key + "pq"]), d, rtol=0, atol=1e-9)


def test_the_widths_median_is_per_parameter_and_the_medoid_is_the_run_nearest_it():
    runs = np.array([[[1.0, 1.0, 1.0, 1.0], [1.2, 0.9, 1.0, 0.5], [0.9, 1.1, 1.0, 1.05]],
                     [[1.0, 1.0, 1.0, 1.0], [1.01, 1.0, 1.0, 1.0], [2.0, 2.0, 2.0, 2.0]]])
    med, mdo, pick = iv.combine_widths(runs)
    assert np.allclose(med[0], [1.0, 1.0, 1.0, 1.0]) and np.allclose(med[1], [1.01, 1.0, 1.0, 1.0])
    assert np.allclose(mdo[0], runs[0, 0]) and np.allclose(mdo[1], runs[1, 1]) and pick.tolist() == [0, 1]


def test_coverage_counts_the_windows_inside_196_standard_errors():
    per = {"1|0.1 % / 1e-3 rad|default": [[1.0, 1.0, 1.0, 1.3]] * 3 + [[1.1, 1.0, 1.0, 1.0]]}
    per_se = {"1|0.1 % / 1e-3 rad|default": [[0.1, 0.1, 0.1, 0.1]] * 4}
    assert np.allclose(iv.coverage(per, per_se)["default"], [1.0, 1.0, 1.0, 0.25])


def test_the_whittle_fit_recovers_a_power_law_above_a_known_floor():
    rng = np.random.default_rng(4)
    f = np.linspace(1.5, 5.0, 400)
    floor, a, beta = 1.0, 40.0, 3.0
    p = (a * f ** -beta + floor) * rng.exponential(size=f.size)  # periodogram ordinates: exponential about the mean
    la, b = iv.whittle_power_law(f, p, floor)
    assert abs(b - beta) < 0.4
    assert abs(np.exp(la) / a - 1.0) < 0.5


def test_the_honest_count_compares_each_rows_spread_with_its_windows_bound(tmp_path):
    """A row whose D/D_real spreads at the bound counts all four parameters, one at twice the bound none."""
    import json

    rng = np.random.default_rng(2)
    n, sd = 400, 0.05
    bounds = [{"1": {"0.1 % / 1e-3 rad|structural": [sd**2] * 4}} for _ in range(n)]
    path = tmp_path / "b.json"
    path.write_text(json.dumps({"per_window_relative_variance": bounds}))
    per = {"1|0.1 % / 1e-3 rad|default": (1.0 + sd * rng.standard_normal((n, 4))).tolist(),
           "1|0.1 % / 1e-3 rad|wide": (1.0 + 2 * sd * rng.standard_normal((n, 4))).tolist()}
    assert iv.honest_counts(per, path) == {"default": 4, "wide": 0}
    assert iv.honest_counts(per, tmp_path / "absent.json") is None
    # One window 60 bounds off in a and Tm: over the bound with it, within without the window farthest from the median.
    tail = np.array(per["1|0.1 % / 1e-3 rad|default"])
    tail[7, [0, 3]] = 1.0 + 60 * sd
    per["1|0.1 % / 1e-3 rad|default"] = tail.tolist()
    assert iv.honest_counts(per, path) == {"default": 2, "wide": 0}
    assert iv.honest_counts(per, path, drop=1) == {"default": 4, "wide": 0}
    r = iv.bound_ratios(per, path, drop=1)["1|0.1 % / 1e-3 rad|default"]
    assert r[0] == pytest.approx(np.delete(tail[:, 0], 7).std(ddof=1) / sd)


def test_the_summary_takes_its_ratios_against_the_chosen_row_and_says_where_the_largest_is(tmp_path, monkeypatch):
    """σ of a row over the ``--against`` row's, per cell × parameter, with the largest named; far-off counts of both;
    ``--report`` gives the same from the stored run."""
    import json

    rng = np.random.default_rng(3)
    z = rng.standard_normal((200, 4))
    base = 1.0 + 0.05 * z
    row = 1.0 + 0.05 * z * np.array([1.0, 1.0, 1.0, 2.0])
    row[0] = [1.5, 1.0, 1.0, 1.0]  # one window off by more than 20 %
    cls = "0.1 % / 1e-3 rad"
    per = {f"2|{cls}|default": (1.0 + 0.1 * z).tolist(), f"2|{cls}|hist6": base.tolist(), f"2|{cls}|new": row.tolist()}
    s = iv.summary(per, "hist6")["new"]
    want = row.std(axis=0, ddof=1) / base.std(axis=0, ddof=1)
    assert s["sigma_ratio_max"] == pytest.approx(want.max()) and s["sigma_ratio_median"] == pytest.approx(np.median(want))
    off = [int(np.sum(np.any(np.abs(x - 1.0) > 0.2, axis=1))) for x in (base, row)]
    assert s["sigma_ratio_max_at"] == f"Tm at DL 2 / {cls}" and s["off_20pct_base_variant"] == {cls: off}
    assert off[0] == 0 and off[1] >= 1
    assert set(iv.summary(per, "hist6")) == {"default", "new"}
    monkeypatch.setattr(iv.common, "RESULTS", tmp_path)
    se = {k: [[0.05] * 4] * 200 for k in per}
    (tmp_path / "run.json").write_text(json.dumps({"seed": 41, "n": 200, "per_window": per, "per_window_se": se}))
    assert iv.main(["--report", "run", "--against", "hist6"])["summary"]["new"] == s


def test_the_floor_variants_reach_the_refinements_weighting_and_restore_it():
    """Stop 45's residual-floor and band variants move the refinement's answer on a noisy window, keep the model's S where it has
    input-error content (``outside``: below the floor's reach, the weighting equals the model's), and leave
    ``input_weighting`` as it was."""
    per, _, _ = iv.run(1, 41, ["floor_outside", "no_floor", "band3"])
    assert input_weighting.disturbance_spectrum is iv._DISTURBANCE_SPECTRUM
    assert input_weighting.whitening is iv._WHITENING and input_weighting.RESIDUAL_SMOOTH_HZ == 1.0
    assert input_weighting.BAND_FRACTION == 0.1
    key = "3|0.1 % / 1e-3 rad|"
    d = np.array(per[key + "default"])
    for name in ("floor_outside", "no_floor", "band3"):
        assert not np.allclose(np.array(per[key + name]), d, rtol=0, atol=1e-9), name
    # The "outside" hooks: S formed with input-error content in the first four bins only; a floor added to the whole
    # diagonal afterwards (as build_weighting adds it) is taken back where the model has content.
    l = 16
    h = np.zeros((l, 2, 2))
    h[2] = np.eye(2)  # |H| = 1 at every frequency
    freqs = np.fft.rfftfreq(l, 0.01)
    px = np.zeros((freqs.size, 2, 2), dtype=complex)
    px[:4, 0, 0] = px[:4, 1, 1] = 1.0
    with iv.residual_floor("outside"):
        s = input_weighting.disturbance_spectrum(h, freqs, freqs, px, (1.0, 1.0))
        s[:, 0, 0] += 5.0
        s[:, 1, 1] += 5.0
        w00, _, w11 = input_weighting.whitening(s)
    np.testing.assert_allclose(w00[:4], 1 / np.sqrt(2.0))
    np.testing.assert_allclose(w00[4:], 1 / np.sqrt(6.0))
    np.testing.assert_allclose(w11[4:], 1 / np.sqrt(6.0))
    assert input_weighting.whitening is iv._WHITENING
    # The "significant_2" hooks (stop 46): the floor is kept only where it raises the diagonal above twice the model's.
    with iv.residual_floor("significant_2"):
        s = input_weighting.disturbance_spectrum(h, freqs, freqs, px, (1.0, 1.0))  # 2 in the first four bins, 1 after
        s[:, 0, 0] += 0.5  # 2.5 and 1.5: not significant anywhere
        s[:, 1, 1] += 3.0  # 5 and 4: significant everywhere
        w00, _, w11 = input_weighting.whitening(s)
    np.testing.assert_allclose(w00[:4], 1 / np.sqrt(2.0))
    np.testing.assert_allclose(w00[4:], 1.0)
    np.testing.assert_allclose(w11[:4], 1 / np.sqrt(5.0))
    np.testing.assert_allclose(w11[4:], 1 / np.sqrt(4.0))
    assert input_weighting.whitening is iv._WHITENING


def test_the_em_spectrum_is_a_spectrum_near_the_windows_own_where_the_signal_is_strong():
    """Stop 45's ``em``: Hermitian, non-negative, zero from 5 Hz, and where V and θ stand well above their floors
    (0.3–1.5 Hz) within a factor of two of the window's own estimate; handed in, it moves the refinement's answer."""
    case = common.cases(1, level=2, seed=41)[0]
    rng = np.random.default_rng(0)
    _, v_rel, th = INPUT_NOISE[2]
    w = with_input_noise(case.window, case.clean, v_rel, th, rng)
    r = identify(w, config=TAIL)
    spec = iv.em_spectrum(w, TAIL, r.d, r.quality["skip_s"])
    assert spec is not None
    s, f = spec.s, spec.freqs
    np.testing.assert_allclose(s, s.conj().transpose(0, 2, 1), atol=1e-15)
    assert np.linalg.eigvalsh(s).min() > -1e-12 * np.abs(s).max()
    assert np.all(s[f >= noise.FLOOR_FROM_HZ] == 0)
    own = noise.spectrum_at(noise.pooled_spectrum([preprocess.input_periodogram(w)]), f)
    band = (f > 0.3) & (f < 1.5)
    for c in range(2):
        ratio = s[band, c, c].real.sum() / own[band, c, c].real.sum()
        assert 0.5 < ratio < 2.0, (c, ratio)
    per, _, _ = iv.run(1, 41, ["em"])
    key = "2|0.1 % / 1e-3 rad|"
    assert not np.allclose(np.array(per[key + "em"]), np.array(per[key + "default"]), rtol=0, atol=1e-9)


def test_the_history_variants_reach_identify_and_restore_the_refinement():
    """Stop 46's ``hist6`` and ``hist6_fine_td`` move the answer on a noisy window, differ from each other, and leave the
    refinement's band and residual floor, and the history's form, as they were."""
    iv.STALENESS.clear()
    per, _, _ = iv.run(2, 41, ["hist6", "hist6_fine_td", "hist6_of1", "hist6_checked_of1"])
    assert input_weighting.BAND_FRACTION == 0.1 and input_weighting.RESIDUAL_SMOOTH_HZ == 1.0
    assert (input_weighting.HISTORY_BAND_HZ, input_weighting.HISTORY_CHI2_MAX, input_history.HISTORY_SMOOTH_HZ,
            input_history.HISTORY_STALE_MAX) == (5.0, 1.5, 0.0, 3.0)
    key = "3|0.1 % / 1e-3 rad|"
    d, h, f, o = (np.array(per[key + name]) for name in ("default", "hist6", "hist6_fine_td", "hist6_of1"))
    assert not np.allclose(h, d, rtol=0, atol=1e-9)
    assert not np.allclose(f, h, rtol=0, atol=1e-9)
    assert not np.allclose(o, h, rtol=0, atol=1e-9)  # another case's history (a stale one) gives another answer
    # The stop 46–47 forms run without the staleness check (their stored runs reproduce); the core's form since stop
    # 48 answers a window whose staleness exceeds 3 as alone.
    refused = checked = 0
    for level in (1, 2, 3):
        for cls in ("0.03 % / 3e-4 rad", "0.1 % / 1e-3 rad"):
            k = f"{level}|{cls}|"
            for stat, c, alone, unchecked in zip(iv.STALENESS[k + "hist6_checked_of1"], per[k + "hist6_checked_of1"],
                                                 per[k + "default"], per[k + "hist6_of1"], strict=True):
                checked += 1
                if stat > 3.0:
                    refused += 1
                    assert c == alone and unchecked != alone
    assert refused >= 3, (refused, checked)


def test_the_own_forms_take_the_historys_form_on_a_window_alone_and_restore_the_core():
    """Stop 48's ``own_td*``: on a noisy window the refinement asks S without the residual floor first (the history's
    form) with no history given; the guard's variant refits with the floor where χ² is large, the switch records the
    window's input-error share and with a threshold above it keeps the default's answer; every knob is restored."""
    per, _, _ = iv.run(1, 41, ["own_td", "own_td_guard1.5", "own_td_switch-1", "own_td_switch1e9"])
    assert input_weighting.build_weighting is iv._BUILD_WEIGHTING
    assert input_weighting.HISTORY_BAND_HZ == noise.FLOOR_FROM_HZ and input_weighting.HISTORY_CHI2_MAX == 1.5
    assert input_weighting.refine is iv._REFINE
    key = "3|0.1 % / 1e-3 rad|"
    d = np.array(per[key + "default"])
    assert not np.allclose(np.array(per[key + "own_td"]), d, rtol=0, atol=1e-9)
    np.testing.assert_allclose(per[key + "own_td_switch-1"], per[key + "own_td_guard1.5"], rtol=1e-9)
    np.testing.assert_allclose(per[key + "own_td_switch1e9"], d, rtol=1e-12)
    rho = iv.RHO[key + "own_td_switch-1"]
    assert len(rho) == 1 and all(np.isfinite(rho[0])) and max(rho[0]) > 0.0


def test_the_switch_report_composes_each_window_from_the_row_its_share_picks():
    """``switched``: a window whose larger input-error share exceeds the threshold takes the form's answer and SE, the
    others (and a NaN share) the default's; the share switched is counted over every noisy window."""
    cls = "0.1 % / 1e-3 rad"
    run = {"rho": {f"3|{cls}|own_td_switch-1": [[5.0, 0.1], [0.2, 0.3], [float("nan"), 9.0]]},
           "per_window": {f"3|{cls}|default": [[1.0] * 4, [1.1] * 4, [1.2] * 4],
                          f"3|{cls}|own_td_switch-1": [[2.0] * 4, [2.1] * 4, [2.2] * 4]},
           "per_window_se": {f"3|{cls}|default": [[0.1] * 4] * 3, f"3|{cls}|own_td_switch-1": [[0.2] * 4] * 3}}
    per, per_se, share = iv.switched(run, 1.0)
    assert per[f"3|{cls}|switch1"] == [[2.0] * 4, [1.1] * 4, [1.2] * 4]
    assert per_se[f"3|{cls}|switch1"] == [[0.2] * 4, [0.1] * 4, [0.1] * 4]
    assert share == pytest.approx(1 / 3)


def test_the_gain49_variants_reach_the_smoother_and_the_band_and_restore_the_core():
    """At 25 frames/s each of stop 49's two changes moves the answer (the band 4 Hz against 2.5, the gain's average
    without the own bin); ``gain49`` makes both; the core's settings are back afterwards."""
    per, _, _ = iv.run(1, 41, ["gain49", "own_bin_out", "band4"], fs=25.0)
    assert not noise.GAIN_WITHOUT_OWN_BIN and input_weighting.MIN_BAND_HZ == 0.0
    key = "2|0.1 % / 1e-3 rad|"
    d = np.array(per[key + "default"])
    rows = {name: np.array(per[key + name]) for name in ("gain49", "own_bin_out", "band4")}
    for v in rows.values():
        assert np.all(np.isfinite(v)) and not np.allclose(v, d, rtol=0, atol=1e-9)
    assert not np.allclose(rows["own_bin_out"], rows["band4"], rtol=0, atol=1e-9)
    with iv.smoother_gain(True, 4.0):
        assert noise.GAIN_WITHOUT_OWN_BIN and input_weighting.fitted_band_hz(1 / 25) == 4.0
    assert not noise.GAIN_WITHOUT_OWN_BIN and input_weighting.fitted_band_hz(1 / 25) == 2.5


def test_the_cap_variants_set_the_band_and_restore_it():
    """``capinf`` (the default before stop 49, 10 Hz at 100 frames/s) moves the answer, ``cap4`` (today's) does not;
    the core's cap is 4 Hz afterwards."""
    per, _, _ = iv.run(1, 41, ["capinf", "cap4"])
    assert input_weighting.MAX_BAND_HZ == 4.0
    key = "2|0.1 % / 1e-3 rad|"
    d = np.array(per[key + "default"])
    uncapped, cap = np.array(per[key + "capinf"]), np.array(per[key + "cap4"])
    assert np.all(np.isfinite(uncapped)) and not np.allclose(uncapped, d, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(cap, d)


def test_the_stop_50_variants_reach_the_core_and_restore_it():
    """``lagrange`` (the 4-point cubics inside a split step) moves the answer at 25 frames/s and not at 100, where the
    step is not split; ``band_cut`` moves it at 100; the core's switches are back afterwards."""
    key = "2|0.03 % / 3e-4 rad|"
    per, _, _ = iv.run(1, 41, ["lagrange", "band_cut"])
    assert motor.SPLINE_INPUTS is True and input_weighting.BAND_AT_CUTOFF is False
    d = np.array(per[key + "default"])
    np.testing.assert_array_equal(np.array(per[key + "lagrange"]), d)
    assert not np.allclose(np.array(per[key + "band_cut"]), d, rtol=0, atol=1e-9)
    per, _, _ = iv.run(1, 41, ["lagrange"], fs=25.0)
    assert not np.allclose(np.array(per[key + "lagrange"]), np.array(per[key + "default"]), rtol=0, atol=1e-9)


def test_the_vouched_reading_keeps_the_windows_without_the_20pct_flag_and_takes_the_bound_over_them(monkeypatch):
    r = [[1.1, 1.0, 1.0, 1.0], [0.9, 1.0, 1.0, 1.0], [1.5, 1.0, 1.0, 1.0], [1.0, 1.2, 1.0, 0.8]]
    se = [[0.05, 0.01, 0.01, 0.01], [0.05, 0.01, 0.01, 0.01], [0.2, 0.01, 0.01, 0.01], [0.01, 0.01, 0.01, 0.01]]
    var = [[0.01] * 4, [0.01] * 4, [1.0] * 4, [0.04] * 4]  # the dropped window's bound is large, as a poorly excited one's
    bounds = [{"2": {"0.1 % / 1e-3 rad|structural": v}} for v in var]
    monkeypatch.setattr(common, "read_json", lambda name: {"per_window_relative_variance": bounds})
    run = {"seed": 43, "per_window": {"2|0.1 % / 1e-3 rad|default": r, "2|0.1 % / 1e-3 rad|cap4": r},
           "per_window_se": {"2|0.1 % / 1e-3 rad|default": se, "2|0.1 % / 1e-3 rad|cap4": se}}
    out = iv.vouched_ratios(run)
    c = out["2|0.1 % / 1e-3 rad"]
    assert list(out) == ["2|0.1 % / 1e-3 rad"] and (c["n"], c["kept"]) == (4, 3)  # 0.2 > 0.06 × 1.5: flagged, out
    keep = np.array(r)[[0, 1, 3]]
    want = keep.std(axis=0, ddof=1) / np.sqrt(np.array(var)[[0, 1, 3]].mean(axis=0))
    np.testing.assert_allclose(c["vouched"], want)
    np.testing.assert_allclose(c["all"], np.array(r).std(axis=0, ddof=1) / np.sqrt(np.array(var).mean(axis=0)))
    assert (c["off_20pct_kept"], c["off_20pct_dropped"]) == (0, 1)
