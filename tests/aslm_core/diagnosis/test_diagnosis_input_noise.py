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
