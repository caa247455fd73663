"""The droop as a broadband response: a gain carried by one line of V is refuted, a real droop is not (stop 32)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from aslm_core.diagnosis import DiagnosisConfig, diagnose
from aslm_core.diagnosis.lag import lagged
from aslm_core.diagnosis.pipeline import _analyse, off_peak_gain
from aslm_sim.cases import make_case
from aslm_sim.effects import apply_effect

ONLY_DER = DiagnosisConfig(candidates=("inverter_der",))


def _tone_window(seed: int):
    """A self-test window whose V carries a 0.3 Hz line and whose P and Q follow that line (only) through a lagged
    droop: what a load's own oscillation moving V looks like to the droop, which V's ambient part refutes."""
    w = make_case(seed, level=3, input_noise=False).window
    dv = 0.004 * np.sin(2 * np.pi * 0.3 * (w.t - w.t[0]))
    dq = 0.5 * lagged(dv, 1.5, float(w.t[1] - w.t[0]))
    return replace(w, V=w.V + dv, P=w.P + 0.5 * dq, Q=w.Q + dq)


def test_a_droop_fitted_to_one_line_of_v_is_refuted_and_a_real_droop_is_not():
    tone = _tone_window(18)
    a = _analyse(tone, None, None, ONLY_DER)
    assert off_peak_gain([a], "inverter_der") < 0.0
    rep = diagnose(tone, config=ONLY_DER)
    e = rep.candidate("inverter_der")
    # The line alone makes the droop pass the score test and the penalty, with the physical sign: only the
    # breadth rule stops it.
    assert e.score_z > 5.0 and e.penalised_gain > 0.0 and e.parameters["Kq"] > 0.0, e
    assert not e.significant and rep.cause is None

    droop = apply_effect(make_case(18, level=3, input_noise=False), "inverter_der", 3.0, seed=8).window
    assert off_peak_gain([_analyse(droop, None, None, ONLY_DER)], "inverter_der") > 0.0
    rep = diagnose(droop, config=ONLY_DER)
    assert rep.candidate("inverter_der").significant and rep.cause == "inverter_der"
