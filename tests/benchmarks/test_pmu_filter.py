"""benchmarks.pmu_filter's noise model and the core's reading of a PMU's filtered noise (input_noise="measured")."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from aslm_core import noise, preprocess  # noqa: E402
from benchmarks import pmu_filter as pf  # noqa: E402


@pytest.mark.parametrize("fs", [25.0, 50.0, 100.0])
def test_the_reporting_filter_meets_its_envelope(fs):
    for shape in ("fs5", "5hz"):
        edge = pf.SHAPES[shape](fs)
        h = pf.reporting_filter(fs, edge)
        w, resp = signal.freqz(h, worN=8192, fs=pf.UP * fs)
        amp = np.abs(resp)
        assert np.abs(amp[w <= edge] - 1.0).max() <= pf.RIPPLE
        assert amp[w >= fs / 2].max() <= pf.STOP


def test_filtered_noise_has_the_white_density_in_the_passband_and_falls_above():
    fs, rng = 50.0, np.random.default_rng(4)
    x = np.concatenate([pf.filtered_noise(500, 2e-3, fs, "fs5", rng) for _ in range(40)])
    f, p = signal.welch(x, fs, nperseg=500)
    white = 2 * (2e-3) ** 2 / fs  # one-sided density of white noise of that std
    assert abs(np.mean(p[(f > 1) & (f < 9)]) / white - 1.0) < 0.1
    assert np.mean(p[(f > 22) & (f < 25)]) < 0.05 * white


def _floors(x4, fs, measured):
    est = noise.channel_floors(*x4, fs)
    flags = preprocess.measured_floors(est, np.stack(x4), fs) if measured else []
    return est, flags


@pytest.mark.parametrize("fs", [25.0, 30.0, 50.0, 100.0])
def test_measured_floors_read_a_filtered_channel_at_its_in_band_level(fs):
    """An M-class PMU's noise alone on all four channels: the band's median reads well below the in-band std and the
    floor rule takes V as exact; declared measured, every channel's floor is, in the median over 16 windows, within
    15 % of the in-band std (one window's ratio scatters by ~0.25 in power: ~34 degrees of freedom)."""
    rng = np.random.default_rng(int(fs))
    n = int(10 * fs)
    stds = (1e-3, 1e-3, 2e-3, 2e-3)
    keys = ("noise_v", "noise_theta", "noise_p", "noise_q")
    ratios = []
    for _ in range(16):
        x4 = [1.0 + pf.filtered_noise(n, stds[0], fs, "fs5", rng)] + [pf.filtered_noise(n, s, fs, "fs5", rng)
                                                                       for s in stds[1:]]
        auto, _ = _floors(x4, fs, False)
        assert auto["noise_v"] < 0.7 * stds[0] and not preprocess.white_floor(auto, "v")
        est, flags = _floors(x4, fs, True)
        assert flags == ["input_noise_filtered"] and preprocess.white_floor(est, "v") and est["inputs_measured"] == 1.0
        assert est["floor_plateau_dof"] == 2 * (20 - 3)  # 20 bins at 4–6 Hz in 10 s, three regressors
        ratios.append([est[k] / s for k, s in zip(keys, stds, strict=True)])
    med = np.median(ratios, axis=0)
    assert np.all(np.abs(med - 1.0) < 0.15), med


def test_measured_floors_leave_white_noise_as_it_is():
    fs, rng = 50.0, np.random.default_rng(9)
    x4 = [1.0 + 1e-3 * rng.standard_normal(500)] + [s * rng.standard_normal(500) for s in (1e-3, 2e-3, 2e-3)]
    auto, _ = _floors(x4, fs, False)
    est, flags = _floors(x4, fs, True)
    assert flags == [] and est["floor_plateau_ratio"] == 1.0
    for key in ("noise_v", "noise_theta", "noise_p", "noise_q"):
        assert est[key] == auto[key]


def test_the_cli_reads_an_m_class_recording_declared_measured(tmp_path):
    """`aslm identify --input-noise measured` on a recording whose noise an M-class filter shaped: the config says
    so, the flag names the filtered floor, and V's noise is read near its in-band std, where the default reads it
    low and takes V as exact.  (Accuracy over many windows: ``benchmarks.pmu_filter``.)"""
    import json
    import subprocess

    from aslm_sim.cases import make_case
    from service.files import write_window

    case = make_case(21, level=3, input_noise=False, fs=50.0)
    w = pf.noisy_window(case, 50.0, 1e-3, 1e-3, "fs5", np.random.default_rng(5))
    path = tmp_path / "m_class.csv"
    write_window(path, w)
    out = {}
    for mode in ("auto", "measured"):
        proc = subprocess.run([sys.executable, "-m", "service.cli", "identify", "--json", "--input-noise", mode,
                               str(path)], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        out[mode] = json.loads(proc.stdout)
    assert out["measured"]["config"]["input_noise"] == "measured" and out["auto"]["config"]["input_noise"] == "auto"
    assert "input_noise_filtered" in out["measured"]["flags"] and "input_noise_filtered" not in out["auto"]["flags"]
    inband = 1e-3 * float(np.mean(case.clean.V))
    assert not preprocess.white_floor(out["auto"]["quality"], "v") and out["auto"]["quality"]["noise_v"] < 0.7 * inband
    assert preprocess.white_floor(out["measured"]["quality"], "v")
    assert 0.8 < out["measured"]["quality"]["noise_v"] / inband < 1.6


def test_the_confirmation_rule_fails_on_each_criterion():
    def cell(bias=0.0, sigma=0.05, cover=0.94, n=300):
        return {"n": n, "bias": [bias] * 4, "sigma": [sigma] * 4, "coverage_95": [cover] * 4,
                "noise_v_over_inband": 1.0, "exact_by_floor": 1.0, "flagged": 0.5, "filtered_flag": 1.0}

    def cells(**measured):
        cls = "0.1 % / 1e-3 rad"
        white = cell()
        return {"50|2": {f"{cls}|white|auto": white, f"{cls}|white|measured": dict(white),
                         f"{cls}|fs5|auto": cell(bias=-0.5), f"{cls}|fs5|measured": cell(**measured)}}

    assert all(pf.verdict(cells())["met"].values())
    assert not pf.verdict(cells(bias=0.03))["met"]["bias"]  # outside, and its interval too
    assert not pf.verdict(cells(sigma=0.06))["met"]["sigma"]  # 1.2 × the white rows'
    assert not pf.verdict(cells(cover=0.86))["met"]["coverage"]
    c = cells()
    c["50|2"]["0.1 % / 1e-3 rad|white|measured"]["bias"] = [0.001] * 4
    assert not pf.verdict(c)["met"]["white_unchanged"]


def test_the_diagnosis_rule_reads_false_findings_and_power():
    def run(consistent=None, named=None, n=120):
        cell = {"n": n, "verdicts": {"consistent": consistent if consistent is not None else n}, "named_effect": named}
        return {"cells": [cell]}

    def reader(white_ff=2, measured_ff=4, white_named=50, measured_named=45):
        runs = {}
        for cls in ("1e-3", "3e-4"):
            runs[f"diagnosis_rates_seed84_pmu_white_{cls}"] = run(120 - white_ff)
            runs[f"diagnosis_rates_seed84_pmu_fs5_{cls}"] = run(0)
            runs[f"diagnosis_rates_seed84_pmu_fs5_measured_{cls}"] = run(120 - measured_ff)
        runs["diagnosis_rates_seed85_pmu_white_second_motor"] = run(named=white_named, n=60)
        runs["diagnosis_rates_seed85_pmu_fs5_second_motor"] = run(named=measured_named, n=60)
        return runs.__getitem__

    assert pf.diagnosis_verdict(reader())["met"] == {"clean": True, "power": True}
    assert not pf.diagnosis_verdict(reader(measured_ff=6))["met"]["clean"]
    assert not pf.diagnosis_verdict(reader(measured_named=43))["met"]["power"]

    def both(ff_5hz=4, named_5hz=45):  # the third confirmation's two shapes, the 5hz one judged as the fs5 one
        fs5 = reader()
        runs = {}
        for cls in ("1e-3", "3e-4"):
            runs[f"diagnosis_rates_seed84_pmu_5hz_{cls}"] = run(0)
            runs[f"diagnosis_rates_seed84_pmu_5hz_measured_{cls}"] = run(120 - ff_5hz)
        runs["diagnosis_rates_seed85_pmu_5hz_second_motor"] = run(named=named_5hz, n=60)
        return lambda name: runs[name] if name in runs else fs5(name)

    shapes = ("fs5", "5hz")
    assert pf.diagnosis_verdict(both(), shapes=shapes)["met"] == {"clean": True, "power": True}
    assert pf.diagnosis_verdict(both(ff_5hz=6), shapes=shapes)["met"] == {"clean": False, "power": True}
    assert pf.diagnosis_verdict(both(named_5hz=43), shapes=shapes)["met"] == {"clean": True, "power": False}


def test_the_andes_check_compares_the_measured_rows_with_the_white_ones():
    from benchmarks import andes_rates as ar

    def run(bias, cover=0.94):
        return {"cells": [{"class": c, "fs": fs, "bias": [bias] * 4, "cover": [cover] * 4}
                          for c in ("exact", "pmu003", "pmu01") for fs in (100.0, 50.0, 25.0)]}

    def reader(measured_bias=-0.012, cover=0.94):
        runs = {"andes_rates_pmu_white_auto": run(-0.01), "andes_rates_pmu_fs5_auto": run(-0.5),
                "andes_rates_pmu_fs5_measured": run(measured_bias, cover)}
        return runs.__getitem__

    assert ar.pmu_check(reader())["met"]
    assert not ar.pmu_check(reader(measured_bias=-0.025))["met"]  # 1.5 points off the white rows' at 0.03 %
    assert not ar.pmu_check(reader(cover=0.85))["met"]


def test_the_diagnosis_reads_an_m_class_pmus_model_true_window_declared_measured():
    """A model-true window whose four channels carry an M-class PMU's noise: the default holds the residual against a
    floor read on the filter's roll-off and calls it unexplained; declared measured, consistent.  (Rates over many
    windows: benchmarks.diagnosis_rates --pmu, DIAGNOSIS_RULE.)"""
    from aslm_core.diagnosis import DiagnosisConfig, diagnose
    from benchmarks import common

    case = common.cases(1, level=2, seed=86, fs=50.0)[0]
    w = pf.noisy_window(case, 50.0, 1e-3, 1e-3, "fs5", np.random.default_rng(86))
    assert diagnose(w).verdict == "unexplained"
    assert diagnose(w, config=DiagnosisConfig(input_noise="measured")).verdict == "consistent"


def test_the_incoherent_level_reads_the_noise_under_a_coherent_signal():
    """V carrying a signal 10 × its noise at 3–7 Hz that θ, P and Q also carry: V's periodogram at 4–6 Hz is two
    orders above the noise, the part the others do not explain is the noise (median over 20 windows within 10 %)."""
    fs, n, rng = 50.0, 500, np.random.default_rng(11)
    sos = signal.butter(4, [3.0, 7.0], btype="band", fs=fs, output="sos")
    got, plain = [], []
    for _ in range(20):
        s = signal.sosfilt(sos, rng.standard_normal(n + 200))[200:]
        s *= 10.0 / np.std(s)
        x = np.stack([s, 0.5 * s, -2.0 * s, s]) + rng.standard_normal((4, n))
        level, dof = noise.incoherent_level(x, fs)
        got.append(level / (2.0 / fs))
        f, p = noise.periodogram(x[0], fs)
        plain.append(np.median(p[(f >= 4) & (f < 6)]) / (2.0 / fs))
        assert dof == 2 * (20 - 3)
    assert abs(np.median(got) - 1.0) < 0.1 and np.median(plain) > 30.0


def test_measured_floors_leave_a_window_too_short_for_the_regression_as_read():
    """Fewer bins at 4–6 Hz than regressors (a 1.5 s window): the floors stay the band's medians, no flag, ratio 1."""
    fs, rng = 50.0, np.random.default_rng(2)
    n = 75
    x4 = [1.0 + pf.filtered_noise(n, 1e-3, fs, "fs5", rng)] + [pf.filtered_noise(n, s, fs, "fs5", rng)
                                                               for s in (1e-3, 2e-3, 2e-3)]
    auto, _ = _floors(x4, fs, False)
    assert not preprocess.white_floor(auto, "v")  # the band falls: the regression would be asked for
    est, flags = _floors(x4, fs, True)
    assert np.isnan(noise.incoherent_level(np.stack(x4), fs)[0])
    assert flags == [] and est["floor_plateau_ratio"] == 1.0 and "floor_plateau_dof" not in est
    assert all(est[k] == auto[k] for k in ("noise_v", "noise_theta", "noise_p", "noise_q"))
    assert preprocess.white_floor(est, "v")  # declared measured: never exact


def test_measured_floors_read_theta_at_its_own_level_where_v_holds_more_signal_above_5_hz():
    """V carries, besides its filtered noise, content at 12–24 Hz the filter did not make (coherent with P), which
    lifts V's band median: V's ratio applied to θ reads θ low (stop 55), θ's own incoherent part reads it right."""
    fs, n = 50.0, 500
    rng = np.random.default_rng(56)
    b = signal.firwin(101, [12.0, 24.0], pass_zero=False, fs=fs)
    own, borrowed = [], []
    for _ in range(16):
        x4 = [1.0 + pf.filtered_noise(n, 1e-3, fs, "fs5", rng)] + [pf.filtered_noise(n, s, fs, "fs5", rng)
                                                                   for s in (1e-3, 2e-3, 2e-3)]
        s = signal.lfilter(b, 1.0, rng.standard_normal(n + 100))[100:] * 2e-3
        x4[0] = x4[0] + s
        x4[2] = x4[2] + 0.5 * s
        est, flags = _floors(x4, fs, True)
        assert flags == ["input_noise_filtered"] and est["floor_ratio_theta"] > 1.0
        own.append(est["noise_theta"] / 1e-3)
        borrowed.append(est["noise_theta"] / math.sqrt(est["floor_ratio_theta"]) * math.sqrt(est["floor_ratio_v"]) / 1e-3)
    assert abs(np.median(own) - 1.0) < 0.15, np.median(own)
    assert np.median(borrowed) < 0.75, np.median(borrowed)


def test_the_diagnosis_brings_each_floor_to_its_in_band_level():
    """A PMU's filtered noise alone on all four channels, declared measured: the diagnosis's scales (the identifier's
    raises) bring each channel's band median to its in-band level (in the median over 16 windows within 15 %), with
    the raises' degrees of freedom; white noise gets no scale."""
    from aslm_core import Window
    from aslm_core.diagnosis.segment import filter_scales

    fs, n = 50.0, 500
    rng = np.random.default_rng(7)
    stds = (1e-3, 1e-3, 2e-3, 3e-3)
    t = np.arange(n) / fs
    got = []
    for _ in range(16):
        x4 = [1.0 + pf.filtered_noise(n, stds[0], fs, "fs5", rng)] + [pf.filtered_noise(n, s, fs, "fs5", rng)
                                                                       for s in stds[1:]]
        raw = preprocess.prepare(Window(t=t, V=x4[0], theta=x4[1], P=0.5 + x4[2], Q=0.2 + x4[3], f0=50.0),
                                 floors=True, input_noise="measured")
        scales = filter_scales(raw)
        assert set(scales) == {"v", "theta", "p", "q"} and all(d == 2 * (20 - 3) for _, d in scales.values())
        assert all(scales[c][0] == raw.noise[f"floor_ratio_{c}"] for c in scales)
        auto = noise.channel_floors(*x4, fs)
        got.append([auto[f"noise_{c}"] * math.sqrt(scales[c][0]) / s
                    for c, s in zip(("v", "theta", "p", "q"), stds, strict=True)])
    med = np.median(got, axis=0)
    assert np.all(np.abs(med - 1.0) < 0.15), med
    white = [1.0 + 1e-3 * rng.standard_normal(n)] + [s * rng.standard_normal(n) for s in stds[1:]]
    raw = preprocess.prepare(Window(t=t, V=white[0], theta=white[1], P=0.5 + white[2], Q=0.2 + white[3], f0=50.0),
                             floors=True, input_noise="measured")
    assert filter_scales(raw) == {}


def test_the_andes_diagnosis_rule_compares_the_measured_runs_with_the_white_ones():
    from benchmarks import diagnosis_rates as dr

    def reader(measured_ff=3, white_ff=1):
        ff = {"white_auto": white_ff, "fs5_measured": measured_ff, "fs5_auto": 200}
        return lambda name: {"cells": [{"n": 210, "verdicts": {"consistent": 210 - ff[k]}}
                                       for k in ff if f"_pmu_{k}_" in name]}

    assert dr.andes_pmu_verdict(reader())["met"]
    assert dr.andes_pmu_verdict(reader(measured_ff=4, white_ff=1))["met"] is True
    assert not dr.andes_pmu_verdict(reader(measured_ff=5, white_ff=1))["met"]
    assert dr.andes_pmu_verdict(reader())["classes"]["1e-3"]["fs5_auto"]["false_findings"] == 200


def test_the_score_width_is_the_mean_square_over_windows_and_candidates():
    from benchmarks.diagnosis_score_width import CANDIDATES, width

    rows = [{"z": {n: 1.0 for n in CANDIDATES}}, {"z": {CANDIDATES[0]: 2.0, "exponential_static": 9.0}}]
    assert width(rows) == pytest.approx((6 * 1.0 + 4.0) / 12)
