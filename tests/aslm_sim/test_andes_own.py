"""The ANDES own-fluctuation bench (aslm_sim/andes/own_fluctuation.py): it builds, and its windows have the requested ratio.

Skipped when the optional ``andes`` package is not installed.  Short ANDES runs (12 s grid-side, an 8 s step
response) cached in a temporary directory.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("andes", reason="optional bench: the andes package is not installed")

from aslm_sim.andes import own_fluctuation as andes_own  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    saved, andes_own.CACHE_DIR = andes_own.CACHE_DIR, tmp_path_factory.mktemp("andes_own")
    grid = andes_own.grid_recording(tf=12.0, tstep=0.01, seed=3)
    own = andes_own.own_recording("switching", tf=12.0, tstep=0.01, seed=3, step_tf=8.0)
    yield grid, own
    andes_own.CACHE_DIR = saved


def test_own_windows_have_the_requested_ratio_and_move_the_voltage(recordings):
    grid, own = recordings
    ratio = 0.5
    ws = andes_own.cut_windows(grid, own, ratio, length_s=4.0, start_s=2.0, stride_s=2.0, n=3, snr_db=60.0,
                               rng=np.random.default_rng(0))
    k = ratio / math.sqrt(1.0 - ratio**2)
    for i, w in enumerate(ws):
        sl = slice(200 + 200 * i, 601 + 200 * i)
        assert w["own_ratio"] == pytest.approx(k, rel=1e-9)
        # own / total std of P near the target (the two parts are uncorrelated only on average).
        total = w["P"] - w["P"].mean()
        assert 0.3 < np.std(w["dp_own"]) / np.std(total) < 0.75
        # Closed loop: the own fluctuation moves the bus voltage through the network.
        dv = w["V"] - grid["V"][sl]
        assert np.std(dv) > 0.02 * np.std(grid["V"][sl])
        assert np.corrcoef(dv, w["dp_own"])[0, 1] < -0.5  # more load, lower voltage


def test_windows_with_the_loop_cut_keep_the_grid_side_inputs_and_add_the_own_powers_alone(recordings):
    grid, own = recordings
    kw = dict(length_s=4.0, start_s=2.0, stride_s=2.0, n=3, snr_db=60.0)
    closed = andes_own.cut_windows(grid, own, 0.5, rng=np.random.default_rng(0), **kw)
    cut = andes_own.cut_windows(grid, own, 0.5, rng=np.random.default_rng(0), loop=False, **kw)
    for i, (wc, wo) in enumerate(zip(closed, cut, strict=True)):
        sl = slice(200 + 200 * i, 601 + 200 * i)
        np.testing.assert_array_equal(wo["V"], grid["V"][sl])  # V and θ carry none of the own process
        np.testing.assert_array_equal(wo["theta"], grid["theta"][sl])
        assert wo["k"] == wc["k"] and np.array_equal(wo["dp_own"], wc["dp_own"])  # the same own ΔP, same scale
        # P is the grid-side run's plus the own ΔP (and the 60 dB noise); closed, P also has the load's response.
        assert np.std(wo["P"] - grid["P"][sl] - wo["dp_own"]) < 0.01 * np.std(wo["dp_own"])
        assert np.std(wc["P"] - grid["P"][sl] - wc["dp_own"]) > np.std(wo["P"] - grid["P"][sl] - wo["dp_own"])


def test_step_response_settles_and_the_load_step_lowers_the_voltage(recordings):
    step = andes_own.step_response(tstep=0.01, tf=8.0)
    assert step["P"][0] > 0.5  # the step itself appears in the bus's P at once
    assert step["V"][-1] < 0.0
    assert np.all(np.isfinite(step["theta"]))


def test_a_partly_coherent_own_dq_is_superposed_from_the_q_step(monkeypatch):
    """ΔQ = 0.33·(ρ·x + √(1 − ρ²)·x₂): the response is the coupled step's to x plus the Q step's to the rest (stub
    steps here: the composition, not ANDES, is under test)."""
    n = 400
    t = np.arange(n) * 0.01
    step_c = {c: np.full(n, v) for c, v in zip(("V", "theta", "P", "Q"), (-0.1, -0.01, 1.0, 0.33), strict=True)}
    step_q = {c: np.full(n, v) for c, v in zip(("V", "theta", "P", "Q"), (-0.3, 0.0, 0.0, 1.0), strict=True)}
    step_c["t"] = step_q["t"] = t
    monkeypatch.setattr(andes_own, "step_response", lambda **kw: step_c)
    monkeypatch.setattr(andes_own, "step_response_q", lambda **kw: step_q)
    full = andes_own.own_recording("lowpass", tf=(n - 1) * 0.01, tstep=0.01, seed=4)
    half = andes_own.own_recording("lowpass", tf=(n - 1) * 0.01, tstep=0.01, seed=4, coherence=0.5)
    np.testing.assert_array_equal(full["dp_own"], half["dp_own"])
    extra = half["dq_own"] - andes_own.OWN_Q_PER_P * half["dp_own"]
    # Steps held flat (and the input taken from 0 before t = 0), so each response is the step's value times the input.
    np.testing.assert_allclose(half["V"], -0.1 * full["dp_own"] - 0.3 * extra, atol=1e-12)
    np.testing.assert_allclose(half["Q"] - full["Q"], extra, atol=1e-12)
    assert 0.2 < np.corrcoef(half["dp_own"], half["dq_own"])[0, 1] < 0.8


def test_a_horizon_superposes_the_own_run_from_the_windows_start_not_its_accumulated_level(monkeypatch):
    """``horizon_s`` 0: a window carries k × the response to the own increments inside it only, so the bus stays at
    its operating point; without it, k × everything since t = 0 (stub steps: the composition, not ANDES, is under test)."""
    n = 1200
    t = np.arange(n) * 0.01
    step = {c: np.full(n, v) for c, v in zip(("V", "theta", "P", "Q"), (-0.1, -0.01, 1.0, 0.33), strict=True)}
    step["t"] = t
    monkeypatch.setattr(andes_own, "step_response", lambda **kw: step)
    own = andes_own.own_recording("ramp", tf=(n - 1) * 0.01, tstep=0.01, seed=5)
    grid = {c: np.zeros(n) for c in ("V", "theta", "P", "Q")}
    grid.update(t=t, P=1.0 + 0.01 * np.sin(t), Q=0.3 + 0.003 * np.sin(t), V=1.0 + 0.001 * np.sin(t))
    kw = dict(length_s=2.0, start_s=6.0, stride_s=2.0, n=2, snr_db=200.0)
    whole = andes_own.cut_windows(grid, own, 0.9, rng=np.random.default_rng(0), **kw)
    local = andes_own.cut_windows(grid, own, 0.9, rng=np.random.default_rng(0), horizon_s=0.0, **kw)
    for i, (w, h) in enumerate(zip(whole, local, strict=True)):
        a = 600 + 200 * i
        sl = slice(a, a + 201)
        assert h["k"] == w["k"]
        np.testing.assert_allclose(h["V"] - grid["V"][sl], -0.1 * h["k"] * (own["dp_own"][sl] - own["dp_own"][a]),
                                   atol=1e-12)
        np.testing.assert_allclose(w["V"] - grid["V"][sl], -0.1 * w["k"] * (own["dp_own"][sl] - own["dp_own"][0]),
                                   atol=1e-12)
        assert h["V"][0] == pytest.approx(grid["V"][a], abs=1e-12)  # no level carried into the window
