"""Identifier vs an independent simulator: ANDES Motor3 + ZIP in the IEEE 14-bus system (benchmarks/andes_crosscheck.py).

Skipped when the optional ``andes`` package is not installed.  Under the model's assumptions (rs ≈ 0,
constant torque) the full benchmark (5 ms ANDES step, 10 s windows) recovers D within 0.3 %; this
shorter, deterministic run (10 ms step, one 6 s window, ~25 s) within 1.4 % (a: −1.4 %, b: −0.8 %,
H2: +0.1 %, Tm: −0.2 %), the difference being ANDES's trapezoid step vs the identifier's RK4.  TOL = 3 %
leaves about 2x margin and is far below what a conversion error would give (2H vs H: factor 2; device vs
system base: factor Sn/Sb = 1/4 on a and H2).

With white PMU noise on V and θ (the benchmark's ``--input-noise``, docs/andes_crosscheck.md "Noise on V and
θ"): one 12.5 s run at 10 ms, its 2.5–12.5 s window, the 0.1 % / 1e-3 rad class and 22 dB on P and Q.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("andes", reason="optional cross-check: the andes package is not installed")

from aslm_core import Window, identify  # noqa: E402
from benchmarks import andes_crosscheck as ac  # noqa: E402

TOL = 0.03


def _model_run(tf: float) -> tuple[dict, dict]:
    """The ``model`` scenario at a 10 ms step, seed 1: ANDES's record and its resampled form."""
    sim = ac.simulate("model", tf=tf, tstep=0.01, amp=0.15, seed=1, tol=1e-8, numba=False)
    return sim, ac.resample(sim)


@pytest.fixture(scope="module")
def andes_run():
    return _model_run(8.0)


def test_converted_motor3_matches_the_transformed_model(andes_run):
    sim, rec = andes_run
    conv = ac.conversion_check(rec, sim)
    assert conv["p"] < 0.02 and conv["q"] < 0.02, conv


def test_identifies_andes_motor3_under_model_assumptions(andes_run):
    sim, rec = andes_run
    sl = rec["t"] >= 2.0 - 1e-9
    w = Window(rec["t"][sl], rec["V"][sl], rec["theta"][sl], rec["P"][sl], rec["Q"][sl], f0=ac.F0, bus="andes")
    res = identify(w)
    ratio = res.d / sim["truth"]
    assert np.all(np.abs(ratio - 1.0) < TOL), dict(zip(ac.NAMES, ratio.round(4), strict=True))
    assert min(res.fit["fd_p"], res.fit["fd_q"]) > 0.99
    assert not [f for f in res.flags if f.startswith(("at_bound", "uncertain", "poor_fit", "low_excitation"))]


#: Median |D/D_true − 1| over the 10 draws of the noisy-input test, a / b / H2 / Tm.  Measured on this run and
#: window with 200 other draws (keys [7, k]): median |error| 6.6 / 3.4 / 2.0 / 3.5 %, the median over 10
#: draws 3.2–9.6 / 1.9–4.6 / 1.2–2.8 / 1.3–5.5 % in 20 disjoint groups, 15.2 / 7.8 / 3.9 / 7.4 % at the
#: 99.9th percentile of 20,000 resampled groups; input_smoother="none" 56 / 24–25 / 27–29 / 30–33 %
#: (a at its bound); the test's own 10 draws (keys [11, k]): 9.6 / 5.3 / 2.0 / 1.7 %, "none" 56 / 25 / 28 / 32 %.
#: The tolerances leave ~1.3× over that percentile and stay below "none".
NOISY_TOL = np.array([0.20, 0.10, 0.05, 0.10])


@pytest.fixture(scope="module")
def andes_run_12s():
    return _model_run(12.5)


def test_identifies_andes_motor3_with_pmu_noise_on_v_and_theta(andes_run_12s):
    sim, rec = andes_run_12s
    span = (2.5, 12.5)
    base = ac.noisy_window(rec, *span, None, None)
    err = {"default": [], "none": []}
    for k in range(10):
        for out in ac.identify_draw(base, rec, span, 22.0, ["pmu01"], [11, k]):
            err[out["variant"]].append(np.abs(np.array(out["d"]) / sim["truth"] - 1.0))
    med = {v: np.median(e, axis=0) for v, e in err.items()}
    assert np.all(med["default"] < NOISY_TOL), dict(zip(ac.NAMES, med["default"].round(4), strict=True))
    # The default against the identifier before issue 11 on the same noisy windows, parameter by parameter.
    assert np.all(med["default"] < 0.5 * med["none"]), med
