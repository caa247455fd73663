"""The ANDES scenarios (aslm_sim/andes/): the moved cross-check reproduces its old numbers, every kind runs.

Skipped when the optional ``andes`` package is not installed.  Each kind runs 0.5 s of ANDES at a 10 ms
step (a few seconds each), enough to show that the system builds, the power flow converges from the
motors' start and the TDS completes with the kind's devices in place.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("andes", reason="optional: the andes package is not installed")

from aslm_sim.andes import effects, scenario  # noqa: E402
from benchmarks import andes_crosscheck  # noqa: E402

# benchmarks/andes_crosscheck.py before the move (commit eea2b04): model, seed 1, 3 s at 10 ms, numba off;
# per channel the 11th sample, the last one and the sum of the resampled record.
OLD = {
    "V": (1.0145779906751367, 1.0146820871716165, 305.43676542229394),
    "theta": (-0.14096480628005015, -0.21989798349794681, -67.32425815606297),
    "P": (0.34926932116962567, 0.3499117104668236, 105.35344184816779),
    "Q": (0.21570546138217428, 0.21470197053734832, 65.21195218803945),
}
OLD_TRUTH = (22.79575427221833, 19.158565035006607, 1.0, 0.2)


def test_the_moved_scenario_reproduces_the_old_crosscheck_numbers():
    assert andes_crosscheck.simulate is scenario.simulate  # the names other benchmarks import stay there
    sim = scenario.simulate("model", tf=3.0, tstep=0.01, amp=0.15, seed=1, tol=1e-8, numba=False)
    rec = scenario.resample(sim)
    for ch, (x10, xlast, total) in OLD.items():
        assert rec[ch][10] == pytest.approx(x10, rel=1e-12, abs=1e-14), ch
        assert rec[ch][-1] == pytest.approx(xlast, rel=1e-12, abs=1e-14), ch
        assert rec[ch].sum() == pytest.approx(total, rel=1e-12), ch
    np.testing.assert_allclose(sim["truth"], OLD_TRUTH, rtol=1e-12)


def _check_record(rec: dict, tf: float) -> None:
    assert rec["t"][-1] == pytest.approx(tf)
    for ch in ("V", "theta", "P", "Q"):
        assert rec[ch].shape == rec["t"].shape and np.all(np.isfinite(rec[ch])), ch
    assert 0.95 < rec["V"].mean() < 1.06 and 0.2 < rec["P"].mean() < 0.6 and 0.05 < rec["Q"].mean() < 0.5


@pytest.mark.parametrize("kind", list(effects.KINDS))
def test_every_kind_builds_and_runs_a_short_simulation(kind, tmp_path, monkeypatch):
    monkeypatch.setenv("ASLM_ANDES_CACHE", str(tmp_path))
    load, drawn = effects.build(kind, 7)
    rec = effects.recording(kind, 7, tf=0.5)
    _check_record(rec, 0.5)
    motors = rec["meta"]["motors"]
    assert [m["model"] for m in motors] == [m for m, _ in load.motors]
    if kind == "double_cage":
        assert motors[0]["model"] == "Motor5"
    elif kind == "stator_resistance":
        assert motors[0]["rs_sys"] > 0.01 * 100 / drawn["motor"]["Sn"] * 0.99  # device-base rs ≥ 0.01
    elif kind == "second_motor":
        assert len(motors) == 2 and motors[1]["d"][2] < motors[0]["d"][2]  # the second one is lighter
    elif kind == "speed_dependent_torque":
        assert motors[0]["tm_slope"] == pytest.approx(-drawn["effect"]["k"] * drawn["motor"]["c1"], rel=1e-9)
    elif kind == "measurement_skew":
        assert 0.015 <= drawn["skew_s"] <= 0.04
    elif kind == "switched_capacitor":
        assert isinstance(rec["meta"]["switchings"], int)
    elif kind == "thermostatic_cycling":
        assert drawn["effect"]["own"]["kind"] == "cycle"
    # The second call reads the cache: the same record without running ANDES.
    again = effects.recording(kind, 7, tf=0.5)
    for ch in ("t", "V", "theta", "P", "Q"):
        np.testing.assert_array_equal(again[ch], rec[ch])
    assert again["meta"] == rec["meta"]


def test_a_toggled_motor_is_absent_until_its_time_then_adds_its_share():
    # A second motor identical per unit, 20 % of the first's size, off until ANDES's Toggle at 0.3 s.
    m1 = {**scenario.MOTOR, **scenario.SCENARIOS["model"]}
    m2 = {**m1, "Sn": 0.2 * m1["Sn"], "c1": 0.2 * m1["c1"], "u": 0}
    alone = scenario.simulate_load(scenario.BusLoad(motors=(("Motor3", m1),)), tf=0.8, tstep=0.01, amp=0.15,
                                   seed=3, numba=False)
    both = scenario.simulate_load(scenario.BusLoad(motors=(("Motor3", m1), ("Motor3", m2)), toggles=((1, 0.3),)),
                                  tf=0.8, tstep=0.01, amp=0.15, seed=3, numba=False)
    first, second = both["motors"]
    # Off at the power flow, its D still converts (Tm from its torque law, not ANDES's τm = 0 while off).
    np.testing.assert_allclose(second["d"], np.array(first["d"]) * [0.2, 1.0, 0.2, 0.2], rtol=1e-9)
    np.testing.assert_allclose(first["d"], alone["motors"][0]["d"], rtol=1e-12)
    # Before the step that lands on the switch (ANDES shortens it to hit 0.3 s) the runs are the same.
    pre = both["t"] < 0.3 - 0.015
    np.testing.assert_array_equal(both["t"][pre], alone["t"][: pre.sum()])
    for ch in ("V", "theta", "P", "Q"):
        np.testing.assert_allclose(both[ch][pre], alone[ch][: pre.sum()], rtol=1e-9, atol=1e-12, err_msg=ch)
    late = both["t"] > 0.6
    share = both["p_motor"][late].mean() / alone["p_motor"][alone["t"] > 0.6].mean()
    assert share == pytest.approx(1.2, abs=0.02)
