"""The stator-resistance, double-cage and frequency candidates on data ANDES generates with that physics (issue 12).

ANDES (an independent simulator; skipped when it is not installed) runs IEEE 14-bus with the motor at
bus 9 (aslm_sim/andes/scenario.py: ambient noise on every other load, 12.5 s at a 10 ms step, ~15 s a
run); one 10 s window with white noise on P and Q at 28 dB is diagnosed with the whole library.  The truth
is ANDES's own device data converted to the system base: Motor3's rs (rs = 0.02 on the motor's 25 MVA
base, 0.08 pu on 100 MVA), Motor5's two rotor modes (``rotor_modes``).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("andes", reason="the andes package is not installed")

from aslm_core.diagnosis import diagnose  # noqa: E402
from benchmarks import andes_crosscheck as ac  # noqa: E402

pytestmark = pytest.mark.slow

CONSTANT_TORQUE = {"c1": 0.14, "c2": 0.0, "c3": 0.0}


def _diagnosed(model: str, data: dict, snr_db: float = 28.0, seed: int = 1):
    sim = ac.simulate("model", tf=12.5, tstep=0.01, amp=0.15, seed=1, numba=False, model=model, motor_data=data)
    w = ac.noisy_window(ac.resample(sim), 2.5, 12.5, snr_db, np.random.default_rng(seed))
    return sim, diagnose(w)


def test_stator_resistance_recovers_rs_of_andes_motor3():
    sim, rep = _diagnosed("Motor3", {"rs": 0.02, **CONSTANT_TORQUE})
    assert rep.verdict == "explained" and rep.cause == "stator_resistance", rep.message
    e = rep.candidate("stator_resistance")
    # Measured: Rs = 0.0832 ± 0.0022 pu against 0.08 (1.5 se; γ = 0.934 ± 0.010 against 0.937).  Two
    # standard errors: an estimate is within one only two times in three.
    assert abs(e.parameters["Rs"] - sim["rs_sys"]) <= 2 * e.stderr["Rs"], (e.parameters, e.stderr)
    assert e.derived["rho"] == pytest.approx(sim["rs_sys"] / sim["x1"], rel=0.1)
    assert e.separation_z is None and all(x.separated for x in rep.missing_physics if x.separation_z is not None)


def test_double_cage_rotor_recovers_motor5s_second_rotor_mode():
    sim, rep = _diagnosed("Motor5", {"rs": 1e-5, "xr2": 0.1, "rr2": 0.02, **CONSTANT_TORQUE})
    (_, _), (a2, b2) = sim["modes"]  # the fast mode: 47.1/s, 59.0/s
    assert rep.verdict == "explained" and rep.cause == "double_cage_rotor", rep.message
    e = rep.candidate("double_cage_rotor")
    # Measured on this draw: g2 = 0.839 ± 0.027 1/pu against 0.797 (1.6 se), b2 = 49.5 ± 4.1/s against 59.0
    # (2.3 se).  b2's Jacobian se is the less reliable one (on other noise draws and ANDES steps: 60.3 ± 9.6,
    # 61.5 ± 8.8, 54.5 ± 6.1), hence 3 se for it.
    assert abs(e.parameters["g2"] - a2 / b2) <= 2 * e.stderr["g2"], (e.parameters, e.stderr)
    assert abs(e.parameters["b2"] - b2) <= 3 * e.stderr["b2"], (e.parameters, e.stderr)
    # The rival it most resembles (its own slip and inertia instead of the shared slip) is separated.
    assert rep.candidate("second_motor").separated is not False


def test_clean_andes_motor3_is_consistent():
    _, rep = _diagnosed("Motor3", {}, snr_db=22.0)  # the "model" scenario: rs ≈ 0, constant torque
    assert rep.verdict == "consistent" and rep.causes == [], rep.message
    for e in rep.missing_physics:
        assert not e.significant, e.name


def test_switched_shunt_recovers_an_andes_relay_switched_bank():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Development scenario 102 of the independent benchmark (aslm_sim/andes/effects.py; cached after its
    # first run): ANDES switches its Shunt device from the simulation's own bus voltage (scenario._Relay:
    # b = 0.01265 pu, dead band ±0.00030 pu about the power-flow V, delay 0.371 s; 27 switchings in 22 s),
    # a relay the candidate did not write.
    rec = effects.recording("switched_capacitor", 102, tf=di.TF, tstep=di.TSTEP)
    relay = rec["meta"]["drawn"]["effect"]["relay"]
    w, _ = di._window(rec, 2.0, 12.0, 3, False, "switched_capacitor/102")
    rep = diagnose(w)
    assert rep.verdict == "explained" and rep.cause == "switched_shunt", rep.message
    e = rep.candidate("switched_shunt")
    # Measured: B = 0.01250 against 0.01265 pu with the relay law (τ + t_op = 0.40 s against the 0.371 s
    # delay); since the steps' form (sixth round) the state comes from V's own steps: B = 0.01270, and V before
    # the switchings in and out (Vc ∓ dv = 1.0140, 1.0192) lies beyond the relay's thresholds V0 ∓ 0.0003
    # (V0 ≈ 1.0160, the record's first sample), as a relay demands.
    assert e.parameters["B"] == pytest.approx(relay["b"], rel=0.1), (e.parameters, e.stderr)
    v0, vc, dv = rec["V"][0], e.parameters["Vc"], e.parameters["dv"]
    assert e.parameters["dV"] > 0.0 and vc - dv < v0 - relay["dv"] and vc + dv > v0 + relay["dv"], e.parameters


def test_switched_shunt_recovers_an_andes_bank_whose_relay_chatters_against_its_own_step():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Scenario 9403 of the fifth confirmation set (seen since): b = 0.0267 pu, dead band ±0.00064 pu, delay
    # 0.207 s.  The bank's own V step (0.0045 pu) is seven dead bands, so the relay chatters (57 switchings in
    # 22 s) and re-enacting it from the recorded V misses 15 of 58 switchings even with its true settings;
    # before the steps' form the window was `unexplained` at every level (B fitted 0.0115).  Measured
    # 2026-11-25: B 0.0269, the state from V's steps (dV > 0), the Q step one 10 ms step after V's.
    rec = effects.recording("switched_capacitor", 9403, tf=di.TF, tstep=di.TSTEP)
    b = rec["meta"]["drawn"]["effect"]["relay"]["b"]
    w, _ = di._window(rec, *di.WINDOWS[0], 3, False, "switched_capacitor/9403")
    rep = diagnose(w)
    assert rep.verdict == "explained" and rep.cause == "switched_shunt", rep.message
    e = rep.candidate("switched_shunt")
    assert e.parameters["dV"] > 0.0, e.parameters
    assert e.parameters["B"] == pytest.approx(b, rel=0.05), (e.parameters, e.stderr)


def test_switched_shunt_reads_andes_banks_steps_not_the_ambients_swings_and_peaks():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Scenario 9701 of the eighth confirmation set (seen since), noise on P and Q at L2: b = 0.0138 pu, V steps of
    # 1.2–2.1e-3 pu.  In its second window the bank switches four times in the training part and never after, and
    # at 19.2 s the ambient V rises 6.5e-4 pu per sample, which the plain 20 ms statistic read as a switching
    # (held-out state 78 % wrong, gain −68: `unexplained`, the run of record); in its first window the relay law
    # tied with the steps' form in training and missed two held-out switchings (gain −8).  Measured 2026-11-25 with
    # the detrended statistic and the threshold in the middle of its training range (stop 31): both named, the
    # steps' form, B 0.0137–0.0138.
    rec = effects.recording("switched_capacitor", 9701, tf=di.TF, tstep=di.TSTEP)
    b = rec["meta"]["drawn"]["effect"]["relay"]["b"]
    for t0, t1 in di.WINDOWS:
        w, _ = di._window(rec, t0, t1, 2, False, "switched_capacitor/9701")
        rep = diagnose(w)
        assert rep.verdict == "explained" and rep.cause == "switched_shunt", (t0, rep.message)
        e = rep.candidate("switched_shunt")
        assert e.parameters["dV"] > 0.0, e.parameters
        assert e.parameters["B"] == pytest.approx(b, rel=0.05), (e.parameters, e.stderr)
    # Scenario 9602 of the seventh set (seen), 2–12 s: an ambient rise of 3.3 × the statistic's scale at the last
    # training sample bounded the threshold's range at 3.34 × when the range was read on every training sample, and
    # the middle, 3.16 ×, let held-out ambient peaks through (gain −72: `unexplained`).  Read on the training samples
    # whose statistic sees no held-out V, the middle is 13.7 × (measured 2026-11-25).
    rec = effects.recording("switched_capacitor", 9602, tf=di.TF, tstep=di.TSTEP)
    w, _ = di._window(rec, 2.0, 12.0, 2, False, "switched_capacitor/9602")
    rep = diagnose(w)
    assert rep.verdict == "explained" and rep.cause == "switched_shunt", rep.message


def test_switched_shunt_names_an_andes_bank_when_v_and_theta_are_noisy_too():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Scenario 9504 of the sixth confirmation set (seen since), second window at L3 with the benchmark's V/θ noise
    # (0.1 % of V, 1e-3 rad): b = 0.0270 pu, a V step of 0.0038 pu against V noise of 0.0011 pu, so the 20 ms
    # steps drown.  Before the two-state form (stop 29) `unexplained` (relay law, z 28, gain +8.5; the run of
    # record).  Measured 2026-11-25: named, B 0.0268, the state from the two-state path (dV < 0).
    rec = effects.recording("switched_capacitor", 9504, tf=di.TF, tstep=di.TSTEP)
    b = rec["meta"]["drawn"]["effect"]["relay"]["b"]
    w, _ = di._window(rec, *di.WINDOWS[1], 3, True, "switched_capacitor/9504")
    rep = diagnose(w)
    assert rep.verdict == "explained" and rep.cause == "switched_shunt", rep.message
    e = rep.candidate("switched_shunt")
    assert e.parameters["dV"] < 0.0, e.parameters
    assert e.parameters["B"] == pytest.approx(b, rel=0.05), (e.parameters, e.stderr)


def test_a_second_andes_motor_is_not_named_inverter_der():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Scenario 9001 of the first confirmation set (seen, no longer a confirmation seed): its second motor was
    # named `inverter_der` at L3 in both windows, and still is with `Candidate.confusable` (measured
    # 2026-11-24: second_motor is a rival and is separated, z = 5.1 and 3.8).  Its b2 is 68.5 1/s, far above the
    # b ≤ 30 box the candidate had; with the box opened to 90 (round 4) the droop no longer wins (was strict xfail).
    rec = effects.recording("second_motor", 9001, tf=di.TF, tstep=di.TSTEP)
    for t0, t1 in di.WINDOWS:
        w, _ = di._window(rec, t0, t1, 3, False, "second_motor/9001")
        rep = diagnose(w)
        assert rep.cause != "inverter_der", rep.message


def test_an_andes_frequency_dependence_the_oracle_separates_is_named_with_its_own_parameters():
    from aslm_sim.andes import effects
    from aslm_sim.andes.scenario import STATIC_PQ
    from benchmarks import diagnosis_independent as di

    # Scenario 9102 of the second confirmation set (seen, development data since), second window at L3: ANDES's
    # FLoad (P = P0·V^ap·f^bp, Q likewise, f from its BusFreq: a 0.02 s lag and a 0.1 s washout).  Before the
    # lag (round 5) it was `ambiguous` against the torque law — each beat the other on the paired test — and
    # before the reverse comparison named `speed_dependent_torque`.  The separability oracle
    # (benchmarks/diagnosis_separability.py) now gives z 7.0 for the frequency term over the torque law at L3
    # and 0.6 back.  Measured 2026-11-25: Kpf 0.0115 ± 0.0004 (truth 0.01165), Kqf 0.0027 ± 0.0003 (0.0031),
    # Tf 0.112 ± 0.023 s (the BusFreq's two lags add to 0.12 s); the torque law separated at z 4.5.
    rec = effects.recording("frequency_dependence", 9102, tf=di.TF, tstep=di.TSTEP)
    fl = rec["meta"]["drawn"]["effect"]["fload"]
    truth = {"Kpf": STATIC_PQ[0] * fl["bp"] / 60.0, "Kqf": STATIC_PQ[1] * fl["bq"] / 60.0}  # dP/df [pu/Hz]
    w, _ = di._window(rec, *di.WINDOWS[1], 3, False, "frequency_dependence/9102")
    rep = diagnose(w)
    assert rep.verdict == "explained" and rep.cause == "frequency_dependence", rep.message
    e = rep.candidate("frequency_dependence")
    for k, v in truth.items():
        assert abs(e.parameters[k] - v) <= 2 * e.stderr[k], (k, e.parameters, e.stderr)
    assert abs(e.parameters["Tf"] - 0.12) <= 3 * e.stderr["Tf"] and e.parameters["Tf"] > 0.05, (e.parameters, e.stderr)
    assert rep.candidate("speed_dependent_torque").separated is True


def test_a_second_andes_motor_with_a_fast_rotor_is_fitted_outside_the_aggregate_box():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Development scenario 102: ANDES's second motor (2.2 × the first's rotor resistance) has b2 = 44.4 1/s on
    # the system base, above the paper's b ≤ 30 for the aggregate motor that bounded the candidate before
    # round 4 (every ANDES second motor of the four sets has b2 = 37-69).  Measured 2026-11-24: b2 46.3 ± 8.0.
    rec = effects.recording("second_motor", 102, tf=di.TF, tstep=di.TSTEP)
    a2, b2, h22, tm2 = rec["meta"]["motors"][1]["d"]
    w, _ = di._window(rec, *di.WINDOWS[0], 3, False, "second_motor/102")
    rep = diagnose(w)
    assert rep.cause == "second_motor", rep.message
    e = rep.candidate("second_motor")
    assert e.parameters["b2"] > 30.0
    assert abs(e.parameters["b2"] - b2) < 3 * e.stderr["b2"]
    assert abs(e.parameters["Tm2"] - tm2) < 0.2 * tm2 + 3 * e.stderr["Tm2"]


def test_a_thermostatic_load_that_pins_the_motor_is_not_named_a_second_motor():
    from aslm_core.diagnosis.pipeline import DiagnosisConfig
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Scenario 9602 of the seventh confirmation set (development data since), first window at L2 with the V/θ
    # noise: a load cycling on and off (outside the library) pulls the plain fit onto b = 30 /s although the drawn
    # motor (b = 16 /s) is inside the box, and opening the box there does not improve the plain fit.  With the
    # bound rival alone (stop 29) `second_motor` was named: its second group took the motor and its first stayed
    # pinned, the cycling half explained.  Stop 30: a motor-form cause kept on that bound with located excess left
    # is withheld.  The rule is tested on the measured inputs and the channels' held-out gain, where the case arises;
    # on the conditional mean of the inputs (the default since stop 32), or with the gain over P and Q-given-P (the
    # default since stop 43: `second_motor` is then not significant), no candidate explains the excess, and the
    # answer is the same.
    rec = effects.recording("thermostatic_cycling", 9602, tf=di.TF, tstep=di.TSTEP)
    w, _ = di._window(rec, *di.WINDOWS[0], 2, True, "thermostatic_cycling/9602")
    rep = diagnose(w, config=DiagnosisConfig(input_mean=False, gain_metric="channels"))
    assert rep.model.at_bound.get("b") == 30.0, "the case no longer pins the plain fit: it tests nothing here"
    assert rep.verdict == "unexplained" and rep.cause is None and rep.causes == [], rep.message
    assert "second_motor, a change of the motor, keeps its motor on that bound (b = 30" in rep.message
    for config in (DiagnosisConfig(input_mean=False), DiagnosisConfig()):
        rep = diagnose(w, config=config)
        assert rep.verdict == "unexplained" and rep.cause is None and rep.causes == [], rep.message


def test_a_stator_resistance_that_clears_the_excess_is_named_on_the_bound():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Scenario 9404 of the fifth confirmation set (development data since), first window at L2 with the V/θ noise:
    # the plain fit sits on b = 30 /s, opening the box does not improve it, and `stator_resistance` keeps its D
    # there too — but leaves no located excess, so the stop-30 rule does not withhold it (the sixth round's veto
    # did).
    rec = effects.recording("stator_resistance", 9404, tf=di.TF, tstep=di.TSTEP)
    w, _ = di._window(rec, *di.WINDOWS[0], 2, True, "stator_resistance/9404")
    rep = diagnose(w)
    assert rep.model.at_bound.get("b") == 30.0, "the case no longer pins the plain fit: it tests nothing here"
    assert rep.verdict == "explained" and rep.cause == "stator_resistance", rep.message
    assert rep.candidate("stator_resistance").remaining_excess_channels == []


def test_a_thermostatic_load_fitted_as_a_droop_of_the_wrong_sign_is_not_named_inverter_der():
    from aslm_sim.andes import effects
    from benchmarks import diagnosis_independent as di

    # Scenario 9703 of the eighth confirmation set (development data since), second window at L1 with the V/θ
    # noise: a load cycling on and off (outside the library) was named `inverter_der` (z 25, 54 % of the held-out
    # excess) with Kq = −1.38 ± 0.23: its Q steps pull V down through the network, so the consumed Q moves against
    # the lagged V, which a droop (Kq > 0 in load convention) cannot do.  Stop 31: such a fit is implausible.
    rec = effects.recording("thermostatic_cycling", 9703, tf=di.TF, tstep=di.TSTEP)
    w, _ = di._window(rec, *di.WINDOWS[1], 1, True, "thermostatic_cycling/9703")
    rep = diagnose(w)
    e = rep.candidate("inverter_der")
    assert e.parameters["Kq"] < 0 and e.score_z > 3, "the droop no longer fits this case: it tests nothing here"
    assert not e.significant
    assert rep.cause != "inverter_der" and "inverter_der" not in rep.causes, rep.message
