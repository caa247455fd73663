"""The switched capacitor's true state and the relay-family oracle of benchmarks/diagnosis_shunt_state.py."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import diagnosis_shunt_state as ss  # noqa: E402


def _record(seed: int = 3) -> tuple[dict, np.ndarray]:
    """A 22 s, 100 Hz record: a smooth ambient V and Q, and a bank of b = 0.02 pu switched by a relay on V."""
    from aslm_core.diagnosis.candidates.switched_shunt import relay_state

    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 22.0 + 1e-9, 0.01)
    slow = np.convolve(rng.standard_normal(t.size + 200), np.hanning(81) / 40.0, mode="same")[100:100 + t.size]
    v_amb = 1.01 + 0.004 * slow / np.std(slow)
    s = relay_state(v_amb, 1.01, 0.001, 0.15, 0.01, 0.0)
    b = 0.02
    v = v_amb + 0.003 * s  # the bank lifts V
    q = 0.2 + 0.05 * (v - 1.0) - b * s * v**2
    rec = {"t": t, "V": v, "Q": q, "meta": {"drawn": {"effect": {"relay": {"b": b, "dv": 0.001, "delay": 0.15}}},
                                             "switchings": int(np.sum(np.diff(s) != 0))}}
    return rec, s


def test_the_true_state_is_read_off_q_and_counts_every_switching():
    rec, s = _record()
    assert rec["meta"]["switchings"] >= 6  # the ambient drives the relay both ways several times
    state, n = ss.true_state(rec, 2.0, 12.0)
    sl = (rec["t"] >= 2.0 - 1e-9) & (rec["t"] <= 12.0 + 1e-9)
    assert n == rec["meta"]["switchings"]
    # A step is placed within the 20 ms statistic's reach of where the bank switched.
    assert np.mean(state == s[sl]) > 0.99


def test_the_relay_family_oracle_reproduces_a_relay_it_can_express():
    rec, s = _record(5)
    sl = (rec["t"] >= 2.0 - 1e-9) & (rec["t"] <= 12.0 + 1e-9)
    v = rec["V"][sl] - 0.003 * s[sl]  # the relay's own input: the law is then inside the family exactly
    target = s[sl]
    train, test = slice(0, 660), slice(660, target.size)
    law = ss.best_law_state(v, target, train, 0.01)
    assert np.mean(law[train] == target[train]) > 0.98
    assert np.mean(law[test] == target[test]) > 0.9
