"""The oracle-detectability tally (benchmarks/diagnosis_detectability.py) and the fourth confirmation set."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import diagnosis_detectability as dd  # noqa: E402
from benchmarks import diagnosis_independent as di  # noqa: E402


def _case(kind: str, level: int, z: float, outcome: str, z_form: float | None = None) -> dict:
    return {"kind": kind, "level": level, "z_oracle": z, "z_form": z_form, "outcome": outcome,
            "expected": "second_motor" if kind == "second_motor" else "consistent"}


def test_cases_are_split_at_the_critical_value_and_right_names_counted_on_each_side():
    rows = [_case("second_motor", 1, 1.0, "consistent"), _case("second_motor", 1, 3.5, "second_motor", 3.4),
            _case("second_motor", 1, 5.0, "consistent", 2.0), _case("second_motor", 1, 4.0, "ambiguous", 3.9),
            _case("second_motor", 2, 9.0, "second_motor", 8.0)]
    tab = {(t["kind"], t["level"]): t for t in dd.table(rows, 3.06)}
    l1 = tab[("second_motor", 1)]
    assert (l1["cases"], l1["detectable"], l1["right_det"], l1["consistent_det"], l1["ambiguous_det"]) == (4, 3, 1, 1, 1)
    assert (l1["undet_with_verdict"], l1["right_undet"], l1["form_below"]) == (1, 0, 1)
    assert tab[("second_motor", 2)]["right_det"] == 1
    assert "| second_motor | L1 | 4 | 3 | 1/4 | 1/3 | 1 | 1 | 0/1 | 1 |" in dd.markdown(dd.table(rows, 3.06), 3.06)


def test_the_fourth_confirmation_set_has_the_third_ones_size():
    assert len(di.SETS["confirm4"]["clean"]) >= 10 and len(di.SETS["confirm4"]["effect"]) >= 4


def test_the_v_theta_oracle_z_is_the_gls_norm_and_reduces_to_the_p_q_one_without_input_noise():
    """Without propagated noise the V/θ mode's z is the P/Q mode's z_unit·10^(SNR/20); with it, √(rᵀC⁻¹r)
    with each coefficient's 2×2 P/Q covariance, and the true form's z_form equals it when D = r."""
    rng = np.random.default_rng(3)
    r = rng.standard_normal((12, 2)) * [2e-4, 1e-4]
    sp, sq, snr = 0.01, 0.004, 22.0
    g = rng.uniform(1e-8, 4e-8, (12, 2))
    gpq = 0.5 * np.sqrt(g[:, 0] * g[:, 1])
    vt = {"sigma_p_unit": sp, "sigma_q_unit": sq, "r_p": r[:, 0], "r_q": r[:, 1],
          "g_p": np.zeros(12), "g_q": np.zeros(12), "g_pq": np.zeros(12)}
    z_unit = np.sqrt(np.sum((r / [sp, sq]) ** 2))
    assert np.isclose(dd.vtheta_z(vt, snr), z_unit * 10 ** (snr / 20))
    vt.update(g_p=g[:, 0], g_q=g[:, 1], g_pq=gpq, d_p=r[:, 0], d_q=r[:, 1])
    s2 = 10 ** (-snr / 10)
    z2 = sum(r[k] @ np.linalg.solve([[sp**2 * s2 + g[k, 0], gpq[k]], [gpq[k], sq**2 * s2 + g[k, 1]]], r[k])
             for k in range(12))
    assert np.isclose(dd.vtheta_z(vt, snr), np.sqrt(z2))
    assert np.isclose(dd.vtheta_z(vt, snr, "d"), np.sqrt(z2))
    assert np.isnan(dd.vtheta_z({k: v for k, v in vt.items() if k not in ("d_p", "d_q")}, snr, "d"))


def test_the_v_theta_oracle_noise_matches_a_monte_carlo_through_fresh_noisy_windows():
    """The oracle's propagated V/θ noise (noise.py's draws through the plain model, smoothed) against a brute
    Monte Carlo on a small synthetic case: 300 windows with noisy V and θ, each prepared afresh (its derived
    signals recomputed) and played through the same fitted plain model; band-averaged variances of P and Q
    and their covariance agree, in the low and the high half of the band."""
    from aslm_core import Window
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import Candidate
    from aslm_core.diagnosis.noise import dct_band
    from aslm_core.diagnosis.pipeline import DiagnosisConfig
    from aslm_core.diagnosis.segment import make_segment
    from aslm_sim.cases import make_case

    clean = make_case(5, level=None, f0=60.0).clean
    rec = {"t": clean.t, "V": clean.V, "theta": clean.theta, "P": clean.P, "Q": clean.Q}
    config = DiagnosisConfig()
    seg, ctx, _, plain, _ = dd.noise_free_plain(rec, clean.t[0], clean.t[-1], config)
    sv, st = dd.true_input_sigmas(seg)
    gp, gq, gpq = dd.input_noise_coefficients(seg, ctx, plain, sv, st)
    rng = np.random.default_rng(11)
    base = engine.output(Candidate(), seg, ctx, plain)
    acc = []
    for _ in range(300):
        w = Window(seg.t, seg.V + sv * rng.standard_normal(seg.n), seg.theta + st * rng.standard_normal(seg.n),
                   seg.P, seg.Q, f0=60.0)
        # The measured inputs, whose white noise the oracle propagates (not their conditional mean, stop 32).
        s = make_segment(w, skip_s=config.skip_s, train_fraction=config.train_fraction, input_mean=False)
        out = engine.output(Candidate(), s, ctx, plain)
        acc.append(dct_band(np.column_stack([out[0] - base[0], out[1] - base[1]])[seg.test], seg.fs, config.band_hz))
    c = np.array(acc)  # (draws, coefficients, channel)
    mc = (np.mean(c[:, :, 0] ** 2, 0), np.mean(c[:, :, 1] ** 2, 0), np.mean(c[:, :, 0] * c[:, :, 1], 0))
    half = gp.size // 2
    for part in (slice(0, half), slice(half, None)):
        for oracle, brute in zip((gp, gq), mc[:2], strict=True):
            assert 0.85 < np.mean(oracle[part]) / np.mean(brute[part]) < 1.15
        scale = np.sqrt(np.mean(mc[0][part]) * np.mean(mc[1][part]))
        assert abs(np.mean(gpq[part]) - np.mean(mc[2][part])) < 0.1 * scale
