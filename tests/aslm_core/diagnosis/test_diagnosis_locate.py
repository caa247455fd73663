"""Noise floor, band excess, coherence, time segments and playback on signals with a known answer."""

from __future__ import annotations

import numpy as np

from aslm_core.diagnosis.locate import band_excess, coherence, locate, noise_floor, time_segments
from aslm_core.diagnosis.playback import model_power, playback

FS = 100.0


def test_noise_floor_recovers_white_noise_sigma():
    rng = np.random.default_rng(0)
    for sigma in (1e-5, 3e-3):
        r = sigma * rng.standard_normal(2000)
        fl = noise_floor(r, FS)
        assert abs(fl["sigma"] / sigma - 1.0) < 0.06


def test_floor_ignores_low_frequency_signal_and_band_test_finds_it():
    rng = np.random.default_rng(1)
    t = np.arange(1000) / FS
    noise = 1e-3 * rng.standard_normal(t.size)
    tone = 1.5e-3 * np.sin(2 * np.pi * 0.8 * t)
    fl = noise_floor(noise + tone, FS)
    assert abs(fl["sigma"] / 1e-3 - 1.0) < 0.1
    bands = {tuple(b["band"]): b for b in band_excess(noise + tone, FS, fl)}
    assert bands[(0.5, 1.0)]["significant"]
    assert not bands[(2.0, 5.0)]["significant"]
    assert not any(b["significant"] for b in band_excess(noise, FS, noise_floor(noise, FS)))


def test_white_noise_false_alarm_rate_is_small():
    rng = np.random.default_rng(2)
    t = np.arange(900) / FS
    hits = 0
    for _ in range(100):
        rp, rq = 1e-3 * rng.standard_normal((2, t.size))
        hits += bool(locate(rp, rq, t, FS, {})["channels"])
    assert hits <= 3


def test_band_test_holds_its_level_at_25_frames_per_second():
    # At 25 frames/s the floor is the median of 61 bins: counted as a mean's 2·M degrees of freedom the test flags
    # white noise at over twice its level (1.2 % of these draws; 0.37 % as a median's 2·M·ln² 2).
    from scipy import stats

    fs, n, draws, level = 25.0, 223, 3000, 0.01 / 8
    rng = np.random.default_rng(11)
    hits = {"median": 0, "mean": 0}
    for _ in range(draws):
        r = rng.standard_normal(n)
        fl = noise_floor(r, fs)
        assert fl["dof"] == 2.0 * fl["bins"] * np.log(2.0) ** 2
        bands = band_excess(r, fs, fl)
        hits["median"] += any(b["significant"] for b in bands)
        f = np.fft.rfftfreq(n, 1.0 / fs)
        hits["mean"] += any(stats.f.sf(b["ratio"], 2 * int(((f >= b["band"][0]) & (f < b["band"][1])).sum()),
                                       2 * fl["bins"]) < level for b in bands)
    se = (0.005 * 0.995 / draws) ** 0.5
    assert hits["median"] / draws <= 0.005 + 2 * se
    assert hits["mean"] / draws > 0.005 + 3 * se


def test_coherence_with_the_driver_that_made_the_residual():
    rng = np.random.default_rng(3)
    n = 1000
    drv = np.convolve(rng.standard_normal(n + 50), np.ones(25) / 25, mode="same")[:n]
    other = np.convolve(rng.standard_normal(n + 50), np.ones(25) / 25, mode="same")[:n]
    r = 0.5 * drv + 0.02 * rng.standard_normal(n)
    c = coherence(r, {"drv": drv, "other": other}, FS)
    assert c["drv"]["mean"] > 0.8
    assert c["other"]["mean"] < c["threshold"]


def test_time_segments_bracket_a_burst():
    rng = np.random.default_rng(4)
    t = np.arange(1000) / FS
    r = 1e-3 * rng.standard_normal(t.size)
    burst = (t > 4.0) & (t < 6.0)
    r[burst] += 4e-3 * np.sin(2 * np.pi * 1.0 * t[burst])
    segs = time_segments(r, t, FS, noise_floor(r, FS))
    assert segs, "burst not found"
    assert all(3.0 < s[0] and s[1] < 7.0 for s in segs)
    assert any(s[0] < 4.6 and s[1] > 5.4 for s in segs)


def test_playback_of_the_generating_model_leaves_no_residual(eq_window):
    from tests.conftest import D_TRUE, ZIP_P, ZIP_Q

    model = {"dynamic": dict(zip(("a", "b", "H2", "Tm"), D_TRUE, strict=True)),
             "static": {"Pz": ZIP_P[0], "Pi": ZIP_P[1], "Pp": ZIP_P[2], "Qz": ZIP_Q[0], "Qi": ZIP_Q[1], "Qp": ZIP_Q[2]}}
    pb = playback(eq_window, model)
    k0 = 100  # after the initial-state transient
    assert np.max(np.abs(pb.rp[k0:])) < 5e-3 * np.std(eq_window.P)
    assert np.max(np.abs(pb.rq[k0:])) < 5e-3 * np.std(eq_window.Q)
    wrong = {**model, "dynamic": {**model["dynamic"], "H2": 2.5}}
    p, _ = model_power(eq_window.V, eq_window.theta, wrong, eq_window.dt, 50.0)
    assert np.std((eq_window.P - p)[k0:]) > 0.01 * np.std(eq_window.P)
