"""Conditional-mean inputs of the diagnosis (docs/diagnosis.md, "Stop 32"): where V and θ carry white noise the
segment holds their Wiener conditional mean and the noise model draws the smoother's error, not white noise; exact
inputs give the segment built without that step, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from aslm_core import motor
from aslm_core.diagnosis.noise import estimate
from aslm_core.diagnosis.segment import FREQ_LOWPASS_HZ, _lowpass, make_segment
from aslm_core.noise import wiener_smooth
from aslm_core.preprocess import prepare
from aslm_core.window import Window

N, DT, SIGMA = 1001, 0.01, 1e-3


def _ambient(scale: float, seed: int) -> np.ndarray:
    b, a = signal.butter(2, 1.5, fs=1.0 / DT)
    x = signal.lfilter(b, a, np.random.default_rng(seed).standard_normal(N + 400))[400:]
    return scale * x / np.std(x)


@pytest.fixture(scope="module")
def windows() -> tuple[Window, Window]:
    """The same bus with exact inputs and with 1e-3 white noise on V [pu] and θ [rad]."""
    t = np.arange(N) * DT
    v, th = 1.0 + _ambient(0.003, 1), _ambient(0.005, 2)
    p_im, q_im, _ = motor.simulate(v, th, np.array([40.0, 15.0, 1.3, 1.0]), DT, motor.omega0_of(50.0))
    rng = np.random.default_rng(3)
    p = p_im + 2.0 + v + 2e-3 * rng.standard_normal(N)
    q = q_im + 0.5 * v * v + 2e-3 * rng.standard_normal(N)
    noisy = Window(t, v + SIGMA * rng.standard_normal(N), th + SIGMA * rng.standard_normal(N), p, q)
    return Window(t, v, th, p, q), noisy


def test_the_conditional_mean_is_closer_to_the_clean_inputs(windows):
    clean, noisy = windows
    seg = make_segment(noisy)
    assert seg.conditional_mean and seg.V_raw is not None
    sl = slice(seg.k0, seg.ke)
    for x, raw, true in ((seg.V, seg.V_raw, clean.V), (seg.theta, seg.theta_raw, clean.theta)):
        err_raw, err_cm = np.std((raw - true)[sl]), np.std((x - true)[sl])
        assert err_raw == pytest.approx(SIGMA, rel=0.15)
        assert err_cm < 0.7 * err_raw
    # Δf and dV/dt are built from the conditional mean.
    assert np.array_equal(seg.dvdt, _lowpass(np.gradient(seg.V, DT), 1.0 / DT, FREQ_LOWPASS_HZ))


def test_the_draws_have_the_smoothers_error_spectrum(windows):
    seg = make_segment(windows[1])
    nm = estimate(seg, lambda s: (2.0 * s.V, s.theta + 0.5 * s.V), slice(seg.k0, seg.ke), error_draws=True)
    # The reported floor stays the measured inputs' white noise.
    assert nm.conditional_mean and nm.sigma_v == pytest.approx(SIGMA, rel=0.15)
    f, px = seg.input_error
    raw = prepare(windows[1], floors=True).noise
    _, _, f_s, px_s = wiener_smooth(np.stack([seg.V_raw, seg.theta_raw]), 1.0 / DT,
                                    [raw["noise_v"], raw["noise_theta"]], return_cutoffs=True, return_error=True)
    ff = np.fft.rfftfreq(N, DT)
    for draws, c, name in ((nm.inputs_v, 0, "v"), (nm.inputs_theta, 1, "theta")):
        var = raw[f"noise_{name}"] ** 2
        smoother = px_s[:, c, c].real
        # The smoother's error where it passes signal; the floor's variance where it passes none (the bound).
        assert np.array_equal(px[:, c, c].real, np.where(smoother > 0.0, smoother, var))
        pw = np.mean(np.abs(np.fft.rfft(draws, axis=1)) ** 2, axis=0) / N  # per-sample units, as px
        for lo, hi in ((0.0, 2.0), (2.0, 4.0), (10.0, 50.0)):
            want = px[(f >= lo) & (f < hi), c, c].real.mean()
            assert np.mean(pw[(ff >= lo) & (ff < hi)]) == pytest.approx(want, rel=0.2)
        # Not white: where the smoother's gain falls (its error below 0.8 of the floor's variance) so do the draws.
        low = (smoother > 0.0) & (smoother < 0.8 * var)
        band = (ff >= f[low].min()) & (ff <= f[low].max())
        assert np.mean(pw[band]) == pytest.approx(np.mean(smoother[low]), rel=0.25)
        assert np.mean(pw[band]) < 0.85 * var


def test_exact_inputs_give_the_segment_as_before(windows):
    clean = windows[0]
    seg = make_segment(clean)
    assert not seg.conditional_mean and seg.V_raw is None
    # The segment of the measured inputs, as make_segment built it before stop 32.
    prep = prepare(clean)
    df = np.gradient(prep.theta, DT) / (2.0 * math.pi)
    df = _lowpass(df - np.median(df), 1.0 / DT, FREQ_LOWPASS_HZ)
    for got, want in ((seg.V, prep.V), (seg.theta, prep.theta), (seg.P, prep.P), (seg.Q, prep.Q), (seg.dfreq, df),
                      (seg.dvdt, _lowpass(np.gradient(prep.V, DT), 1.0 / DT, FREQ_LOWPASS_HZ))):
        assert np.array_equal(got, want)
    assert np.array_equal(seg.v_measured, seg.V)
    nm = estimate(seg, lambda s: (2.0 * s.V, s.theta + 0.5 * s.V), slice(seg.k0, seg.ke))
    assert not nm.conditional_mean
    rng = np.random.default_rng(0)  # the white draws at the measured floors, as before
    assert np.array_equal(nm.inputs_v, nm.sigma_v * rng.standard_normal((16, N)))


def test_by_default_the_draws_are_white_at_the_measured_floors(windows):
    seg = make_segment(windows[1])
    win = slice(seg.k0, seg.ke)
    nm = estimate(seg, lambda s: (2.0 * s.V, s.theta + 0.5 * s.V), win)
    assert nm.conditional_mean and nm.sigma_v == pytest.approx(SIGMA, rel=0.15)
    rng = np.random.default_rng(0)
    assert np.array_equal(nm.inputs_v, nm.sigma_v * rng.standard_normal((16, N)))
    assert np.array_equal(nm.inputs_theta, nm.sigma_theta * rng.standard_normal((16, N)))


def test_the_smoothers_tail_is_an_option_that_leaves_exact_inputs_alone(windows):
    # DiagnosisConfig.input_tail (off: worse on the development sets, docs/diagnosis.md "Stop 42").
    clean, noisy = windows
    for a, b in zip(_arrays(make_segment(clean)), _arrays(make_segment(clean, input_tail=True)), strict=True):
        assert np.array_equal(a, b)
    plain, tail = make_segment(noisy), make_segment(noisy, input_tail=True)
    assert np.array_equal(tail.V, prepare(noisy, input_smoother="wiener", input_tail=True).V)
    assert np.array_equal(plain.V_raw, tail.V_raw)
    assert not np.array_equal(plain.V, tail.V)
    # The continued spectrum passes more of the window above the cut-off: the smoothed V moves more there.
    sl = slice(plain.k0, plain.ke)
    ff = np.fft.rfftfreq(sl.stop - sl.start, DT)
    hi = (ff > 3.0) & (ff < 5.0)
    power = [np.sum(np.abs(np.fft.rfft(x[sl] - x[sl].mean()))[hi] ** 2) for x in (plain.V, tail.V)]
    assert power[1] > power[0]


def _arrays(seg) -> list[np.ndarray]:
    return [seg.V, seg.theta, seg.P, seg.Q, seg.dfreq, seg.dvdt]
