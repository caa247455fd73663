"""The hierarchical identifier against ground truth from the independent synthetic network simulator."""

from __future__ import annotations

import numpy as np
import pytest

from aslm_core import IdentificationResult, IdentifyConfig, Window, WindowError, identify, identify_many
from aslm_sim.cases import make_cases


@pytest.fixture(scope="module")
def clean_cases():
    return make_cases(10, level=None, seed=11)


@pytest.fixture(scope="module")
def noisy_cases():
    return make_cases(24, level=3, seed=12, input_noise=False)


def rel_err(result: IdentificationResult, case) -> np.ndarray:
    return result.d / case.truth.d - 1.0


def feasible(result: IdentificationResult, window: Window) -> bool:
    a, b, h2, tm = result.d
    vmin = window.V.min()
    return (10 <= a <= 80 and 3 <= b <= 30 and 0.5 <= h2 <= 3 and 0 <= tm <= window.P.mean()
            and a * vmin**2 > 2 * b * tm)


def test_noise_free_recovers_every_parameter_within_one_percent(clean_cases):
    errs = np.array([rel_err(identify(c.window), c) for c in clean_cases])
    assert np.abs(errs).max() < 0.01, errs


def test_noisy_level3_is_unbiased_and_tight(noisy_cases):
    ratios = np.array([identify(c.window).d / c.truth.d for c in noisy_cases])
    assert np.all(np.abs(ratios.mean(axis=0) - 1) < 0.01), ratios.mean(axis=0)
    assert np.all(ratios.std(axis=0) < 0.02), ratios.std(axis=0)


def test_standard_errors_match_the_spread_across_cases(noisy_cases):
    results = [identify(c.window) for c in noisy_cases]
    ratios = np.array([r.d / c.truth.d for r, c in zip(results, noisy_cases, strict=True)])
    reported = np.array([[r.stderr[k] / r.dynamic[k] for k in ("a", "b", "H2", "Tm")] for r in results])
    spread = ratios.std(axis=0)
    typical = np.median(reported, axis=0)
    assert np.all(typical > 0.4 * spread) and np.all(typical < 2.5 * spread), (typical, spread)


def test_result_always_satisfies_bounds_and_equilibrium_constraint():
    cases = make_cases(12, level=1, seed=13, input_noise=True)  # hard: errors-in-variables, no filter
    for c in cases:
        r = identify(c.window, config=IdentifyConfig(n_starts=2))
        assert feasible(r, c.window), (r.dynamic, c.window.V.min())


def test_warm_start_alone_reaches_the_same_optimum_with_fewer_evaluations(noisy_cases):
    c = noisy_cases[0]
    full = identify(c.window)
    warm = identify(c.window, warm_start=full.d * np.array([1.05, 0.95, 1.04, 0.97]),
                    config=IdentifyConfig(n_starts=0))
    np.testing.assert_allclose(warm.d, full.d, rtol=1e-4)
    assert warm.evaluations < full.evaluations


def test_no_start_at_all_is_a_clear_error(clean_cases):
    with pytest.raises(ValueError, match="n_starts is 0 and no warm_start"):
        identify(clean_cases[0].window, config=IdentifyConfig(n_starts=0))
    with pytest.raises(ValueError, match="n_starts is 0 and some windows have no warm start"):
        identify_many([c.window for c in clean_cases[:2]], warm_starts=[clean_cases[0].truth.d, None],
                      config=IdentifyConfig(n_starts=0))


def test_objectives_agree_on_clean_data(clean_cases):
    c = clean_cases[0]
    ds = [identify(c.window, config=IdentifyConfig(objective=o)).d for o in ("paper", "ml", "ssq")]
    for d in ds[1:]:
        np.testing.assert_allclose(d, ds[0], rtol=5e-3)


def test_exponential_static_model(clean_cases):
    c = clean_cases[1]
    r = identify(c.window, config=IdentifyConfig(static="exponential"))
    assert set(r.static) == {"P0", "np", "Q0", "nq"}
    assert np.abs(rel_err(r, c)).max() < 0.02
    # P0 is the static active power at V = 1 pu: total mean P minus the motor's Tm, roughly.
    assert r.static["P0"] == pytest.approx(c.window.P.mean() - r.dynamic["Tm"], rel=0.05)


def test_papers_euler_mode_is_biased_where_rk4_is_not(clean_cases):
    e_rk4 = np.array([rel_err(identify(c.window), c) for c in clean_cases[:6]])
    e_eul = np.array([rel_err(identify(c.window, config=IdentifyConfig(integrator="euler")), c)
                      for c in clean_cases[:6]])
    assert np.abs(e_eul).mean() > 3 * np.abs(e_rk4).mean()


def test_nominal_frequency_is_used():
    c = make_cases(1, level=None, seed=14, f0=60.0)[0]
    assert c.window.f0 == 60.0
    right = identify(c.window)
    wrong = identify(Window(c.window.t, c.window.V, c.window.theta, c.window.P, c.window.Q, f0=50.0))
    assert np.abs(rel_err(right, c)).max() < 0.01
    # Only H2/ω0 is identifiable (ω0 multiplies s, and ds/dt ∝ 1/H2): a wrong f0 rescales H2.
    assert wrong.dynamic["H2"] == pytest.approx(right.dynamic["H2"] * 50 / 60, rel=2e-3)


def test_fit_degree_is_eq9_over_the_regression_samples(clean_cases):
    c = clean_cases[2]
    r = identify(c.window)
    assert 0.99 < r.fit["fd_p"] <= 1.0 and 0.99 < r.fit["fd_q"] <= 1.0
    dt = c.window.t[1] - c.window.t[0]
    assert r.quality["skip_s"] >= IdentifyConfig().skip_s - 1e-9
    assert r.quality["n_regression"] == c.window.t.size - round(r.quality["skip_s"] / dt)


# ----------------------------------------------------------------------------------- bad input
def _window(n=1001, dt=0.01, **over):
    rng = np.random.default_rng(0)
    t = np.arange(n) * dt
    base = dict(t=t, V=1 + 0.002 * rng.standard_normal(n), theta=0.01 * rng.standard_normal(n),
                P=1 + 0.01 * rng.standard_normal(n), Q=0.3 + 0.01 * rng.standard_normal(n))
    base.update(over)
    return Window(**base)


@pytest.mark.parametrize(
    ("make", "reason"),
    [
        (lambda: _window(V=np.ones(5)), "shape"),
        (lambda: _window(n=300), "too_short"),
        (lambda: _window(t=np.r_[np.arange(500), np.arange(499, 1000)] * 0.01), "non_monotonic"),
        (lambda: _window(t=np.arange(1001) * 0.01 + np.r_[0, 0.004 * (-1) ** np.arange(1000)]), "non_uniform"),
        (lambda: _window(V=np.where(np.arange(1001) % 100 < 20, np.nan, 1.0)), "gaps"),
        (lambda: _window(P=np.where(np.arange(1001) == 500, np.inf, 1.0)), "non_finite"),
        (lambda: _window(t=np.r_[np.nan, np.arange(1, 1001) * 0.01]), "non_finite"),
        (lambda: _window(V=np.full(1001, 0.1)), "bad_range"),
        (lambda: _window(V=np.ones(1001)), "no_excitation"),
    ],
)
def test_bad_input_raises_clear_error(make, reason):
    with pytest.raises(WindowError) as info:
        identify(make())
    assert info.value.reason == reason
    assert str(info.value).startswith(reason + ":") and len(str(info.value)) > len(reason) + 5


def test_short_gaps_are_repaired_and_flagged(clean_cases):
    c = clean_cases[3]
    w = c.window
    keep = np.ones(w.t.size, bool)
    keep[400:403] = False  # three missing time stamps
    P = w.P.copy()
    P[700] = np.nan  # one missing value
    gappy = Window(w.t[keep], w.V[keep], w.theta[keep], P[keep], w.Q[keep], f0=w.f0)
    r = identify(gappy)
    assert any(f.startswith("repaired_samples:") for f in r.flags)
    assert np.abs(rel_err(r, c)).max() < 0.02


def test_batch_keeps_order_and_isolates_bad_windows(clean_cases):
    windows = [clean_cases[0].window, _window(n=300), clean_cases[1].window]
    out = identify_many(windows, workers=2)
    assert isinstance(out[0], IdentificationResult) and isinstance(out[2], IdentificationResult)
    assert isinstance(out[1], WindowError) and out[1].reason == "too_short"
    np.testing.assert_allclose(out[2].d, identify(windows[2]).d, rtol=1e-12)


def test_every_random_start_reaches_the_global_optimum():
    """The paper's §VI.C reliability test in small: LM from random feasible starts, one window per level."""
    from aslm_core.identify import Problem, levenberg_marquardt
    from aslm_core.preprocess import prepare

    for level, seed in ((1, 31), (3, 32)):
        c = make_cases(1, level=level, seed=seed, input_noise=False)[0]
        problem = Problem(prepare(c.window), c.window.f0, IdentifyConfig())
        rng = np.random.default_rng(seed)
        runs = [levenberg_marquardt(problem, problem.random_start(rng)) for _ in range(25)]
        best = min(runs, key=lambda r: r["cost"])
        misses = [r for r in runs if np.abs(r["d"] / best["d"] - 1).sum() >= 0.1]
        assert not misses, [(r["status"], r["iterations"], r["d"]) for r in misses]
        assert all(r["status"] == "converged" for r in runs)


def test_coarse_to_fine_reaches_the_full_grid_optimum_for_less_work():
    """Starts descending on the coarse grid end at the same optimum as a full-grid descent for less work
    (coarse evaluations counted at their cost); the coarse grid drives the same ODE with measured
    half-step inputs."""
    from aslm_core.identify import Problem, _descend, levenberg_marquardt
    from aslm_core.preprocess import prepare

    cases = make_cases(6, level=1, seed=41, input_noise=False)
    work_full = work_c2f = 0.0
    for c in cases:
        full = identify(c.window, config=IdentifyConfig(coarse_to_fine=False))
        c2f = identify(c.window)
        np.testing.assert_allclose(c2f.d, full.d, rtol=1e-4)
        assert c2f.objective <= full.objective * (1 + 1e-6)
        # Work in full-grid evaluations: a coarse one costs a quarter at 100 frames/s.
        for coarse_first in (False, True):
            pr = Problem(prepare(c.window), c.window.f0, IdentifyConfig())
            rng, runs = np.random.default_rng(0), []
            for _ in range(3):
                known = [r["d"] for r in runs if r["status"] in ("converged", "stalled")]
                runs.append(_descend(pr, pr.random_start(rng), IdentifyConfig(), known, coarse=coarse_first))
            n_coarse = pr.coarse().evaluations if coarse_first else 0
            work = (pr.evaluations - n_coarse) + n_coarse / 4
            if coarse_first:
                work_c2f += work
            else:
                work_full += work
    assert work_c2f < 0.8 * work_full, (work_c2f, work_full)
    problem = Problem(prepare(cases[0].window), cases[0].window.f0, IdentifyConfig())
    coarse = problem.coarse()
    assert coarse is not None and coarse.dt == pytest.approx(4 * problem.dt)
    # Half-step inputs of the coarse grid are the measured samples in between.
    np.testing.assert_array_equal(coarse.vdm[:5], problem.vd[2:20:4])
    # The coarse optimum lies in the full optimum's basin: polishing it on the full grid ends where a
    # full-grid descent from the truth ends.
    d = cases[0].truth.d
    assert coarse.l == pytest.approx(problem.l / 4, abs=1)
    ref = levenberg_marquardt(problem, d)
    near = levenberg_marquardt(coarse, d)
    assert np.all(np.abs(near["d"] / ref["d"] - 1) < 0.15), (near["d"], ref["d"])
    np.testing.assert_allclose(levenberg_marquardt(problem, near["d"])["d"], ref["d"], rtol=1e-5)
    # No coarse grid for the paper's Euler (unstable at long steps) or for a 25 Hz window (step > 40 ms).
    assert Problem(prepare(cases[0].window), 50.0, IdentifyConfig(integrator="euler")).coarse() is None
    w = cases[0].window
    slow = Window(t=w.t[::4], V=w.V[::4], theta=w.theta[::4], P=w.P[::4], Q=w.Q[::4], f0=w.f0)
    assert Problem(prepare(slow), slow.f0, IdentifyConfig()).coarse() is None


def test_standard_errors_follow_the_objectives_own_spread_when_channels_differ_in_noise():
    """Eq. 7 weights P and Q by 1/‖r‖, not 1/σ²: with P at 14 dB and Q at 34 dB its estimates spread
    ~1.5× wider than the inverse Fisher information. The reported SE (sandwich form) must follow the
    estimator actually used; the ``ml`` objective reaches the smaller spread."""
    import dataclasses

    c = make_cases(2, level=None, seed=77)[1]
    w = c.window
    rng = np.random.default_rng(0)
    sp, sq = 10 ** (-14 / 20) * np.std(w.P), 10 ** (-34 / 20) * np.std(w.Q)
    noisy = [dataclasses.replace(w, P=w.P + rng.normal(0, sp, w.P.size), Q=w.Q + rng.normal(0, sq, w.Q.size))
             for _ in range(300)]
    spread = {}
    for obj in ("paper", "ml"):
        res = identify_many(noisy, config=IdentifyConfig(objective=obj), workers=2)
        d = np.array([r.d for r in res])
        se = np.array([[r.stderr[k] for k in ("a", "b", "H2", "Tm")] for r in res])
        ratio = d.std(axis=0) / se.mean(axis=0)
        assert np.all((ratio > 0.85) & (ratio < 1.15)), (obj, ratio)
        spread[obj] = d.std(axis=0)
    assert np.all(spread["ml"] < 0.85 * spread["paper"]), spread


def test_slow_motor_skips_its_initial_transient():
    """A slow slip mode (τ ≈ 0.43 s) carries the steady-state-at-the-first-sample error past 1 s.

    With the paper's fixed 1 s skip this noise-free case is off by 4 % (a); five time constants of the
    identified motor's slowest mode recover it within the 1 % target.
    """
    c = make_cases(1, level=None, seed=818, input_noise=False)[0]
    fixed = identify(c.window, config=IdentifyConfig(transient_tau=0.0))
    assert np.abs(rel_err(fixed, c)).max() > 0.02
    r = identify(c.window)
    assert 1.8 < r.quality["skip_s"] <= IdentifyConfig().skip_max_s
    assert np.abs(rel_err(r, c)).max() < 0.01, rel_err(r, c)
