"""The separability oracle's library mode (benchmarks/diagnosis_separability.py --library, stop 31)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import diagnosis_separability as ds  # noqa: E402

SIG = (2e-3, 1e-3)  # unit-SNR std of P and Q [pu]


def _zero_g(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.zeros(k), np.zeros(k), np.zeros(k)


def _linear_pair(k: int = 40, seed: int = 5):
    """Held-out coefficients of data made by form A (the plain fit leaves a·x_A), and of two one-parameter
    forms fitted to it by least squares: A (exact) and B (another shape, overlapping A's)."""
    rng = np.random.default_rng(seed)
    x_a = rng.standard_normal((k, 2)) * SIG
    x_b = 0.7 * x_a + 0.7 * rng.standard_normal((k, 2)) * SIG
    r0 = 3.0 * x_a
    res = {}
    for name, x in (("frequency_dependence", x_a), ("speed_dependent_torque", x_b)):
        w = x / SIG  # the white-noise weights of the fit
        beta = float(np.sum(w * (r0 / SIG)) / np.sum(w * w))
        res[name] = r0 - beta * x
    return r0, res


def test_without_input_noise_the_metric_is_the_pair_modes_white_one_scaled_by_the_snr():
    r0, res = _linear_pair()
    snr = 20.0
    out = ds.pair_zs(r0, res, "frequency_dependence", snr, SIG, _zero_g(len(r0)))
    s = 10 ** (snr / 20)
    assert np.isclose(out["z_oracle"], np.linalg.norm(r0 / SIG) * s, rtol=1e-9)
    rb, ra = res["speed_dependent_torque"] / SIG, res["frequency_dependence"] / SIG
    d = rb - ra  # the pair mode's z(A over B) = Dᵀr_B/‖D‖ at unit SNR
    assert np.isclose(out["fwd"]["speed_dependent_torque"], np.sum(d * rb) / np.linalg.norm(d) * s, rtol=1e-9)
    assert np.isclose(out["back"]["speed_dependent_torque"], np.sum(-d * ra) / np.linalg.norm(d) * s, atol=1e-9)


def test_the_input_noise_enters_as_each_coefficients_2x2_covariance_and_lowers_z():
    r0, res = _linear_pair()
    k = len(r0)
    rng = np.random.default_rng(1)
    gp, gq = (rng.uniform(0.5, 2.0, k) * s ** 2 * 1e-2 for s in SIG)
    gpq = 0.6 * np.sqrt(gp * gq)
    snr = 22.0
    out = ds.pair_zs(r0, res, "frequency_dependence", snr, SIG, (gp, gq, gpq))
    s2 = 10 ** (-snr / 10)
    brute = sum(float(r0[i] @ np.linalg.solve(np.array([[SIG[0] ** 2 * s2 + gp[i], gpq[i]],
                                                        [gpq[i], SIG[1] ** 2 * s2 + gq[i]]]), r0[i]))
                for i in range(k))
    assert np.isclose(out["z_oracle"], np.sqrt(brute), rtol=1e-6)
    white = ds.pair_zs(r0, res, "frequency_dependence", snr, SIG, _zero_g(k))
    assert out["z_oracle"] < white["z_oracle"]
    # The input noise does not scale with the SNR: 20 dB more P/Q SNR gains far less than 10×.
    hi = ds.pair_zs(r0, res, "frequency_dependence", snr + 20, SIG, (gp, gq, gpq))
    assert hi["z_oracle"] < 5 * out["z_oracle"]


def test_a_pair_fitted_on_data_of_one_separates_in_the_right_direction():
    r0, res = _linear_pair()
    out = ds.pair_zs(r0, res, "frequency_dependence", 14.0, SIG, _zero_g(len(r0)))
    assert out["fwd"]["speed_dependent_torque"] > 3.0
    assert abs(out["back"]["speed_dependent_torque"]) < 1e-6  # the exact form leaves nothing for B to explain
    sep = ds.separation(out, "frequency_dependence", 3.06, [])
    assert sep["separable"] and sep["rivals"] == ["speed_dependent_torque"]
    # The same data read with B as the truth: B does not beat A, and A beats B back.
    other = ds.pair_zs(r0, res, "speed_dependent_torque", 14.0, SIG, _zero_g(len(r0)))
    sep = ds.separation(other, "speed_dependent_torque", 3.06, [])
    assert not sep["separable"] and sep["not_forward"] == ["frequency_dependence"]
    # At a low enough SNR neither is detectable and the look-alike is not separated.
    low = ds.pair_zs(r0, res, "frequency_dependence", -30.0, SIG, _zero_g(len(r0)))
    assert low["z_oracle"] < 3.06 and not ds.separation(low, "frequency_dependence", 3.06, [])["separable"]


def test_holm_steps_down_and_stops_at_the_first_failure():
    assert ds._holm({"a": 0.001, "b": 0.02, "c": 0.04}, 0.05) == ["a", "b", "c"]
    assert ds._holm({"a": 0.001, "b": 0.03, "c": 0.04}, 0.05) == ["a"]  # 0.03 > 0.05/2
    assert ds._holm({}, 0.05) == []


def test_the_tally_counts_detectable_and_separable_cases_and_the_target():
    def case(level, det, sep, outcome):
        return {"mode": "input", "kind": "frequency_dependence", "level": level, "expected": "frequency_dependence",
                "detectable": det, "separable": sep, "outcome": outcome}

    cases = [case(2, True, True, "frequency_dependence"), case(2, True, True, "ambiguous"),
             case(2, True, False, "ambiguous"), case(2, True, False, "speed_dependent_torque"),
             case(2, False, False, "consistent"), case(1, True, True, "frequency_dependence")]
    tab = {(t["mode"], t["level"]): t for t in ds.library_table(cases)}
    t2 = tab[("input", 2)]
    assert (t2["cases"], t2["detectable"], t2["det_sep"], t2["right_det_sep"], t2["ambiguous_det_sep"]) == (5, 4, 2, 1, 1)
    assert t2["det_not_sep_outcomes"] == {"ambiguous": 1, "wrong": 1}
    goals = {(g["mode"], g["level"]): g for g in ds.honest_targets(list(tab.values()))}
    assert not goals[("input", 2)]["met"] and goals[("input", 2)]["misses"] == {"frequency_dependence": 1}
    assert goals[("input", 1)]["met"] and goals[("input", 1)]["share"] == 1.0


def test_the_power_reading_asks_the_oracle_z_to_clear_the_critical_value_and_the_bank_to_be_readable(
        tmp_path, monkeypatch):
    """``--detect-margin`` and ``--readable`` (stop 44): a case whose oracle z clears the critical value by less than
    the margin is not detectable, and a capacitor's V/θ case whose bank state the two-state form cannot read from the
    PMU's V is not detectable either — in that mode and that kind only."""
    import benchmarks.diagnosis_detectability as dd

    zcrit = 3.06

    def window(kind: str, truth: str, z: float) -> dict:
        cell = {"z_oracle": z, "score": {truth: z}, "fwd": {}, "back": {}}
        return {"kind": kind, "seed": 7, "window": [2.0, 12.0], "truth": truth, "implausible": [],
                "levels": {"1": {"snr_db": 14.0, "pq": cell, "input": cell}}}

    windows = [window("switched_capacitor", "switched_shunt", zcrit + 0.5),
               window("frequency_dependence", "frequency_dependence", zcrit + 1.5)]
    monkeypatch.setattr(ds, "jobs", lambda st, kinds=None: [("switched_capacitor", 7), ("frequency_dependence", 7)])
    monkeypatch.setattr(dd, "_records", lambda stem, input_noise: [])
    monkeypatch.setattr(ds, "RESULTS", tmp_path)
    (tmp_path / "shunt.json").write_text(
        '{"rows": [{"seed": 7, "window": [2.0, 12.0], "level": 1, "agreement_best_two_state_noisy_v": 0.9},'
        ' {"seed": 7, "window": [12.0, 22.0], "level": 1, "agreement_best_two_state_noisy_v": 0.99}]}')
    unreadable = ds.unreadable_banks({"S": "shunt"})
    assert unreadable == {("S", "switched_capacitor", 7, 2.0, 1)}

    def detectable(**kw) -> dict:
        return {(c["mode"], c["kind"]): c["detectable"]
                for c in ds.library_cases(windows, ["S"], {"S": "x"}, zcrit, **kw)}

    assert all(detectable().values())
    assert detectable(detect_margin=1.0) == {("pq", "switched_capacitor"): False, ("input", "switched_capacitor"): False,
                                             ("pq", "frequency_dependence"): True,
                                             ("input", "frequency_dependence"): True}
    assert detectable(unreadable=unreadable) == {("pq", "switched_capacitor"): True,
                                                 ("input", "switched_capacitor"): False,
                                                 ("pq", "frequency_dependence"): True,
                                                 ("input", "frequency_dependence"): True}


def test_the_reachable_count_is_the_expected_number_of_detections_at_the_critical_value():
    """A case whose oracle z equals the critical value is detected in half the draws, one far above it always, one far
    below never; the separable-only sum leaves the others out."""
    def case(z, sep):
        return {"mode": "input", "level": 2, "z_oracle": z, "separable": sep}

    zcrit = 3.06
    got = {(r["mode"], r["level"]): r
           for r in ds.reachable([case(zcrit, True), case(zcrit + 10.0, False), case(zcrit - 10.0, True)], zcrit)}
    r = got[("input", 2)]
    assert r["cases"] == 3
    assert abs(r["detected"] - 1.5) < 1e-9
    assert abs(r["detected_and_separable"] - 0.5) < 1e-9
