"""Tests of the synthetic generator: truth, steady state, noise, physics consistency, fleet, fault."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from aslm_core.params import dynamic_bounds, equilibrium_margin
from aslm_sim import network
from aslm_sim.cases import SyntheticCase, make_case, make_cases
from aslm_sim.faults import large_disturbance
from aslm_sim.fleet import SyntheticFleet
from aslm_sim.noise import NOISE_LEVELS, SNR_SPREAD_DB
from aslm_sim.truth import random_truth


@pytest.fixture(scope="module")
def clean_cases() -> list[SyntheticCase]:
    return make_cases(3, seed=11)


def test_truth_in_box_feasible_and_consistent():
    rng = np.random.default_rng(123)
    for _ in range(200):
        tr = random_truth(rng)
        p_tot, q_tot = tr.power(1.0)
        lo, hi = dynamic_bounds(p_tot)
        assert np.all(tr.d >= lo) and np.all(tr.d <= hi), tr
        # Equilibrium with margin during a sag to 0.8 pu (breakdown torque > 1.1·Tm).
        assert tr.a * 0.8**2 > 1.1 * 2.0 * tr.b * tr.Tm
        assert equilibrium_margin(tr.d, 0.8) > 0.0
        # Transformation (eq. 4): a, b from X, X', Td0 and a/b = 1/X' - 1/X.
        assert tr.a == pytest.approx((tr.X / tr.Xp - 1.0) / (tr.Td0 * tr.Xp), rel=1e-12)
        assert tr.b == pytest.approx(tr.X / (tr.Td0 * tr.Xp), rel=1e-12)
        assert tr.a / tr.b == pytest.approx(1.0 / tr.Xp - 1.0 / tr.X, rel=1e-12)
        assert 0.0 < tr.Xp < tr.X
        # Motor share of P and overall power factor as documented.
        share = tr.Tm / p_tot
        assert 0.3 - 1e-9 <= share <= 0.7 + 1e-9
        pf = p_tot / math.hypot(p_tot, q_tot)
        assert 0.9 - 1e-9 <= pf <= 0.98 + 1e-9
        assert tr.Pz + tr.Pi + tr.Pp == pytest.approx(p_tot - tr.Tm, rel=1e-12)
        assert tr.static_identifiable["Qz"] == pytest.approx(tr.Qz + 1.0 / tr.Xp)
        assert 0.0 < tr.slip0(1.0) < 0.05
    d = tr.to_dict()
    assert d["dynamic"] == tr.dynamic and d["static"]["Qp"] == tr.Qp


def test_initial_state_is_a_steady_state():
    rng = np.random.default_rng(5)
    for _ in range(10):
        tr = random_truth(rng)
        net = network.draw_network(rng, tr, 50.0)
        p, x0, vl0 = network.steady_state(tr, net)
        v, vh, il, dx = network.solve_at(p, x0, 0.0, 0.0, False, vl0)
        assert abs(v - vl0) < 1e-12  # the network solution is the power-flow one
        assert abs(abs(v) - net["V_L"]) < 1e-12
        assert np.max(np.abs(dx)) < 1e-9, dx
        # The load draws its steady-state power through the feeder.
        s_load = v * np.conj(il)
        p_ss, q_ss = network.static_load(tr, np.array([abs(v)]))[0].real, network.static_load(tr, np.array([abs(v)]))[0].imag
        assert s_load.real == pytest.approx(p_ss, rel=1e-10)
        assert s_load.imag == pytest.approx(q_ss, rel=1e-9, abs=1e-10)
        # ...and the discretised system stays put without forcing.
        m, k, h = network.step_grid(100.0, network.MAX_STEP_S, network.MAX_FORCING_STEP_S)
        out_v, out_s, _, _, _ = network.simulate(
            p[None], x0[None], np.array([vl0]), np.zeros((1, 2, 200 * m + 1)), h, k, m, 0, 200,
            -np.ones((1, 2), dtype=np.int64),
        )
        assert np.max(np.abs(out_v[0] - vl0)) < 1e-10
        assert np.max(np.abs(out_s[0] - s_load)) < 1e-9 * abs(s_load)


def test_ambient_record_moves(clean_cases):
    for c in clean_cases:
        w = c.clean
        assert w.n == 1000 and w.t[0] == 0.0 and w.dt == pytest.approx(0.01)
        assert c.window is c.clean and c.snr_db == math.inf
        dv = np.std(w.V) / np.mean(w.V)
        assert 2e-4 < dv < 1e-2  # ambient, not a flat line and not a disturbance
        assert np.std(w.P) / np.mean(w.P) > 1e-4
        assert np.std(w.theta) > 1e-4
        assert abs(np.mean(w.f) - 50.0) < 0.01


@pytest.mark.parametrize("level", [1, 2, 3])
def test_snr_per_level(level):
    cases = make_cases(4, level=level, seed=3)
    for c in cases:
        assert c.level == level
        assert abs(c.snr_db - NOISE_LEVELS[level]) <= 2.5
        target = c.clean.meta["snr_target_db"]
        for ch in ("P", "Q", "V", "theta"):
            assert abs(c.states["snr"][ch] - target) < 1.0
        # Independent recomputation of eq. 10 for P.
        y = c.clean.P - c.clean.P.mean()
        e = c.window.P - c.clean.P
        assert 10 * np.log10(np.sum(y * y) / np.sum(e * e)) == pytest.approx(c.states["snr"]["P"])
        assert not np.allclose(c.window.V, c.clean.V)
    # Same seed, other level: same clean record (noise streams are separate).
    other = make_cases(1, level=1 if level != 1 else 3, seed=3)[0]
    np.testing.assert_array_equal(other.clean.P, cases[0].clean.P)


def test_input_noise_switch_and_determinism():
    a = make_case(7, snr_db=20.0, input_noise=False)
    b = make_case(7, snr_db=20.0, input_noise=False)
    np.testing.assert_array_equal(a.window.P, b.window.P)
    np.testing.assert_array_equal(a.window.V, a.clean.V)
    np.testing.assert_array_equal(a.window.theta, a.clean.theta)
    assert not np.array_equal(a.window.P, a.clean.P)
    c = make_case(8, snr_db=20.0)
    assert c.truth != a.truth
    with pytest.raises(ValueError):
        make_cases(1, level=1, snr_db=20.0)


def test_recorded_power_equals_zip_plus_motor(clean_cases):
    for c in clean_cases:
        w, tr, st = c.clean, c.truth, c.states
        v = w.V * np.exp(1j * w.theta)
        vd, vq = v.real, v.imag
        p_zip = tr.Pz * w.V**2 + tr.Pi * w.V + tr.Pp
        q_zip = tr.Qz * w.V**2 + tr.Qi * w.V + tr.Qp
        p_im = (st["Ed"] * vq - st["Eq"] * vd) / tr.Xp  # eq. 3
        q_im = (w.V**2 - vd * st["Ed"] - vq * st["Eq"]) / tr.Xp
        scale = np.mean(w.P)
        assert np.max(np.abs(w.P - (p_zip + p_im))) < 1e-9 * scale
        assert np.max(np.abs(w.Q - (q_zip + q_im))) < 1e-9 * scale


def test_transformed_model_reproduces_original_motor_power(clean_cases):
    c = clean_cases[0]
    w, tr, st = c.clean, c.truth, c.states
    w0 = 2.0 * math.pi * w.f0
    sv = CubicSpline(w.t, w.V)
    sth = CubicSpline(w.t, w.theta)

    def rhs(t, y):  # eq. 4 with D = [a, b, H2, Tm]
        vm, th = sv(t), sth(t)
        vd, vq = vm * math.cos(th), vm * math.sin(th)
        fd, fq, s = y
        return [
            -tr.b * fd + s * w0 * fq + tr.a * vd,
            -tr.b * fq - s * w0 * fd + tr.a * vq,
            (tr.Tm - vq * fd + vd * fq) / tr.H2,
        ]

    y0 = [st["Ed"][0] / tr.Xp, st["Eq"][0] / tr.Xp, st["s"][0]]  # Fd = Ed/X', Fq = Eq/X'
    sol = solve_ivp(rhs, (w.t[0], w.t[-1]), y0, t_eval=w.t, method="DOP853", rtol=1e-10, atol=1e-12)
    assert sol.success
    fd, fq, s = sol.y
    vd, vq = w.V * np.cos(w.theta), w.V * np.sin(w.theta)
    p_t = fd * vq - fq * vd  # eq. 5
    q_t = -vd * fd - vq * fq
    scale = np.mean(st["P_motor"])
    assert np.max(np.abs(p_t - st["P_motor"])) < 1e-4 * scale
    assert np.max(np.abs(q_t + w.V**2 / tr.Xp - st["Q_motor"])) < 1e-4 * scale
    assert np.max(np.abs(s - st["s"])) < 1e-4 * np.mean(st["s"])
    # The check has teeth: a 2 % error in a gives a deviation far above that tolerance.
    a_true = tr.a
    object.__setattr__(tr, "a", a_true * 1.02)
    try:
        bad = solve_ivp(rhs, (w.t[0], w.t[-1]), y0, t_eval=w.t, method="DOP853", rtol=1e-10, atol=1e-12)
    finally:
        object.__setattr__(tr, "a", a_true)
    p_bad = bad.y[0] * vq - bad.y[1] * vd
    assert np.max(np.abs(p_bad - st["P_motor"])) > 2e-3 * scale


def test_fleet_continuous_and_deterministic():
    f1 = SyntheticFleet(4, fs=50.0, level=2, seed=9, t0=1000.0)
    f2 = SyntheticFleet(4, fs=50.0, level=2, seed=9, t0=1000.0)
    a1, a2 = f1.advance(30), f1.advance(70)
    b = f2.advance(100)
    assert f1.bus_names == ["bus0001", "bus0002", "bus0003", "bus0004"]
    assert f1.truths == f2.truths
    t = np.concatenate([a1["t"], a2["t"]])
    np.testing.assert_allclose(np.diff(t), 1.0 / 50.0, rtol=1e-9)
    assert t[0] == 1000.0
    for key in ("V", "theta", "P", "Q", "f"):
        assert a1[key].shape == (4, 30) and a2[key].shape == (4, 70)
        np.testing.assert_allclose(np.concatenate([a1[key], a2[key]], axis=1), b[key], rtol=1e-12, atol=1e-14)
    # Continuity at the seam: the step across calls looks like any other step.
    jump = np.abs(a2["V"][:, 0] - a1["V"][:, -1])
    typical = np.max(np.abs(np.diff(b["V"], axis=1)), axis=1)
    assert np.all(jump <= typical)
    other = SyntheticFleet(4, fs=50.0, level=2, seed=10).advance(100)
    assert not np.allclose(other["P"], b["P"])


def test_fleet_noise_level():
    clean = SyntheticFleet(3, fs=25.0, level=None, seed=1)
    noisy = SyntheticFleet(3, fs=25.0, level=1, seed=1)
    assert np.all(np.isnan(clean.snr_db))
    assert np.all(np.abs(noisy.snr_db - NOISE_LEVELS[1]) <= SNR_SPREAD_DB)
    c, n = clean.advance(250), noisy.advance(250)  # 10 s
    np.testing.assert_array_equal(c["t"], n["t"])
    for key in ("P", "Q"):
        y = c[key] - c[key].mean(axis=1, keepdims=True)
        e = n[key] - c[key]
        snr = 10 * np.log10(np.sum(y * y, axis=1) / np.sum(e * e, axis=1))
        # The noise std is fixed from a 20 s calibration, so a live window scatters around the target.
        assert np.all(np.abs(snr - noisy.snr_db) < 4.0), (snr, noisy.snr_db)


def test_large_disturbance_sag_and_recovery():
    tr = random_truth(np.random.default_rng(42))
    w = large_disturbance(tr, seed=1, sag_depth=0.2)
    v0 = w.V[0]
    assert w.n == 500
    assert w.V.min() < 0.9 and w.V.min() == pytest.approx(0.8 * v0, abs=0.03)
    s = w.meta["states"]["s"]
    assert s.max() < 0.2
    assert s.max() > s[0]  # the motor did slow down
    # Pre-fault steady state and recovery afterwards.
    assert np.ptp(w.P[: int(0.9 * 100)]) < 1e-9 * w.P[0]
    assert abs(w.V[-1] - v0) < 0.02 * v0
    assert abs(s[-1] - s[0]) < 0.2 * s[0]
    # The disturbance is large: P and Q move far more than in ambient conditions.
    assert np.ptp(w.P) > 0.1 * w.P[0]
