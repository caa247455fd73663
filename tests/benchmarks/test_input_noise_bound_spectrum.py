"""benchmarks/input_noise_bound_spectrum.py: the per-bin Fisher information against the score's spread, the model's
D-derivative against differences, and the bounds' order on one window."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from benchmarks import common  # noqa: E402
from benchmarks.input_noise_bound import LEVELS  # noqa: E402
from benchmarks.input_noise_bound_spectrum import (  # noqa: E402
    WIDTHS_HZ,
    _sqrtm,
    band_loss,
    bounds,
    fisher_per_bin,
    transfer,
    window_bounds,
)


def _toy(m: int = 6, seed: int = 0):
    """A 2×2 transfer and a coherent input spectrum on m bins, and ∂H for six parameters."""
    rng = np.random.default_rng(seed)
    h = rng.standard_normal((m, 2, 2)) + 1j * rng.standard_normal((m, 2, 2))
    dh = 0.3 * (rng.standard_normal((6, m, 2, 2)) + 1j * rng.standard_normal((6, m, 2, 2)))
    a = rng.standard_normal((m, 2, 2)) + 1j * rng.standard_normal((m, 2, 2))
    sx = a @ a.conj().transpose(0, 2, 1) + 0.1 * np.eye(2)
    return h, dh, sx


def _sigma(h, sx, r_u, r_y):
    hh = h.conj().transpose(0, 2, 1)
    return np.block([[sx + np.diag(r_u), sx @ hh], [h @ sx, h @ sx @ hh + np.diag(r_y)]])


def test_fisher_per_bin_is_the_covariance_of_the_score():
    """The information is the covariance of the score of the complex Gaussian (V, θ, P, Q) per bin, checked by
    drawing z and differencing the log-likelihood in each of the ten directions (D, g, and S_x's deviations)."""
    h, dh, sx = _toy(m=1)
    r_u, r_y = (0.4, 0.2), (0.3, 0.5)
    info = fisher_per_bin(h, dh, sx, r_u, r_y)[0]
    root = _sqrtm(sx)[0]
    basis = [np.array([[1, 0], [0, 0]]), np.array([[0, 0], [0, 1]]), np.array([[0, 1], [1, 0]]),
             np.array([[0, 1j], [-1j, 0]])]

    def sigma(step: int, eps: float) -> np.ndarray:
        hx, sxx = h[0].copy(), sx[0].copy()
        if step < 6:
            hx = hx + eps * dh[step, 0]
        else:
            sxx = sxx + eps * root @ basis[step - 6] @ root
        return _sigma(hx[None], sxx[None], r_u, r_y)[0]

    rng = np.random.default_rng(1)
    s0 = sigma(0, 0.0)
    chol = np.linalg.cholesky(s0)
    n = 40_000
    z = chol @ ((rng.standard_normal((4, n)) + 1j * rng.standard_normal((4, n))) / np.sqrt(2))
    eps = 1e-6
    score = np.empty((10, n))
    for a in range(10):
        lp, lm = sigma(a, eps), sigma(a, -eps)
        # log-likelihood of CN(0, Σ): −log det Σ − zᴴ Σ⁻¹ z
        ll = [-np.log(np.linalg.det(s).real) - np.einsum("in,ij,jn->n", z.conj(), np.linalg.inv(s), z).real
              for s in (lp, lm)]
        score[a] = (ll[0] - ll[1]) / (2 * eps)
    emp = np.cov(score)
    rel = np.abs(emp - info) / np.sqrt(np.outer(np.diag(info), np.diag(info)))
    assert np.all(rel < 0.05), rel.max()
    assert np.all(np.abs(score.mean(axis=1)) < 4 * np.sqrt(np.diag(info) / n))  # the score has mean zero


def test_learnt_spectrum_never_informs_more_and_tiny_input_noise_gives_the_exact_input_bound():
    """Unknown S_x in bands costs information (learnt ≥ known, finer bands ≥ coarser), the conditional-mean part
    never exceeds the joint; with input noise → 0 the joint and the mean part meet the exact-input information
    2·Re Σ tr(R_y⁻¹·∂H·S_x·∂Hᴴ)."""
    m = 40
    h, dh, sx = _toy(m=m, seed=3)
    freqs = np.linspace(0.0, 0.1 * (m - 1), m)
    d = np.array([2.0, 1.0, 0.5, 0.8])
    r_y = (0.3, 0.5)
    b = bounds(freqs, h, dh, sx, (0.4, 0.2), r_y, d, widths=(0.2, 0.5, 2.0))
    assert np.all(b["learnt_0.2"] >= b["learnt_0.5"] * (1 - 1e-9))
    assert np.all(b["learnt_0.5"] >= b["learnt_2"] * (1 - 1e-9))
    assert np.all(b["learnt_2"] >= b["known"] * (1 - 1e-9))
    assert np.all(b["known_mean"] >= b["known"] * (1 - 1e-9))
    assert np.any(b["learnt_0.2"] > 1.02 * b["known"])  # a real loss, not a zero
    tiny = bounds(freqs, h, dh, sx, (1e-10, 1e-10), r_y, d, widths=(0.5,))
    k = slice(1, m - 1)
    ry_inv = np.diag(1.0 / np.array(r_y))
    exact = np.array([[2.0 * np.einsum("ij,kjl,kli->", ry_inv, dh[a, k] @ sx[k],
                                       dh[c, k].conj().transpose(0, 2, 1)).real for c in range(6)] for a in range(6)])
    want = np.diag(np.linalg.inv(exact))[:4] / d**2
    np.testing.assert_allclose(tiny["known"], want, rtol=1e-4)
    np.testing.assert_allclose(tiny["known_mean"], want, rtol=1e-4)


def test_band_loss_of_one_bin_bands_takes_all_the_spectrum_can_explain():
    """Bands of one bin lose at least what bands of two do (the nuisance spans more), and the loss is symmetric
    positive semi-definite."""
    h, dh, sx = _toy(m=8, seed=5)
    per_bin = fisher_per_bin(h, dh, sx, (0.4, 0.2), (0.3, 0.5))
    freqs = np.arange(8) * 0.1
    one, two = band_loss(per_bin, freqs, 0.1), band_loss(per_bin, freqs, 0.2)
    for loss in (one, two):
        np.testing.assert_allclose(loss, loss.T, atol=1e-12 * np.abs(loss).max())
        assert np.linalg.eigvalsh(loss).min() > -1e-9 * np.abs(loss).max()
    assert np.linalg.eigvalsh(one - two).min() > -1e-9 * np.abs(one).max()


def test_transfer_derivative_is_the_difference_of_the_impulse_response_in_d():
    """∂H/∂D from the simulator's forward sensitivities equals the central difference of H in each parameter."""
    case = common.cases(1, level=2, seed=43)[0]
    _, h, dh, _, _ = transfer(case)
    d = np.asarray(case.truth.d, dtype=np.float64)
    band = slice(1, 100)  # up to 10 Hz at 100 frames/s, where the fit and the bound have their information
    for j in range(4):
        step = 1e-4 * d[j]
        hs = []
        for sgn in (1.0, -1.0):
            dj = d.copy()
            dj[j] += sgn * step
            hs.append(transfer(case, dj)[1])
        fd = (hs[0] - hs[1]) / (2 * step)
        err = np.abs(fd[band] - dh[j][band]).max() / np.abs(dh[j][band]).max()
        assert err < 1e-3, (j, err)


def test_one_window_bounds_order_and_kinds():
    """On one synthetic window: every kind for both classes and levels; more input noise never informs more, the
    learnt bound is never below the known one."""
    cases = {level: common.cases(1, level=level, seed=43)[0] for level in LEVELS}
    out = window_bounds(cases, long_s=60.0)
    low, high = "0.03 % / 3e-4 rad", "0.1 % / 1e-3 rad"
    for level in LEVELS:
        b = {k: np.array(v) for k, v in out[level].items()}
        assert {f"{low}|learnt_{w:g}" for w in WIDTHS_HZ} <= set(b)
        for cls in (low, high):
            assert np.all(b[f"{cls}|learnt_0.5"] >= b[f"{cls}|known"] * (1 - 1e-9))
        assert np.all(b[f"{low}|known"] <= b[f"{high}|known"])


def test_default_on_other_seeds_uses_the_draws_of_the_other_benchmarks():
    """``--seed``'s in-process default answers as the variants benchmark's default row on the same seed (the same
    windows, noise draws and configuration)."""
    from benchmarks import input_noise_variants as iv
    from benchmarks.input_noise_bound_spectrum import default_ratios

    cases = {level: common.cases(1, level=level, seed=41) for level in LEVELS}
    own = default_ratios(cases, 41, 1)[0]
    per, _, _ = iv.run(1, 41, [])
    for level in LEVELS:
        for cls, ratio in own[level].items():
            np.testing.assert_allclose(ratio, per[f"{level}|{cls}|default"][0], rtol=1e-12)


def test_efficiency_scores_the_stored_default_against_the_stored_bounds(monkeypatch):
    """``--efficiency`` re-runs the default on the stored run's windows and draws: its z on seed 53's first windows is
    the stored default's error over the stored reference bound, window by window (the default as the run was made,
    before stop 49's 4 Hz cap on the band and stop 57's white level of P and Q)."""
    import json

    from aslm_core import input_weighting, noise
    from benchmarks.input_noise_bound_spectrum import REFERENCE, efficiency

    monkeypatch.setattr(input_weighting, "MAX_BAND_HZ", float("inf"))
    monkeypatch.setattr(noise, "WHITE_LEVEL_LR_MIN", float("inf"))

    stored = json.loads((common.RESULTS / "input_noise_bound_spectrum_seed53.json").read_text())
    n = 3
    bounds_ = stored["per_window_relative_variance"][:n]
    out = efficiency(bounds_, {level: common.cases(n, level=level, seed=53) for level in LEVELS}, 53)
    for cell, r in out.items():
        level, cls = cell.split("|")
        z = np.array([(np.array(stored["per_window_default"][i][level][cls]) - 1.0)
                      / np.sqrt(bounds_[i][level][f"{cls}|{REFERENCE}"]) for i in range(n)])
        np.testing.assert_allclose(r["rms_z"], np.sqrt(np.mean(z**2, axis=0)), rtol=1e-9)
        assert all(0.0 <= s <= 1.0 for s in r["tail_share_of_squared_error"])
