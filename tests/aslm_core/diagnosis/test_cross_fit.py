"""Cross-fitted diagnosis (``DiagnosisConfig.cross_fit``): the mirror fold, and its evidence combined honestly."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from aslm_core.diagnosis import DiagnosisConfig, diagnose
from aslm_core.diagnosis.pipeline import _combine_params, _fold_overlap
from aslm_core.diagnosis.segment import make_segment
from aslm_sim.cases import make_cases
from aslm_sim.effects import apply_effect


@pytest.fixture(scope="module")
def cases():
    return make_cases(3, level=2, seed=21, input_noise=False)


@pytest.mark.parametrize("gap", [0, 100])
def test_the_mirror_fold_holds_out_as_many_samples_after_the_skip_and_its_gap(cases, gap):
    seg = make_segment(cases[0].window)
    mirror = replace(seg, held_out_first=True, mirror_gap=gap)
    n_test = seg.ke - seg.ks
    assert (mirror.test.start, mirror.test.stop) == (seg.k0 + gap, seg.k0 + gap + n_test)
    assert (mirror.train.start, mirror.train.stop) == (seg.k0 + gap + n_test, seg.ke)
    assert mirror.train.stop - mirror.train.start == seg.train.stop - seg.train.start - gap
    # Each fold's held-out samples are outside its own training samples, and the two held-out sets are disjoint.
    for s in (seg, mirror):
        assert s.test.stop <= s.train.start or s.train.stop <= s.test.start
    assert mirror.test.stop <= seg.test.start


def _analysis(window: int, value: float, se: float, seg) -> SimpleNamespace:
    fit = SimpleNamespace(params={"k": value}, stderr={"k": se})
    return SimpleNamespace(window=window, fits={"c": fit}, seg=seg)


def test_two_folds_of_one_window_count_the_training_samples_they_share(cases):
    seg = make_segment(cases[0].window)
    mirror = replace(seg, held_out_first=True, mirror_gap=100)
    rho = _fold_overlap(seg, mirror)
    # 10 s at 100 frames/s: 5.5 s and 4.5 s of training, 1.1 s of it shared.
    assert (seg.ks - seg.k0, seg.ke - seg.ks) == (550, 340)
    assert rho == pytest.approx(110 / math.sqrt(550 * 450))
    assert _fold_overlap(seg, seg) == pytest.approx(1.0)
    folds = [_analysis(0, 1.0, 0.2, seg), _analysis(0, 3.0, 0.2, mirror)]
    val, se = _combine_params(folds, "c")
    assert val["k"] == pytest.approx(2.0)
    assert se["k"] == pytest.approx(0.2 / math.sqrt(2.0) * math.sqrt(1.0 + rho))
    # Unequal errors: the weighted mean's variance with the correlation, Σ w_i w_j C_ij / (Σ w)².
    folds = [_analysis(0, 1.0, 0.1, seg), _analysis(0, 3.0, 0.3, mirror)]
    val, se = _combine_params(folds, "c")
    w = np.array([100.0, 1 / 0.09])
    c = np.array([[0.01, rho * 0.03], [rho * 0.03, 0.09]])
    assert val["k"] == pytest.approx((100.0 * 1.0 + 3.0 / 0.09) / w.sum())
    assert se["k"] == pytest.approx(math.sqrt(w @ c @ w) / w.sum())
    # A fold or window without a standard error drops out of the mean, and nothing warns.
    for parts in ([_analysis(0, 1.0, 0.1, seg), _analysis(0, 3.0, math.inf, mirror)],
                  [_analysis(0, 1.0, 0.1, seg), _analysis(1, 3.0, math.inf, seg)]):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            val, se = _combine_params(parts, "c")
        assert (val["k"], se["k"]) == (pytest.approx(1.0), pytest.approx(0.1))
    # Two windows are independent: the plain inverse-variance standard error, as before cross-fitting.
    windows = [_analysis(0, 1.0, 0.2, seg), _analysis(1, 3.0, 0.2, seg)]
    assert _combine_params(windows, "c")[1]["k"] == pytest.approx(0.2 / math.sqrt(2.0))


def test_cross_fitting_doubles_the_held_out_samples_and_keeps_the_report_per_window(cases):
    ec = apply_effect(cases[1], "measurement_skew", 0.03, seed=3)
    one = diagnose(ec.window, config=DiagnosisConfig(cross_fit=False))
    two = diagnose(ec.window, config=DiagnosisConfig(cross_fit=True))
    assert two.verdict == "explained" and two.cause == "measurement_skew"
    assert two.held_out.windows == 1 and len(two.held_out.t_start) == 2 and two.held_out.folds == 2
    assert one.held_out.folds == 1
    assert two.held_out.n == 2 * one.held_out.n
    assert two.held_out.t_start[1] == pytest.approx(2.0) and two.held_out.t_end[1] < two.held_out.t_start[0]
    assert len(two.series) == 1 and two.located == one.located
    # The same effect judged on twice the held-out data: a larger score statistic.
    assert two.candidate("measurement_skew").score_z > one.candidate("measurement_skew").score_z


def test_clean_windows_stay_consistent_with_cross_fitting(cases):
    for c in cases:
        rep = diagnose(c.window, config=DiagnosisConfig(cross_fit=True))
        assert rep.verdict == "consistent", (c.window.bus, rep.message)
        assert all(e.score_z is None or np.isfinite(e.score_z) for e in rep.missing_physics)


def test_a_relay_is_judged_on_the_time_ordered_fold_only(cases):
    from aslm_core.diagnosis import pipeline
    from aslm_core.diagnosis.candidates import LIBRARY

    config = DiagnosisConfig(cross_fit=True)
    a = pipeline._analyse(cases[0].window, None, None, config)
    b = pipeline._second_fold(a, config)
    assert b.seg.held_out_first and b.seg.mirror_gap == 100
    relay = {n for n, c in LIBRARY.items() if c.time_ordered_only}
    assert relay == {"switched_shunt"}
    assert relay <= set(a.fits) and not relay & set(b.fits)
    assert set(b.fits) == set(a.fits) - relay
    # Its statistics are its time-ordered folds'; the others' are both folds', Stouffer-combined.
    assert pipeline._having([a, b], "switched_shunt") == [a]
    e = pipeline._entry([a, b], "switched_shunt", 3.0)
    assert e.score_z == pytest.approx(a.comps["switched_shunt"].score_z)
    # Ranked against sums over two folds, its one fold's gain counts twice (its mean per fold × the folds).
    assert e.penalised_gain == pytest.approx(2.0 * a.comps["switched_shunt"].penalised_gain)
    e = pipeline._entry([a, b], "frequency_dependence", 3.0)
    z = (a.comps["frequency_dependence"].score_z + b.comps["frequency_dependence"].score_z) / math.sqrt(2.0)
    assert e.score_z == pytest.approx(z)
    g = a.comps["frequency_dependence"].penalised_gain + b.comps["frequency_dependence"].penalised_gain
    assert e.penalised_gain == pytest.approx(g)
