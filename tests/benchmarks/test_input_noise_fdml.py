"""The frequency-domain joint likelihood with the transient term (``benchmarks.input_noise_fdml``): the DFT relation with
its transient is exact for the discretised linear motor (plain and differenced), the transient term takes the clean
records' misfit down, the likelihood's gradient in the bands' spectrum is right, the motor's nonlinear remainder is
second order and removes the exact-input bias it causes, and the restarted descent finds the same maximum from 3 % off
as from the truth."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import common
from benchmarks.input_noise_fdml import (
    WindowDFT,
    _edge_basis,
    fdml,
    misfit,
    nll_nuisance,
    own_model_pq,
    remainder,
    response,
)
from benchmarks.input_noise_kalman import first_order_hold, linear_motor


def _window(n: int = 1000, dt: float = 0.01, seed: int = 3):
    """A window with smooth random inputs and P, Q from the discretised linear motor plus static slopes, simulated
    in the time domain from a non-zero initial state; noise-free."""
    rng = np.random.default_rng(seed)
    d = np.array([1.2, 0.35, 0.6, 0.45])
    v0, w_off, f0 = 1.0, 0.02, 50.0
    k = np.fft.rfftfreq(n, dt)
    u = np.fft.irfft(np.fft.rfft(rng.standard_normal((2, n)), axis=1) * (k < 3.0), n, axis=1) * [[0.01], [0.02]]
    t = np.arange(n) * dt
    # V's mean and θ's least-squares line are the window's operating point and frame: draw the inputs about them.
    u[0] -= u[0].mean()
    basis = np.stack([np.ones(n), t], axis=1)
    u[1] -= basis @ np.linalg.lstsq(basis, u[1], rcond=None)[0]
    V = v0 + u[0]
    theta = u[1] + w_off * t
    a_m, b_m, c_m, d_m = linear_motor(d, v0, w_off, 2.0 * np.pi * f0)
    phi, g0, g1 = first_order_hold(a_m, b_m, dt)
    z = np.array([0.01, -0.02, 0.005])
    y = np.empty((n, 2))
    cp, cq = 0.8, 1.5
    for i in range(n):
        y[i] = c_m @ z + d_m @ u[:, i] + [cp * u[0, i], cq * u[0, i]]
        if i + 1 < n:
            z = phi @ z + g0 @ u[:, i] + g1 @ u[:, i + 1]
    return V, theta, 0.9 + y[:, 0], 0.4 + y[:, 1], dt, f0, d, cp, cq


@pytest.mark.parametrize("poles", [(0j,), (-3 + 0j,), (-1.2 + 6.0j,)])
def test_the_edge_basis_is_the_segment_dft_of_an_autoregression_less_its_circular_part(poles):
    # x_t from its AR recursion, started before the segment: X(k) = E(k)/A(ζ_k⁻¹) + the edge term, real coefficients.
    dt, n = 0.01, 600
    p = np.exp(np.asarray(poles) * dt)
    a = np.real(np.poly(np.r_[p, p.conj()] if abs(p[0].imag) > 0 else p))  # A(z⁻¹) = 1 + a1·z⁻¹ + ...
    rng = np.random.default_rng(5)
    e = rng.standard_normal(n + 500)
    x = np.zeros(n + 500)
    for t in range(len(a) - 1, x.size):
        x[t] = e[t] - a[1:] @ x[t - 1::-1][: len(a) - 1]
    xs, es = x[500:], e[500:]
    k = np.arange(1, n // 2)
    zeta = np.exp(2j * np.pi * k / n)
    den = sum(a[j] * zeta ** (-j) for j in range(len(a)))
    rest = np.fft.fft(xs)[k] - np.fft.fft(es)[k] / den
    basis = _edge_basis(zeta, poles, dt)
    coef = np.linalg.lstsq(np.vstack([basis.real, basis.imag]), np.r_[rest.real, rest.imag], rcond=None)[0]
    assert np.linalg.norm(rest - basis @ coef) < 1e-9 * np.linalg.norm(rest)


@pytest.mark.parametrize("difference", [False, True])
def test_the_dft_with_its_transient_is_exact_for_the_discretised_motor(difference):
    V, theta, P, Q, dt, f0, d, cp, cq = _window()
    win = WindowDFT(V, theta, P, Q, dt, f0, skip_s=1.0, difference=difference)
    g, t = response(win, d, cp, cq)
    y = win.z[:, 2:] - np.einsum("kij,kj->ki", g, win.z[:, :2])
    tt = t.reshape(-1, 3)
    delta = np.linalg.lstsq(np.vstack([tt.real, tt.imag]), np.r_[y.ravel().real, y.ravel().imag], rcond=None)[0]
    rel_with = np.sum(np.abs(y - t @ delta) ** 2) / np.sum(np.abs(win.z[:, 2:]) ** 2)
    rel_without = np.sum(np.abs(y) ** 2) / np.sum(np.abs(win.z[:, 2:]) ** 2)
    assert rel_without > 1e-4
    assert rel_with < 1e-6 * rel_without


def test_the_transient_term_takes_the_clean_records_misfit_down():
    cases = common.cases(5, level=3, seed=41)
    for case in cases:
        m = misfit(case)
        none, trans = np.array(m["none"]), np.array(m["transient"])
        assert np.median(trans) < 0.1 * np.median(none)
        assert np.median(trans) < 2e-3


def test_the_gradient_in_the_bands_spectrum_matches_differences():
    V, theta, P, Q, dt, f0, d, cp, cq = _window()
    rng = np.random.default_rng(5)
    n = V.size
    V = V + 3e-4 * rng.standard_normal(n)
    theta = theta + 3e-4 * rng.standard_normal(n)
    P = P + 1e-4 * rng.standard_normal(n)
    Q = Q + 1e-4 * rng.standard_normal(n)
    win = WindowDFT(V, theta, P, Q, dt, f0, skip_s=1.0)
    g, t = response(win, d, cp, cq)
    p = 0.3 * rng.standard_normal(4 * win.nb)
    val, grad, _ = nll_nuisance(win, g, t, p)
    for j in rng.choice(p.size, 8, replace=False):
        h = 1e-6
        pp, pm = p.copy(), p.copy()
        pp[j] += h
        pm[j] -= h
        fd = (nll_nuisance(win, g, t, pp, False)[0] - nll_nuisance(win, g, t, pm, False)[0]) / (2 * h)
        assert abs(fd - grad[j]) <= 1e-4 * max(1.0, abs(fd))


def test_the_motors_remainder_is_second_order_in_the_inputs_deviations():
    case = common.cases(1, level=3, seed=41)[0]
    w = case.clean
    d = np.asarray(case.truth.d, float)
    amp = []
    for scale in (1.0, 0.5):
        V = w.V.mean() + scale * (w.V - w.V.mean())
        theta = w.theta[0] + scale * (w.theta - w.theta[0])
        win = WindowDFT(V, theta, w.P, w.Q, 0.01, w.f0, 1.0)
        r = remainder(win, d)
        assert r is not None
        amp.append(np.sqrt(np.sum(np.abs(r) ** 2)))
    # Halving the deviations quarters a second-order term (θ's line halves too, which moves the frame: not exact).
    assert 0.15 < amp[1] / amp[0] < 0.35


def test_with_the_remainder_the_exact_input_fit_is_unbiased_at_small_noise():
    """Without the remainder a small P, Q noise moved a by +0.65 % on this record (the linear motor's misfit reweighted
    between P and Q); with it the fit stays within 0.3 % (+0.18 %).  Record 2 of the same seed (+0.47 % and −0.01 %)
    was dropped from the test at stop 58: the four fits took 90 s, the suite's slowest test."""
    case = common.cases(1, level=3, seed=41)[0]
    rng = np.random.default_rng(0)
    w = case.clean
    d0 = np.asarray(case.truth.d, float)
    P = w.P + 6e-6 * rng.standard_normal(w.P.size)
    Q = w.Q + 6e-6 * rng.standard_normal(w.Q.size)
    lin, _ = fdml(w.V, w.theta, P, Q, 0.01, w.f0, d0)
    nl, _ = fdml(w.V, w.theta, P, Q, 0.01, w.f0, d0, nonlinear=2)
    assert abs(lin[0] / d0[0] - 1.0) > 0.004
    assert abs(nl[0] / d0[0] - 1.0) < 0.003


def test_the_fit_finds_the_same_maximum_from_the_truth_and_from_3_percent_off():
    """P, Q from the candidate's own linear model with exact inputs and noise at DL 3's level: started 3 % off in every
    parameter the fit ends where it ends from the truth, close to the truth (the restarts; without them it stopped
    5,000 nats short)."""
    case = common.cases(1, level=3, seed=43)[0]
    cl = case.clean
    d = np.asarray(case.truth.d, float)
    P, Q = own_model_pq(case, np.random.default_rng(0), 6e-5, 6e-5)
    nv = np.array([0.0, 0.0, 3.6e-9, 3.6e-9])
    ref, rec_ref = fdml(cl.V, cl.theta, P, Q, 0.01, cl.f0, d, noise_var=nv)
    got, rec = fdml(cl.V, cl.theta, P, Q, 0.01, cl.f0, d * np.array([1.03, 0.97, 1.03, 0.97]), noise_var=nv)
    assert np.all(np.abs(ref / d - 1.0) < 5e-3)
    assert np.all(np.abs(got / ref - 1.0) < 1e-3)
    assert abs(rec["nll"] - rec_ref["nll"]) < 0.05


def _rule_cells(scale: dict, windows: range = range(50, 100), base: float = 1.0, own: float = 0.0,
                control: float | None = None) -> dict:
    """Rows of a rule's six cells over ``windows``: the likelihood's errors a fixed draw, the default's the same draw
    times ``scale[(cell, parameter)]`` (``base`` elsewhere) plus an independent part of std ``own``, the control's (where
    given) the draw times ``control``."""
    rng = np.random.default_rng(59)
    cells = {}
    for level in (1, 2, 3):
        for cls in ("0.03 % / 3e-4 rad", "0.1 % / 1e-3 rad"):
            key = f"{level}|{cls}"
            err = 0.03 * rng.standard_normal((len(windows), 4))
            extra = own * rng.standard_normal((len(windows), 4))
            k = np.array([scale.get((key, j), base) for j in range(4)])
            cells[key] = [{"i": i, "fdml": (1.0 + e).tolist(), "default": (1.0 + k * e + o).tolist(),
                           **({} if control is None else {"control": (1.0 + control * e).tolist()})}
                          for i, e, o in zip(windows, err, extra, strict=True)]
    return cells


def _verdict_cells(scale: dict) -> dict:
    """The likelihood rule's rows, windows 50-99 (:func:`_rule_cells`)."""
    return _rule_cells(scale)


def test_the_likelihood_rule_counts_each_cells_ratio():
    from benchmarks.input_noise_fdml import likelihood_verdict

    assert likelihood_verdict(_verdict_cells({}))["met"]
    two = {("1|0.1 % / 1e-3 rad", 3): 1.5, ("2|0.03 % / 3e-4 rad", 0): 1.4}
    assert likelihood_verdict(_verdict_cells(two))["met"]  # 22 of 24 within 1.3 x, none above 1.6 x
    three = {**two, ("3|0.1 % / 1e-3 rad", 1): 1.35}
    assert not likelihood_verdict(_verdict_cells(three))["met"]
    assert not likelihood_verdict(_verdict_cells({("3|0.03 % / 3e-4 rad", 2): 1.7}))["met"]
    cells = _verdict_cells({})
    cells["1|0.1 % / 1e-3 rad"] = cells["1|0.1 % / 1e-3 rad"][:-1]
    with pytest.raises(ValueError):
        likelihood_verdict(cells)
    del cells["1|0.1 % / 1e-3 rad"]
    assert not likelihood_verdict(cells)["met"]


def _efficiency_cells(scale: dict, control: float = 1.5) -> dict:
    """The efficiency rule's rows, windows 0-99 (:func:`_rule_cells`): the default 1.05 × the likelihood's errors
    where ``scale`` does not say otherwise, plus a small independent part."""
    return _rule_cells(scale, range(100), base=1.05, own=0.003, control=control)


def test_the_efficiency_rule_needs_the_mean_no_cell_clearly_off_and_a_control_that_fails():
    from benchmarks.input_noise_fdml import efficiency_verdict

    v = efficiency_verdict(_efficiency_cells({}))
    assert v["met"] and 1.04 < v["default"]["geometric_mean"] < 1.07
    assert not v["control"]["passes"] and v["control"]["geometric_mean"] > 1.15
    # Every ratio 1.2: the mean fails though no single cell is clearly above 1.3.
    everywhere = {(f"{lv}|{c}", j): 1.2 for lv in (1, 2, 3) for c in ("0.03 % / 3e-4 rad", "0.1 % / 1e-3 rad")
                  for j in range(4)}
    v = efficiency_verdict(_efficiency_cells(everywhere))
    assert not v["met"] and not v["default"]["wholly_above_1_3"]
    # One cell x parameter at 2: the mean holds (1.08) but its interval lies above 1.3.
    v = efficiency_verdict(_efficiency_cells({("2|0.1 % / 1e-3 rad", 3): 2.0}))
    assert v["default"]["geometric_mean"] <= 1.15
    assert v["default"]["wholly_above_1_3"] == ["2|0.1 % / 1e-3 rad Tm"] and not v["met"]
    # A control as good as the default: the rule cannot tell them apart, so it is not met.
    assert not efficiency_verdict(_efficiency_cells({}, control=1.05))["met"]
    cells = _efficiency_cells({})
    cells["3|0.1 % / 1e-3 rad"] = cells["3|0.1 % / 1e-3 rad"][1:]
    with pytest.raises(ValueError):
        efficiency_verdict(cells)
