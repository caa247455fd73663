"""The diagnosis at PMU reporting rates below 100 frames/s: its motor kernels sub-step RK4 as the identifier does."""

from __future__ import annotations

import numpy as np
import pytest

from aslm_core import motor
from aslm_core.diagnosis import diagnose
from aslm_core.diagnosis.candidates.speed_dependent_torque import simulate_k
from aslm_core.diagnosis.motor_variants import variant_power
from aslm_core.diagnosis.segment import make_segment
from aslm_sim import make_cases

D = np.array([60.0, 60.0, 0.6, 0.3])  # a fast motor: RK4 at the 40 ms sample step is far off for it


@pytest.fixture(scope="module")
def segment_25():
    return make_segment(make_cases(1, level=None, seed=7, fs=25.0, input_noise=False)[0].window)


def _reference(seg):
    """P_im, Q_im of the paper's motor on the segment's inputs, integrated by the identifier's sub-stepped RK4."""
    p, q, _ = motor.simulate(seg.V, seg.theta, D, seg.dt, seg.omega0)
    return p, q


def test_the_segment_carries_the_inputs_inside_each_sub_step(segment_25):
    assert motor.substeps(segment_25.dt) == 4
    assert segment_25.vdm.size == (segment_25.n - 1) * 7


def test_the_motor_variants_kernel_reduces_to_the_identifiers_motor_at_25_frames_per_second(segment_25):
    """No second rotor mode, no stator resistance: the variant is the paper's motor, integrated the same way.
    With RK4 at the sample step (before stop 51) it was off by 0.21 of P_im's ambient std."""
    p_ref, q_ref = _reference(segment_25)
    p, q = variant_power(segment_25, D)
    k = slice(25, None)
    assert np.max(np.abs(p - p_ref)[k]) < 1e-9 * np.std(p_ref[k]) + 1e-12
    assert np.max(np.abs(q - q_ref)[k]) < 1e-9 * np.std(q_ref[k]) + 1e-12


def test_the_speed_dependent_torque_kernel_with_k_0_is_the_identifiers_motor_at_25_frames_per_second(segment_25):
    seg = segment_25
    x0 = motor.steady_state(float(np.hypot(seg.vd[0], seg.vq[0])), float(seg.theta[0]), D, seg.omega0)
    p, q = simulate_k(seg.vd, seg.vq, seg.vdm, seg.vqm, *D, 0.0, seg.omega0, seg.dt, x0[0], x0[1], x0[2])
    p_ref, q_ref = _reference(seg)
    # The identifier starts turning with the bus frequency; this kernel at the steady state it is given: compare
    # after the start has decayed (b = 60 /s).
    k = slice(25, None)
    assert np.max(np.abs(p - p_ref)[k]) < 1e-3 * np.std(p_ref[k])
    assert np.max(np.abs(q - q_ref)[k]) < 1e-3 * np.std(q_ref[k])


def test_model_true_windows_at_25_frames_per_second_are_consistent():
    """Measured over 180 windows per rate (benchmarks.diagnosis_rates --seed 72 --n 60 --rates 25 30): with the
    diagnosis's kernels at the sample step 16 of 180 at 25 frames/s came out other than consistent (6 naming a
    cause), with sub-steps 0.  The two windows here were among the false findings."""
    cases = make_cases(5, level=3, seed=17, fs=25.0, input_noise=False)
    for c in (cases[1], cases[4]):  # before: explained by second_motor, ambiguous
        r = diagnose(c.window)
        assert r.verdict == "consistent", (r.verdict, r.cause)


def test_with_exact_inputs_quiet_exact_inputs_at_25_frames_per_second_carry_no_noise():
    """Above the floor's edge (5 Hz) at 25 frames/s lies the inputs' own content, not noise. The default reads it as
    noise and propagates it into P and Q: their floors come out 1.2–1.4 × the injected noise here (3–9 × on ANDES's
    records). With ``exact_inputs_quiet`` they are the injected ones, and noisy V and θ keep their white floors."""
    from aslm_core.diagnosis.pipeline import DiagnosisConfig

    quiet = DiagnosisConfig(exact_inputs_quiet=True)
    rng = np.random.default_rng(0)
    for c in make_cases(2, level=3, seed=41 * 1000, fs=25.0, input_noise=False):
        w = c.window
        assert diagnose(w).to_dict()["noise"]["sigma_p"] / np.std(w.P - c.clean.P) > 1.1  # the default's
        noise = diagnose(w, config=quiet).to_dict()["noise"]
        assert noise["sigma_v"] == 0.0 and noise["sigma_theta"] == 0.0
        assert 0.85 < noise["sigma_p"] / np.std(w.P - c.clean.P) < 1.15
        assert 0.85 < noise["sigma_q"] / np.std(w.Q - c.clean.Q) < 1.15
        v_noise = 1e-3 * float(np.mean(c.clean.V))
        noisy = type(w)(t=w.t, V=w.V + v_noise * rng.standard_normal(w.V.size),
                        theta=w.theta + 1e-3 * rng.standard_normal(w.V.size), P=w.P, Q=w.Q, f0=w.f0, bus=w.bus)
        nn = diagnose(noisy, config=quiet).to_dict()["noise"]
        assert 0.8 < nn["sigma_v"] / v_noise < 1.25 and 0.8 < nn["sigma_theta"] / 1e-3 < 1.25
