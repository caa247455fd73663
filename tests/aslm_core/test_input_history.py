"""A bus's history of input periodograms (aslm_core.input_history) and the identifier given its spectrum."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import D_TRUE, equation_window
from scipy import signal

from aslm_core import identify, noise
from aslm_core import input_weighting as iw
from aslm_core.input_history import HISTORY_STALE_MAX, InputHistory, staleness
from aslm_core.preprocess import input_periodogram
from aslm_core.window import Window

FS, N = 50.0, 500


def _noisy_inputs(k: int, seed: int = 7) -> list[np.ndarray]:
    """k consecutive 10 s pieces of two coherent 1 Hz low-passed channels with white noise."""
    rng = np.random.default_rng(seed)
    b, a = signal.butter(2, 1.0, fs=FS)
    w = signal.lfilter(b, a, rng.standard_normal((2, k * N + 1000)), axis=1)[:, 1000:]
    x = np.stack([w[0], 0.5 * w[0] + w[1]]) + 0.1 * rng.standard_normal((2, k * N))
    return [x[:, j * N:(j + 1) * N] for j in range(k)]


def test_the_history_pools_its_last_k_windows_as_pooling_the_windows_does():
    wins = _noisy_inputs(8)
    hist = InputHistory(k=6, max_age_s=300.0)
    for j, x in enumerate(wins[:7]):
        assert hist.spectrum(10.0 * j) is (None if j < 6 else hist.spectrum(10.0 * j))
        assert hist.add(10.0 * j, 10.0 * j + 9.98, noise.input_periodogram(x, FS))
    assert len(hist) == 6  # the oldest of the seven left
    got = hist.spectrum(70.0)
    # Unsmoothed across frequency: the refinement given a history drops its residual floor and needs the fine structure.
    want = noise.pooled_spectrum([noise.input_periodogram(x, FS) for x in wins[1:7]], smooth_hz=0.0)
    assert got.n_windows == 6
    np.testing.assert_array_equal(got.freqs, want.freqs)
    np.testing.assert_array_equal(got.s, want.s)
    assert got is hist.spectrum(70.0)  # the same windows: the pooled spectrum is not computed again


def test_overlapping_stale_and_later_windows_are_not_pooled():
    wins = _noisy_inputs(7)
    g = [noise.input_periodogram(x, FS) for x in wins]
    hist = InputHistory(k=3, max_age_s=35.0)
    assert hist.add(0.0, 9.98, g[0])
    assert not hist.add(5.0, 14.98, g[1])  # overlaps the newest held: its noise would count twice
    for j in (1, 2, 3):
        assert hist.add(10.0 * j, 10.0 * j + 9.98, g[j])
    assert len(hist) == 3
    assert hist.spectrum(40.0).n_windows == 3  # windows starting at 10, 20, 30 s
    assert hist.spectrum(30.0) is None  # the window starting at 30 s has not ended by then
    assert hist.spectrum(50.0) is None  # the one starting at 10 s began more than 35 s before
    # Another sample rate restarts the history.
    other = noise.input_periodogram(signal.resample(wins[4], 2 * N, axis=1), 2 * FS)
    assert hist.add(40.0, 49.99, other) and len(hist) == 1


def test_windows_short_of_frames_pool_with_the_others():
    """A window missing frames at its ends (10 % here, what the service accepts) has another bin spacing: it is
    interpolated, not refused, and kept by the history.  (Measured here: 3.6 % summed difference from the full
    windows' spectrum below 5 Hz, where two independent sets of six windows differ by 20 %.)"""
    wins = _noisy_inputs(6)
    full = noise.pooled_spectrum([noise.input_periodogram(x, FS) for x in wins])
    short = noise.pooled_spectrum([noise.input_periodogram(x[:, :N - 50] if j % 2 == 0 else x, FS)
                                   for j, x in enumerate(wins)])
    m = min(full.freqs.size, short.freqs.size)
    np.testing.assert_allclose(short.freqs[:m], full.freqs[:m])  # the last window's bins: a full one here
    below = full.freqs[:m] < noise.FLOOR_FROM_HZ
    assert short.n_windows == 6
    rel = np.abs(short.s[:m][below, 0, 0] - full.s[:m][below, 0, 0]).sum() / np.abs(full.s[:m][below, 0, 0]).sum()
    assert rel < 0.05, rel
    hist = InputHistory(k=2)
    assert hist.add(0.0, 8.98, noise.input_periodogram(wins[0][:, :N - 50], FS))
    assert hist.add(10.0, 19.98, noise.input_periodogram(wins[1], FS)) and len(hist) == 2
    with pytest.raises(ValueError, match="sample rate"):
        noise.pooled_spectrum([noise.input_periodogram(wins[0], FS), noise.input_periodogram(wins[1], 2 * FS)])


def _with_noise(w: Window, seed: int, v_rel: float = 1e-3, th_rad: float = 1e-3) -> Window:
    rng = np.random.default_rng(seed)
    return Window(w.t, w.V + v_rel * rng.standard_normal(w.t.size), w.theta + th_rad * rng.standard_normal(w.t.size),
                  w.P, w.Q, f0=w.f0, bus=w.bus)


def test_identify_says_when_its_refinement_used_the_history():
    """Noisy V and θ: the refinement takes the history's spectrum and says so; exact inputs: the same D as
    without it and no mark (the refinement does not run)."""
    rec = equation_window(seed=4, fs=FS, fine=4, duration=70.0)
    pieces = [slice(j * N, (j + 1) * N) for j in range(7)]
    windows = [Window(rec.t[s], rec.V[s], rec.theta[s], rec.P[s], rec.Q[s], f0=rec.f0, bus="b") for s in pieces]
    noisy = [_with_noise(w, seed=j) for j, w in enumerate(windows)]
    hist = InputHistory()
    for w in noisy[:6]:
        assert hist.add(float(w.t[0]), float(w.t[-1]), input_periodogram(w))
    spectrum = hist.spectrum(float(noisy[6].t[0]))
    alone = identify(noisy[6])
    pooled = identify(noisy[6], input_spectrum=spectrum)
    assert "input_spectrum_windows" not in alone.quality and "weighted_chi2" in alone.quality
    assert pooled.quality["input_spectrum_windows"] == 6.0
    assert not np.array_equal(pooled.d, alone.d)  # the smoother's spectrum changed, so did D
    assert np.all(np.abs(pooled.d / D_TRUE - 1) < 0.25), pooled.d
    exact = identify(windows[6], input_spectrum=spectrum)
    np.testing.assert_array_equal(exact.d, identify(windows[6]).d)
    assert "input_spectrum_windows" not in exact.quality


def test_given_a_history_the_refinement_whitens_in_time_below_5_hz_without_the_residual_floor(monkeypatch):
    """At 100 frames/s the window's own refinement fits per frequency up to 4 Hz (a tenth of the rate capped at 4 Hz since
    stop 49) with S's diagonal floored by the residual; given a history's spectrum it whitens in the time domain on the bins below
    5 Hz (where that spectrum is known) without the floor (docs/numerics.md, "Stop 47"), redone with the floor where
    its χ² exceeds ``HISTORY_CHI2_MAX``; with ``HISTORY_BAND_HZ`` None it takes the window's own form."""
    fs, n = 100.0, 1000
    rec = equation_window(seed=4, fs=fs, fine=2, duration=70.0)
    windows = [_with_noise(Window(rec.t[j * n:(j + 1) * n], rec.V[j * n:(j + 1) * n], rec.theta[j * n:(j + 1) * n],
                                  rec.P[j * n:(j + 1) * n], rec.Q[j * n:(j + 1) * n], f0=rec.f0, bus="b"), seed=j)
               for j in range(7)]
    hist = InputHistory()
    for w in windows[:6]:
        hist.add(float(w.t[0]), float(w.t[-1]), input_periodogram(w))
    calls = []
    real = iw.build_weighting

    def spy(pb, d, input_error, white, band_hz=np.inf, form="spectral", residual_floor=True):
        calls.append((band_hz, form, residual_floor))
        return real(pb, d, input_error, white, band_hz, form, residual_floor)

    monkeypatch.setattr(iw, "build_weighting", spy)
    spectrum = hist.spectrum(float(windows[6].t[0]))
    alone = identify(windows[6])
    pooled = identify(windows[6], input_spectrum=spectrum)  # the module's defaults
    assert pooled.quality["input_spectrum_windows"] == 6.0 and "input_spectrum_windows" not in alone.quality
    assert np.all(np.abs(pooled.d / D_TRUE - 1) < 0.25), pooled.d
    (band_alone, form_alone, floor_alone), (band_pooled, form_pooled, floor_pooled) = calls[:2]
    assert (band_alone, form_alone, floor_alone) == (pytest.approx(4.0), "spectral", True)
    assert form_pooled == "temporal" and floor_pooled is False
    assert 5.0 - 1e-9 < band_pooled < 5.0  # the bin at 5 Hz itself is out: the history's spectrum is zero from there
    # Its χ² guard: above the threshold the fit is redone with the floor, in the same band and form.
    monkeypatch.setattr(iw, "HISTORY_CHI2_MAX", None)
    del calls[:]
    unguarded = identify(windows[6], input_spectrum=spectrum)
    assert [c[2] for c in calls] == [False]
    chi2 = unguarded.quality["weighted_chi2"]
    monkeypatch.setattr(iw, "HISTORY_CHI2_MAX", 0.5 * chi2)
    del calls[:]
    guarded = identify(windows[6], input_spectrum=spectrum)
    assert [c[2] for c in calls] == [False, True] and calls[1][:2] == calls[0][:2]
    assert not np.array_equal(guarded.d, unguarded.d)
    monkeypatch.setattr(iw, "HISTORY_CHI2_MAX", 2.0 * chi2)
    np.testing.assert_array_equal(identify(windows[6], input_spectrum=spectrum).d, unguarded.d)
    # Switched off, a history leaves the window's own form.
    monkeypatch.setattr(iw, "HISTORY_BAND_HZ", None)
    del calls[:]
    identify(windows[6], input_spectrum=spectrum)
    assert calls == [(pytest.approx(4.0), "spectral", True)]


def test_a_windows_staleness_is_near_one_against_its_own_process_and_large_against_another():
    """The deviance per term of the window's band periodograms against the history's spectrum plus the window's
    floor: about 1 for a window of the same process, far above :data:`HISTORY_STALE_MAX` when the signal is three
    times larger (another network's stiffness) or a third."""
    wins = _noisy_inputs(7)
    spectrum = noise.pooled_spectrum([noise.input_periodogram(x, FS) for x in wins[:6]], smooth_hz=0.0)
    own = staleness(noise.input_periodogram(wins[6], FS), spectrum)
    assert 0.3 < own < HISTORY_STALE_MAX
    for scale in (3.0, 1.0 / 3.0):
        other = staleness(noise.input_periodogram(wins[6] * scale, FS), spectrum)
        assert other > 3 * HISTORY_STALE_MAX, (scale, other)


def test_identify_refuses_a_stale_history_and_says_so():
    """A history whose inputs swing three times as far: the window is identified alone (the same D as without it),
    flagged ``input_history_stale`` with its staleness in ``quality``; its own history is used, unflagged."""
    rec = equation_window(seed=4, fs=FS, fine=4, duration=70.0)
    pieces = [slice(j * N, (j + 1) * N) for j in range(7)]
    windows = [Window(rec.t[s], rec.V[s], rec.theta[s], rec.P[s], rec.Q[s], f0=rec.f0, bus="b") for s in pieces]
    noisy = [_with_noise(w, seed=j) for j, w in enumerate(windows)]

    def history_of(ws):
        hist = InputHistory()
        for w in ws:
            assert hist.add(float(w.t[0]), float(w.t[-1]), input_periodogram(w))
        return hist.spectrum(float(noisy[6].t[0]))

    swung = [Window(w.t, w.V.mean() + 3 * (w.V - w.V.mean()), w.theta.mean() + 3 * (w.theta - w.theta.mean()), w.P,
                    w.Q, f0=w.f0, bus=w.bus) for w in noisy[:6]]
    alone = identify(noisy[6])
    own = identify(noisy[6], input_spectrum=history_of(noisy[:6]))
    stale = identify(noisy[6], input_spectrum=history_of(swung))
    assert own.quality["input_spectrum_windows"] == 6.0 and "input_history_stale" not in own.flags
    assert own.quality["input_history_staleness"] <= HISTORY_STALE_MAX
    assert "input_history_stale" in stale.flags and "input_spectrum_windows" not in stale.quality
    assert stale.quality["input_history_staleness"] > HISTORY_STALE_MAX
    np.testing.assert_array_equal(stale.d, alone.d)
    assert "input_history_staleness" not in alone.quality
    # θ as a PMU sends it, wrapped at ±π: the window's check unwraps it as the history's periodograms do.
    shift = np.pi - float(noisy[6].theta.mean())
    wrapped = [Window(w.t, w.V, np.angle(np.exp(1j * (w.theta + shift))), w.P, w.Q, f0=w.f0, bus=w.bus) for w in noisy]
    assert np.ptp(wrapped[6].theta) > np.pi  # it does wrap
    both = identify(wrapped[6], input_spectrum=history_of(wrapped[:6]))
    assert both.quality["input_history_staleness"] == pytest.approx(own.quality["input_history_staleness"], rel=1e-6)
    assert both.quality["input_spectrum_windows"] == 6.0
