"""The load's own fluctuation in the simulation bench (aslm_sim.own, make_cases(own_sigma=...))."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from aslm_core import identify
from aslm_sim.cases import make_cases
from aslm_sim.network import forcing_filter
from aslm_sim.own import OWN_Q_PER_P, OWN_SHAPES, own_process, window_covariance

# make_cases(3, level=2, seed=5) before the own fluctuation existed (computed with that code): Σ V and Σ P of
# case 0's noisy window, Σ Q of case 2's clean window.
PINNED = (996.5719964826169, 652.2773149129437, 459.98860440106836)


@pytest.fixture(scope="module")
def pair():
    off = make_cases(3, level=2, seed=5, input_noise=False)
    on = make_cases(3, level=2, seed=5, input_noise=False, own_sigma=0.01)
    return off, on


def test_same_seed_gives_the_cases_of_before_when_off():
    cs = make_cases(3, level=2, seed=5)
    got = (float(np.sum(cs[0].window.V)), float(np.sum(cs[0].window.P)), float(np.sum(cs[2].clean.Q)))
    np.testing.assert_allclose(got, PINNED, rtol=1e-12)


def test_off_is_the_default_and_draws_nothing(pair):
    off, _ = pair
    again = make_cases(3, level=2, seed=5, input_noise=False, own_sigma=0.0)
    for a, b in zip(off, again, strict=True):
        assert np.array_equal(a.window.P, b.window.P) and np.array_equal(a.window.V, b.window.V)
        assert "P_own" not in b.states and "own_sigma" not in b.window.meta


def test_own_fluctuation_moves_p_and_through_the_network_v_with_the_same_load(pair):
    off, on = pair
    for a, b in zip(off, on, strict=True):
        assert a.truth == b.truth
        p_load = b.truth.power(1.0)[0]
        assert np.std(b.states["P_own"]) == pytest.approx(0.01 * p_load, rel=0.35)
        np.testing.assert_allclose(b.states["Q_own"], OWN_Q_PER_P * b.states["P_own"])
        # The measured P carries it: the clean P minus the own ΔP is close to the grid-driven P.
        assert np.std(b.clean.P - a.clean.P) > 0.5 * np.std(b.states["P_own"])
        # Closed loop: V moves with it (a little: the network is stiff against one load).
        assert not np.allclose(b.clean.V, a.clean.V, rtol=0, atol=1e-7)


@pytest.mark.parametrize("shape", OWN_SHAPES)
def test_every_shape_is_unit_variance_and_shaped_as_named(shape):
    fs = 1000.0
    sos, gain = forcing_filter(fs)
    x = own_process(np.random.default_rng(1), shape, 60_000, fs, sos, gain)
    assert x.mean() == pytest.approx(0.0, abs=1e-9) and x.std() == pytest.approx(1.0)
    f, pxx = signal.welch(x, fs, nperseg=8192)
    if shape == "switching":
        assert np.mean(np.diff(x) == 0.0) > 0.8  # steps
    if shape == "pink":
        sel = (f > 0.2) & (f < 4.0)
        slope = np.polyfit(np.log(f[sel]), np.log(pxx[sel]), 1)[0]
        assert slope == pytest.approx(-1.0, abs=0.3)
    if shape == "lowpass":
        assert pxx[f > 8.0].max() < 1e-4 * pxx[f < 1.0].max()
    if shape == "ramp":
        assert np.mean(np.abs(np.diff(x, 2)) < 1e-9) > 0.99  # straight lines between few breakpoints


def test_window_covariance_is_of_the_demeaned_process_at_unit_variance():
    cov = window_covariance("lowpass", 200, 100.0, 300, seed=4)
    assert np.mean(np.diag(cov)) == pytest.approx(1.0)
    np.testing.assert_allclose(cov.sum(axis=1), 0.0, atol=1e-9)  # each window's mean removed
    assert cov[0, 5] > 0.5 * cov[0, 0]  # 2 Hz low-passed: correlated over 50 ms


def test_window_covariance_has_the_windows_full_rank_and_matches_many_windows():
    # Fewer windows than samples: their sample covariance would have rank 49 of 199, and a bound computed with it
    # finds own-free directions the switching process does not have.
    cov = window_covariance("switching", 200, 100.0, 50, seed=4)
    ev = np.linalg.eigvalsh(cov)
    assert np.sum(ev > 1e-8 * ev.max()) == 199  # all but the removed mean
    from aslm_sim.network import forcing_filter

    sos, gain = forcing_filter(100.0)
    w = own_process(np.random.default_rng(5), "switching", 200 * 2000, 100.0, sos, gain).reshape(2000, 200)
    w = w - w.mean(axis=1, keepdims=True)
    many = w.T @ w / 2000
    many /= np.mean(np.diag(many))
    assert np.abs(cov - many).max() < 0.15


def test_unknown_shape_is_a_clear_error():
    with pytest.raises(ValueError, match="own-fluctuation shape"):
        make_cases(1, own_sigma=0.01, own_shape="square")


def test_excitation_share_is_small_when_the_own_fluctuation_dominates(pair):
    off, on = pair
    for a, b in zip(off, on, strict=True):
        ra, rb = identify(a.window), identify(b.window)
        assert ra.quality["excitation_share_p"] > 0.9
        assert rb.quality["excitation_share_p"] < 0.4
        true_ratio = np.std(b.states["P_own"]) / np.std(b.clean.P)
        assert rb.quality["own_ratio_p"] == pytest.approx(true_ratio, abs=0.15)
        assert "unexplained_fluctuation" in rb.flags and "unexplained_fluctuation" not in ra.flags


def test_own_q_coherence_sets_the_correlation_of_the_own_dq_with_dp_and_keeps_dp(pair):
    _, on = pair
    partly = make_cases(3, level=2, seed=5, input_noise=False, own_sigma=0.01, own_q_coherence=0.5)
    for full, half in zip(on, partly, strict=True):
        np.testing.assert_array_equal(full.states["P_own"], half.states["P_own"])
        # ρ = 1 is ΔQ = 0.33·ΔP exactly, as before the knob.
        np.testing.assert_allclose(full.states["Q_own"], OWN_Q_PER_P * full.states["P_own"], rtol=1e-12)
        r = np.corrcoef(half.states["P_own"], half.states["Q_own"])[0, 1]
        assert 0.2 < r < 0.8  # 0.5 in expectation; a 10 s window of a 2 Hz process scatters


def test_the_own_spectrum_indicator_reads_switching_slower_than_a_2hz_process():
    # Issue 20's excitation indicator: the own fluctuation's spectrum in the result's quality.  Step-like
    # switching (1 s dwell) has most of its variance below 0.5 Hz, the 2 Hz low-passed process near 1 Hz.
    med = {}
    for shape in ("switching", "lowpass"):
        cs = make_cases(6, level=2, seed=5, input_noise=False, own_sigma=0.01, own_shape=shape)
        med[shape] = float(np.median([identify(c.window).quality["own_median_hz_p"] for c in cs]))
    assert med["switching"] < 0.6 and 0.8 < med["lowpass"] < 1.6, med
