"""Noise on the inputs V and θ (errors in variables): modelled, so clean cases stay ``consistent`` and a
concealed effect is still named when the PMU's V, θ and f are as noisy as its P and Q."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from aslm_core.diagnosis import diagnose
from aslm_core.diagnosis.locate import band_excess, noise_floor, periodogram
from aslm_sim.cases import make_case, make_cases
from aslm_sim.effects import apply_effect

dg = importlib.import_module("aslm_core.diagnosis.pipeline")


@pytest.fixture(scope="module")
def noisy_cases():
    """Clean ZIP + IM cases with noise on V, θ and f too, one per noise level."""
    return [make_case(900 + lvl, level=lvl, input_noise=True) for lvl in (1, 2, 3)]


def test_noise_model_recovers_the_input_and_output_noise(noisy_cases):
    for c in noisy_cases:
        a = dg._analyse(c.window, None, None, dg.DiagnosisConfig())
        nm, w, cl = a.noise, c.window, c.clean
        for est, true in ((nm.sigma_v, w.V - cl.V), (nm.sigma_theta, w.theta - cl.theta), (nm.sigma_p, w.P - cl.P),
                          (nm.sigma_q, w.Q - cl.Q)):
            assert est == pytest.approx(np.std(true), rel=0.2)
        # Most of the residual noise comes through the inputs (the motor's and ZIP's instantaneous gain).
        assert a.floors["P"]["input_share"] > 0.3 and a.floors["Q"]["input_share"] > 0.3


def test_without_input_noise_nothing_is_propagated():
    c = make_case(903, level=2, input_noise=False)
    a = dg._analyse(c.window, None, None, dg.DiagnosisConfig())
    assert a.floors["P"]["input_share"] < 0.02 and a.floors["Q"]["input_share"] < 0.02


def test_clean_cases_with_input_noise_are_consistent(noisy_cases):
    """The old white-noise test named ``measurement_skew`` (or located a mismatch) on every such case."""
    for c in noisy_cases:
        rep = diagnose(c.window)
        assert rep.verdict == "consistent", (c.level, rep.message, rep.missing_physics[:2])
        assert not rep.located.channels


def test_clean_case_with_input_noise_against_its_true_model_is_consistent():
    c = make_cases(1, level=2, seed=907, input_noise=True)[0]
    rep = diagnose(c.window, {"dynamic": c.truth.dynamic, "static": c.truth.static_identifiable})
    assert rep.mode == "user" and rep.verdict == "consistent", (rep.message, rep.missing_physics[:2])


@pytest.mark.parametrize(("effect", "magnitude"), [("inverter_der", 3.0), ("frequency_dependence", 2.5)])
def test_concealed_effect_with_input_noise_is_named(effect, magnitude):
    # Concealed on the same case without input noise (noisy V/θ alone lower the plain fit's FD).
    ec = apply_effect(make_case(911, level=3, input_noise=True), effect, magnitude, seed=4,
                      conceal_case=make_case(911, level=3, input_noise=False))
    assert min(ec.fd_plain.values()) >= 0.9  # concealed
    rep = diagnose(ec.window)
    assert rep.verdict == "explained" and rep.cause == effect, (rep.message, rep.missing_physics[:2])


def test_band_test_takes_the_propagated_noise_into_account():
    """Coloured noise (white + low-passed, as V noise through a motor) is excess over a white floor but not
    over the floor plus its propagated spectrum."""
    rng = np.random.default_rng(5)
    fs, n = 100.0, 900
    k = np.exp(-np.arange(60) / 12.0)
    low = np.convolve(rng.standard_normal(n + 60), k / np.linalg.norm(k), mode="valid")[:n]
    r = 1e-3 * rng.standard_normal(n) + 2e-3 * low
    fl = noise_floor(r, fs)
    assert any(b["significant"] for b in band_excess(r, fs, fl))
    # The expected spectrum of the coloured part, from independent draws (as the noise model's probes).
    draws = [np.convolve(rng.standard_normal(n + 60), k / np.linalg.norm(k), mode="valid")[:n] for _ in range(32)]
    extra = np.mean([periodogram(2e-3 * d, fs)[1] for d in draws], axis=0)
    assert not any(b["significant"] for b in band_excess(r, fs, {**fl, "extra_psd": extra}))


def _diagonal_gain(m, R0p, R0q, Dp, Dq, vp, vq):
    """The gain before P and Q were decorrelated: per channel on x/√v, the P/Q covariance ignored."""
    s0 = [np.sum(R0p**2 / vp), np.sum(R0q**2 / vq)]
    s1 = [np.sum((R0p - Dp) ** 2 / vp), np.sum((R0q - Dq) ** 2 / vq)]
    return 0.5 * m * sum(np.log(a / b) for a, b in zip(s0, s1, strict=True))


def test_gain_without_p_q_covariance_is_the_per_channel_one_and_the_bias_enters_as_before():
    from aslm_core.diagnosis.engine import _gain

    rng = np.random.default_rng(0)
    m = 30
    R0p, R0q, Dp, Dq = rng.standard_normal((4, m)) * [[2e-4], [1e-4], [1e-4], [5e-5]]
    vp, vq = rng.uniform(1, 2, m) * 1e-8, rng.uniform(1, 2, m) * 4e-9
    g = _gain(m, R0p, R0q, Dp, Dq, vp, vq, np.zeros(m))
    assert g == pytest.approx(_diagonal_gain(m, R0p, R0q, Dp, Dq, vp, vq), rel=1e-12)
    G0p, G0q, dGp, dGq = rng.standard_normal((4, m, 8)) * 1e-4
    bp = np.mean(-np.sum(G0p * dGp / vp[:, None], axis=0))
    bq = np.mean(-np.sum(G0q * dGq / vq[:, None], axis=0))
    s = [np.sum(R0p**2 / vp), np.sum(R0q**2 / vq), np.sum((R0p - Dp) ** 2 / vp) + 2 * bp,
         np.sum((R0q - Dq) ** 2 / vq) + 2 * bq]
    want = 0.5 * m * (np.log(s[0] / s[2]) + np.log(s[1] / s[3]))
    assert _gain(m, R0p, R0q, Dp, Dq, vp, vq, np.zeros(m), (G0p, G0q, dGp, dGq)) == pytest.approx(want, rel=1e-12)


def test_gain_counts_a_correction_where_correlated_p_q_noise_cancels():
    """P and Q noise 0.9 correlated (V/θ noise propagated into both) and a true correction along P − Q, where
    the noise nearly cancels: the GLS score is ~5, the decorrelated gain passes the one-parameter penalty in
    nearly every draw, the diagonal gain (which sees the large per-channel noise) in few; with nothing to
    correct (the same D, residual pure noise) the decorrelated gain is negative in most draws."""
    from aslm_core.diagnosis.engine import _gain, _gls_metric

    rng = np.random.default_rng(1)
    m, rho, s = 30, 0.9, 1e-3
    vp = vq = np.full(m, s * s)
    cpq = np.full(m, rho * s * s)
    cinv = _gls_metric(vp, vq, cpq, None)
    d = np.full(m, 5.0 * s * np.sqrt(2 * (1 - rho) / m))  # the GLS norm √(DᵀC⁻¹D) = 5; the diagonal one 1.6
    Dp, Dq = d / 2, -d / 2
    wp, wq = cinv(Dp, Dq)
    assert np.sqrt(wp @ Dp + wq @ Dq) == pytest.approx(5.0, rel=1e-9)
    chol = np.linalg.cholesky([[1, rho], [rho, 1]]) * s
    fixed, diag, null = [], [], []
    for _ in range(200):
        e = chol @ rng.standard_normal((2, m))
        fixed.append(_gain(m, Dp + e[0], Dq + e[1], Dp, Dq, vp, vq, cpq))
        diag.append(_diagonal_gain(m, Dp + e[0], Dq + e[1], Dp, Dq, vp, vq))
        null.append(_gain(m, e[0], e[1], Dp, Dq, vp, vq, cpq))
    penalty = 0.5 * np.log(m)
    assert np.mean(np.array(fixed) > penalty) > 0.8
    assert np.mean(np.array(diag) > penalty) < 0.3
    assert np.mean(np.array(null) < 0) > 0.8
