"""The joint likelihood over latent V and θ in the frequency domain, with the transient term (issue 11, stop 53; a
candidate).

Stop 46 built this likelihood on the windows' tapered DFTs and it failed: a finite window's DFT carries the response to
the inputs before the window, and the model Y = H·X had no term for it (docs/numerics.md, "Stop 46"). For a linear
system of finite order the term is exact and small: with x_{t+1} = Φ·x_t + B·u_t, y_t = C·x_t + D·u_t and the DFT
over N samples without a taper, Y(k) = G(ζ_k)·U(k) + C·(ζ_k·I − Φ)⁻¹·ζ_k·(x_0 − x_N), ζ_k = exp(2πjk/N)
(Pintelon & Schoukens, *System Identification*, the transient term). Here x is the linearised motor's three states,
so the term has three real unknowns; it is linear in them and is profiled out by generalised least squares.

The model, per window (V about its mean, θ about its least-squares line, whose slope sets the frame the motor is
linearised in, as :mod:`benchmarks.input_noise_kalman`; the samples after the identifier's skipped first second):

* the latent inputs' DFT X(k) ~ CN(0, S_x(f_k)), S_x = S0^½·E_b·S0^½ with S0 the window's own smoothed estimate and
  E_b a Hermitian 2×2 per band of :data:`WIDTH_HZ` (four real parameters a band, as stop 46's learnt bound);
* z(k) = [V, θ, P, Q](k) = [X, G·X + T·Δ] + noise, G the motor (paper eq. 4–5) linearised about its steady state and
  discretised with the inputs linear between samples, plus the static slopes c_P, c_Q on ΔV; the noise white with
  the window's floors (:func:`aslm_core.noise.channel_floors`, read above 5 Hz, independent of the bins used);
* only the bins up to :data:`TOP_HZ`, where the bound says the information is.

The fit: L-BFGS-B over D (in its bounds), c_P, c_Q and the bands' E_b together, from the default's D, the static
slopes of the measured inputs and E_b = I (the bands alone first); the gradient analytic in E_b, by central differences
in D and the slopes, each of these scaled by its curvature; restarted while a restart gains (:func:`_fit`).
``--nonlinear 2`` takes the motor's nonlinear remainder off P and Q first (:func:`remainder`). Not adopted
(docs/numerics.md, "Stop 53: the frequency-domain joint likelihood with the transient term").

    .venv/bin/python -m benchmarks.input_noise_fdml [--seed 41] [--n 50] [--cells "3|0.1 % / 1e-3 rad"] [--nonlinear 2]
        [--oracle-noise] [--oracle-spectrum] [--own-model] [--difference] [--exact DL] [--check] [--report NAME]
        [--circular [gaussian|phases|segment]] [--edge [POLE ...]]
    .venv/bin/python -m benchmarks.input_noise_fdml --likelihood-verdict | --efficiency-verdict | --efficiency-development

``--efficiency-verdict`` judges stop 60's :data:`EFFICIENCY_RULE` (the default's σ against this estimator's on fresh seed
100) from its stored runs and reads issue 11's σ targets beside it; ``--efficiency-development`` prints the same on the
rule's development windows (seed 43's 0-99) with this tree's default and control.

``--circular``, ``--edge`` (stop 54): data drawn from the fit's own model with the latent inputs circular Gaussian, the
window's own with their phases scrambled, or a segment of a longer Gaussian draw (:func:`circular_draw`); and the
inputs' edge term of a process with the given poles (:class:`WindowDFT`).  Which of these reach the bound says where
stop 53's own-model gap comes from (docs/numerics.md, "Stop 54: where the joint likelihood's own-model gap comes
from").

On seed 43 each row carries the window's structural bound (``input_noise_bound_n300.json``) and its learnt bound
below 5 Hz (``input_noise_bound_spectrum.json``); the summary gives σ over both RMS bounds, the robust spread of the
errors over the structural bound and the windows more than 3 bounds off.

``--check``: on the clean records at the truth, P's and Q's relative misfit |Y − G·X − T·Δ|² / |Y|² per band, with and
without the transient term (stop 46's measurement of why the tapered form failed).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
from scipy import optimize  # noqa: E402

from aslm_core import IdentifyConfig, identify, motor, noise  # noqa: E402
from aslm_core.params import dynamic_bounds  # noqa: E402
from aslm_core.preprocess import white_floor  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import identified_draws, noisy_draws  # noqa: E402
from benchmarks.input_noise_bound import long_inputs  # noqa: E402
from benchmarks.input_noise_bound_spectrum import signal_spectrum  # noqa: E402
from benchmarks.input_noise_kalman import first_order_hold, linear_motor, linear_response  # noqa: E402

LEVELS = (1, 2, 3)
DEFAULT = IdentifyConfig()
#: The efficiency rule's control: the default's Wiener-smoothed output error without its S-weighted refinement.
CONTROL = replace(DEFAULT, input_weighting="none")
#: Band width of the learnt spectrum's relative deviation [Hz] (stop 46's learnt bound).
WIDTH_HZ = 0.5
#: Highest bin used [Hz]: above it the signal lies under the PMU floor (stop 46).
TOP_HZ = 5.0
#: An exact input's noise variance as a fraction of its floor band's level: the likelihood needs Σ positive [-].
RU_MIN = 1e-4
#: Bands of the misfit check [Hz] (stop 46's).
MISFIT_BANDS = ((0.0, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 5.0))


class WindowDFT:
    """One window's DFTs over the regression samples, its operating point, floors and the inputs' smoothed spectrum."""

    def __init__(self, V, theta, P, Q, dt: float, f0: float, skip_s: float, difference: bool = False,
                 edge: tuple[complex, ...] = ()):
        n = V.size
        k0 = int(math.ceil(skip_s / dt - 1e-9))
        t = np.arange(n) * dt
        slope, icpt = np.polyfit(t, theta, 1)
        self.dt, self.omega0, self.w_off = dt, motor.omega0_of(f0), float(slope)
        self.v0 = float(V.mean())
        full = np.stack([V - self.v0, theta - (slope * t + icpt), P - P.mean(), Q - Q.mean()])
        self.V, self.theta, self.u, self.k0 = np.asarray(V, float), np.asarray(theta, float), full[:2], k0
        x = full[:, k0:]
        self.difference = difference
        self.l = x.shape[1]
        freqs = np.fft.rfftfreq(self.l, dt)
        self.sel = (freqs > 0) & (freqs <= TOP_HZ)
        self.freqs = freqs[self.sel]
        self.zeta = np.exp(2j * np.pi * np.arange(freqs.size)[self.sel] / self.l)
        # Differenced, every channel (a linear system's relation and its transient hold for the differences too): the
        # inputs' spectrum is flatter, so their DFT bins should leak less into each other (tried against the own-model
        # gap, and worse: docs/numerics.md, stop 53); white noise becomes MA(1), 2·σ²·(1 − cos ω), :attr:`gain` per bin.
        self.gain = np.abs(1.0 - 1.0 / self.zeta) ** 2 if difference else np.ones(self.zeta.size)
        # The inputs' own edge (stop 54): a segment of an integrated process x_t = x_{t−1} + e_t has the DFT
        # E(k)/(1 − ζ_k⁻¹) + (x_{−1} − x_{N−1})/(1 − ζ_k⁻¹), independent bins plus one real unknown per input whose
        # shape is known (a leftover linear trend has the same shape); an AR(1) with pole p the same with 1 − p·ζ_k⁻¹,
        # a pair of complex poles two real unknowns over (1 − p·ζ_k⁻¹)(1 − p̄·ζ_k⁻¹).  Without it that common part
        # leaks into every bin and the bins' prior, independent, cannot see it as a few numbers.  ``edge``: the
        # generating process's poles in the s-plane [1/s] (0: the integrator; one of each complex pair).
        if edge and difference:
            raise ValueError("the input edge term is written for the undifferenced DFTs")
        self.tau = _edge_basis(self.zeta, edge, dt) / math.sqrt(self.l) if edge else None
        self.z = (np.fft.rfft(self._differenced(full), axis=1).T / math.sqrt(self.l))[self.sel]
        self.z_measured = self.z.copy()
        self.band = np.floor((self.freqs - self.freqs[0]) / WIDTH_HZ + 1e-9).astype(int)
        self.nb = int(self.band.max()) + 1
        fl = noise.channel_floors(V, theta, P, Q, 1.0 / dt)
        # An input whose floor band is not white is exact (the identifier's rule): its floor is its own content.
        self.ru = np.array([fl[f"noise_{c}"] if white_floor(fl, c) else 0.0 for c in ("v", "theta")]) ** 2
        self.ru = np.maximum(self.ru, RU_MIN * np.array([fl["noise_v"], fl["noise_theta"]]) ** 2)
        self.ry = np.array([fl["noise_p"], fl["noise_q"]]) ** 2
        own = noise.pooled_spectrum([noise.input_periodogram(x[:2], 1.0 / dt)], top_hz=TOP_HZ + noise.WIENER_SMOOTH_HZ)
        s0 = noise.spectrum_at(own, self.freqs) + 0.1 * np.diag(self.ru)
        self.root = _root(s0 * self.gain[:, None, None])

    def _differenced(self, x: np.ndarray) -> np.ndarray:
        """The regression samples of x (c, n), differenced when :attr:`difference` (the first from the sample before)."""
        return np.diff(x[:, self.k0 - 1:], axis=1) if self.difference else x[:, self.k0:]


def _edge_basis(zeta: np.ndarray, poles: tuple[complex, ...], dt: float) -> np.ndarray:
    """The edge term's shapes (m, nb) at the bins ζ for a process with these s-plane poles [1/s] (:class:`WindowDFT`)."""
    cols = []
    for s in poles:
        p = complex(np.exp(complex(s) * dt))
        if abs(p.imag) < 1e-12:
            cols.append(1.0 / (1.0 - p.real / zeta))
        else:
            den = (1.0 - p / zeta) * (1.0 - p.conjugate() / zeta)
            cols += [1.0 / den, (1.0 / zeta) / den]
    return np.stack(cols, axis=1)


def _root(s: np.ndarray) -> np.ndarray:
    """Hermitian square root per bin, eigenvalues floored at 1e-30."""
    w, v = np.linalg.eigh(s)
    return (v * np.sqrt(np.maximum(w, 1e-30))[:, None, :]) @ v.conj().transpose(0, 2, 1)


def response(win: WindowDFT, d: np.ndarray, cp: float, cq: float) -> tuple[np.ndarray, np.ndarray] | None:
    """G (m, 2, 2) from [ΔV, Δθ] to [ΔP, ΔQ] and the transient's T (m, 2, 3) at the window's bins; None without a
    steady state.

    With the inputs linear between samples z_{k+1} = Φ·z_k + Γ0·u_k + Γ1·u_{k+1}; the state w = z − Γ1·u makes it
    w_{k+1} = Φ·w_k + (Φ·Γ1 + Γ0)·u_k, y = C·w + (C·Γ1 + D)·u, whose DFT is exact with the transient term."""
    lin = linear_motor(d, win.v0, win.w_off, win.omega0)
    if lin is None:
        return None
    a_m, b_m, c_m, d_m = lin
    phi, g0, g1 = first_order_hold(a_m, b_m, win.dt)
    b = phi @ g1 + g0
    dd = c_m @ g1 + d_m
    dd[0, 0] += cp
    dd[1, 0] += cq
    res = np.linalg.inv(win.zeta[:, None, None] * np.eye(3) - phi)
    g = c_m @ res @ b + dd
    return g, (c_m @ res) * win.zeta[:, None, None]


def linear_playback(win: WindowDFT, lin: tuple) -> np.ndarray:
    """[ΔP_im, ΔQ_im] (n, 2) [pu] of the linearised motor ``lin`` (:func:`~benchmarks.input_noise_kalman.linear_motor`)
    driven by the window's input deviations over the whole window, inputs linear between samples, from zero state."""
    return linear_response(lin, win.u.T, win.dt)


def remainder(win: WindowDFT, d: np.ndarray) -> np.ndarray | None:
    """The motor's nonlinear remainder at the window's bins (m, 2): the DFT of the compiled simulator's P_im, Q_im
    (paper eq. 4–5, from the steady state at the first sample) minus the linearised motor's response, both driven by
    the measured inputs over the whole window; None without a steady state.  Second order in the inputs'
    deviations, so the inputs' noise and D's error reach it only at higher order."""
    lin = linear_motor(d, win.v0, win.w_off, win.omega0)
    if lin is None:
        return None
    try:
        p_nl, q_nl, _ = motor.simulate(win.V, win.theta, d, win.dt, win.omega0)
    except motor.NoEquilibriumError:
        return None
    if not (np.all(np.isfinite(p_nl)) and np.all(np.isfinite(q_nl))):
        return None
    y = linear_playback(win, lin)
    r = win._differenced((np.stack([p_nl, q_nl], axis=1) - y).T).T
    r = r - r.mean(axis=0)
    return (np.fft.rfft(r, axis=0) / math.sqrt(win.l))[win.sel]


def _hermitian(p: np.ndarray) -> np.ndarray:
    """Per band the lower-triangular L (nb, 2, 2) of E_b = L·Lᴴ from [log L00, log L11, Re L10, Im L10]."""
    p = p.reshape(-1, 4)
    lo = np.zeros((p.shape[0], 2, 2), dtype=complex)
    lo[:, 0, 0] = np.exp(np.clip(p[:, 0], -30, 30))
    lo[:, 1, 1] = np.exp(np.clip(p[:, 1], -30, 30))
    lo[:, 1, 0] = p[:, 2] + 1j * p[:, 3]
    return lo


def nll_nuisance(win: WindowDFT, g: np.ndarray, t: np.ndarray, p: np.ndarray,
                 want_grad: bool = True) -> tuple[float, np.ndarray, np.ndarray]:
    """Negative log-likelihood (constants dropped) of the window's bins at G, T and the bands' parameters p (4·nb),
    with Δ profiled out; its gradient in p; and Δ."""
    lo = _hermitian(p)
    e = lo @ lo.conj().transpose(0, 2, 1)
    sx = win.root @ e[win.band] @ win.root
    m = np.zeros((g.shape[0], 4, 2), dtype=complex)
    m[:, 0, 0] = m[:, 1, 1] = 1.0
    m[:, 2:] = g
    sig = m @ sx @ m.conj().transpose(0, 2, 1)
    sig[:, range(4), range(4)] += np.r_[win.ru, win.ry][None, :] * win.gain[:, None]
    try:
        c = np.linalg.cholesky(sig)
    except np.linalg.LinAlgError:
        return 1e30, np.zeros_like(p), np.zeros(3 + (0 if win.tau is None else 2 * win.tau.shape[1]))
    inv = np.linalg.inv(sig)
    nb = 0 if win.tau is None else win.tau.shape[1]
    ez = np.zeros((g.shape[0], 4, 3 + 2 * nb), dtype=complex)
    ez[:, 2:, :3] = t
    for b in range(nb):  # the inputs' edges, through the inputs and through G into P and Q
        for ch in range(2):
            ez[:, ch, 3 + 2 * b + ch] = win.tau[:, b]
            ez[:, 2:, 3 + 2 * b + ch] = g[:, :, ch] * win.tau[:, b, None]
    ehi = ez.conj().transpose(0, 2, 1) @ inv
    a = np.einsum("kij,kjl->il", ehi, ez).real
    rhs = np.einsum("kij,kj->i", ehi, win.z).real
    delta = np.linalg.lstsq(a, rhs, rcond=None)[0]
    r = win.z - (ez @ delta.astype(complex))
    ir = np.einsum("kij,kj->ki", inv, r)
    val = float(2.0 * np.log(np.abs(np.diagonal(c, axis1=1, axis2=2))).sum() + np.einsum("ki,ki->", r.conj(), ir).real)
    if not want_grad:
        return val, np.zeros_like(p), delta
    # ∂/∂Σ_k = Σ⁻¹ − Σ⁻¹·r·rᴴ·Σ⁻¹ (Δ at its optimum: the envelope theorem), carried to each band's E_b.
    wk = inv - ir[:, :, None] * ir.conj()[:, None, :]
    gs = m.conj().transpose(0, 2, 1) @ wk @ m
    ge = win.root.conj().transpose(0, 2, 1) @ gs @ win.root
    gam = np.zeros((win.nb, 2, 2), dtype=complex)
    np.add.at(gam, win.band, ge)
    gl = gam @ lo
    grad = np.empty((win.nb, 4))
    grad[:, 0] = 2.0 * gl[:, 0, 0].real * lo[:, 0, 0].real
    grad[:, 1] = 2.0 * gl[:, 1, 1].real * lo[:, 1, 1].real
    grad[:, 2] = 2.0 * gl[:, 1, 0].real
    grad[:, 3] = 2.0 * gl[:, 1, 0].imag
    return val, grad.ravel(), delta


def static_slopes(win: WindowDFT, d: np.ndarray) -> tuple[float, float]:
    """c_P, c_Q by least squares over the bins of P, Q minus the motor's response to the measured inputs, on ΔV."""
    gt = response(win, d, 0.0, 0.0)
    if gt is None:
        return 0.0, 0.0
    y = win.z[:, 2:] - np.einsum("kij,kj->ki", gt[0], win.z[:, :2])
    u = win.z[:, 0]
    den = float(np.vdot(u, u).real)
    return float(np.vdot(u, y[:, 0]).real / den), float(np.vdot(u, y[:, 1]).real / den)


def fdml(V, theta, P, Q, dt: float, f0: float, d0: np.ndarray, skip_s: float = 1.0, maxiter: int = 3000,
         nonlinear: int = 0, noise_var: np.ndarray | None = None,
         spectrum: np.ndarray | None = None, difference: bool = False,
         edge: tuple[complex, ...] = ()) -> tuple[np.ndarray, dict]:
    """D [a, b, H2, Tm] maximising the window's frequency-domain likelihood over latent V and θ with the transient term
    (module docstring), from d0; and the fit's record.  ``nonlinear`` > 0: the motor's nonlinear remainder
    (:func:`remainder`) taken off P and Q first, at d0 and then ``nonlinear − 1`` times more at the fitted D.
    ``noise_var``: the noise variances of V, θ, P, Q to use instead of the window's floors (an oracle's);
    ``spectrum``: the inputs' signal spectrum (every rfft bin of the regression samples, (l//2 + 1, 2, 2)) whose shape
    the bands scale, instead of the window's own smoothed estimate (an oracle's).  ``difference``: the DFTs of the
    differenced signals (:class:`WindowDFT`); ``edge``: the poles of the inputs' edge term (:class:`WindowDFT`, stop 54)."""
    win = WindowDFT(V, theta, P, Q, dt, f0, skip_s, difference, edge)
    if noise_var is not None:  # an oracle's: the injected variances of V, θ, P, Q instead of the window's floors
        win.ru, win.ry = np.maximum(noise_var[:2], RU_MIN * win.ru.max()), np.asarray(noise_var[2:], float)
    if spectrum is not None:  # an oracle's: the inputs' signal spectrum's shape on the rfft bins of the window
        win.root = _root((spectrum[win.sel] + 1e-6 * np.diag(win.ru)) * win.gain[:, None, None])
    lo, hi = dynamic_bounds(float(P.mean()))
    d = np.asarray(d0, float)
    rec: dict = {}
    for _ in range(max(nonlinear, 1)):
        if nonlinear:
            rem = remainder(win, d)
            if rem is None:
                break
            win.z = win.z_measured.copy()
            win.z[:, 2:] -= rem
        d, rec = _fit(win, d, lo, hi, maxiter)
    return d, rec


def _fit(win: WindowDFT, d0: np.ndarray, lo: np.ndarray, hi: np.ndarray, maxiter: int,
         restarts: int = 6) -> tuple[np.ndarray, dict]:
    """:func:`fdml`'s descent on the window's current DFTs from d0, restarted (the nuisance at the new D, the scaling
    re-measured) while a restart gains more than 0.01 nats: from a start a few per cent off, one quasi-Newton descent
    can stop far short of the maximum (docs/numerics.md, stop 53)."""
    d, rec = _descent(win, d0, lo, hi, maxiter)
    for k in range(restarts):
        d2, rec2 = _descent(win, d, lo, hi, maxiter)
        if rec2["nll"] > rec["nll"] - 0.01:
            break
        d, rec = d2, {**rec2, "nll0": rec["nll0"], "restarts": k + 1}
    return d, rec


def _descent(win: WindowDFT, d0: np.ndarray, lo: np.ndarray, hi: np.ndarray, maxiter: int) -> tuple[np.ndarray, dict]:
    """One descent of :func:`_fit`: the nuisance at d0, then everything together."""
    q = 4 * win.nb

    def value(p: np.ndarray, e: np.ndarray) -> float:
        gt = response(win, p[:4], p[4], p[5])
        return 1e30 if gt is None else nll_nuisance(win, gt[0], gt[1], e, False)[0]

    def f(p: np.ndarray, e: np.ndarray, s: np.ndarray, which: range) -> tuple[float, np.ndarray, np.ndarray]:
        """The value, its gradient in the outer parameters ``which`` (central differences at steps 1e-6·s) and in
        the bands' parameters (analytic)."""
        gt = response(win, p[:4], p[4], p[5])
        if gt is None:
            return 1e30, np.zeros(len(which)), np.zeros(q)
        val, ge, _ = nll_nuisance(win, gt[0], gt[1], e)
        go = np.empty(len(which))
        for k, j in enumerate(which):
            h = 1e-6 * s[j]
            pp, pm = p.copy(), p.copy()
            pp[j] += h
            pm[j] -= h
            go[k] = (value(pp, e) - value(pm, e)) / (2.0 * h)
        return val, go, ge

    p0 = np.r_[d0, static_slopes(win, d0)]
    s0 = np.maximum(np.abs(p0), 1e-3)
    opts = {"maxiter": maxiter, "ftol": 1e-15, "gtol": 1e-7}
    val0 = value(p0, np.zeros(q))

    def f_nuisance(y):
        p = p0.copy()
        p[4:] = y[:2]
        val, go, ge = f(p, y[2:], s0, range(4, 6))
        return val, np.r_[go, ge]

    # The nuisance first, at d0 (scratch: from E_b = I the joint descent's line search stalled on some windows).
    nui = optimize.minimize(f_nuisance, np.r_[p0[4:], np.zeros(q)], jac=True, method="L-BFGS-B", options=opts)
    p1 = np.r_[d0, nui.x[:2]]
    e1 = nui.x[2:]
    # Each outer parameter in units of its curvature's standard deviation, so that the quasi-Newton descent's first
    # steps are of the right size in D as in the bands (unscaled, it stopped after one step on some windows).
    f1 = value(p1, e1)
    curv = np.empty(6)
    for j in range(6):
        h = 1e-3 * s0[j]
        pp, pm = p1.copy(), p1.copy()
        pp[j] += h
        pm[j] -= h
        curv[j] = (value(pp, e1) - 2.0 * f1 + value(pm, e1)) / (h * h)
    s = np.where(curv > 0, 1.0 / np.sqrt(np.maximum(curv, 1e-300)), 0.01 * s0)

    def f_joint(y):
        val, go, ge = f(p1 + y[:6] * s, y[6:], s, range(6))
        return val, np.r_[go * s, ge]

    bounds = [((lo[i] - p1[i]) / s[i], (hi[i] - p1[i]) / s[i]) for i in range(4)] + [(None, None)] * (2 + q)
    res = optimize.minimize(f_joint, np.r_[np.zeros(6), e1], jac=True, method="L-BFGS-B", bounds=bounds, options=opts)
    p = p1 + res.x[:6] * s
    return p[:4], {"nll0": float(val0), "nll_at_d0": float(nui.fun), "nll": float(res.fun), "nit": int(res.nit),
                   "nfev": int(res.nfev), "message": str(res.message), "cp": float(p[4]), "cq": float(p[5])}


def own_model_pq(case, rng: np.random.Generator, p_std: float, q_std: float) -> tuple[np.ndarray, np.ndarray]:
    """P, Q drawn from the candidate's own model: the linearised motor at the truth (and the static slopes of the
    clean record) driven by the clean inputs in their own frame, from the steady state, plus white noise of the
    given stds [pu]; about the clean record's means (the bounds of D scale with P)."""
    cl = case.clean
    dt = float(np.median(np.diff(cl.t)))
    d = np.asarray(case.truth.d, float)
    win = WindowDFT(cl.V, cl.theta, cl.P, cl.Q, dt, cl.f0, 1.0)
    cp, cq = static_slopes(win, d)
    y = linear_playback(win, linear_motor(d, win.v0, win.w_off, win.omega0)) + np.outer(win.u[0], [cp, cq])
    n = y.shape[0]
    return (cl.P.mean() + y[:, 0] + p_std * rng.standard_normal(n),
            cl.Q.mean() + y[:, 1] + q_std * rng.standard_normal(n))


def _on_grid(sx: np.ndarray, m: int) -> np.ndarray:
    """A spectrum on the rfft bins of l samples (l//2 + 1, 2, 2), linearly interpolated onto those of m samples: the
    same spectrum, so that draws of both lengths differ only in length."""
    f_from = np.linspace(0.0, 0.5, sx.shape[0])
    f_to = np.fft.rfftfreq(m)
    out = np.empty((f_to.size, 2, 2), dtype=complex)
    for i in range(2):
        for j in range(2):
            out[:, i, j] = np.interp(f_to, f_from, sx[:, i, j].real) + 1j * np.interp(f_to, f_from, sx[:, i, j].imag)
    return out


def circular_draw(case, w, rng: np.random.Generator, skip_s: float, p_std: float, q_std: float,
                  source: str = "gaussian") -> tuple[np.ndarray, ...]:
    """V, θ, P, Q over the window's regression samples drawn from the candidate's own frequency-domain model exactly
    (stop 54): latent inputs circular Gaussian with the 300 s realisation's spectrum (independent rfft bins, the
    bound's S_x), P and Q their response through G at the truth (no transient: the circular steady state), the window's
    own noise levels on every channel, white.  :class:`WindowDFT` removes θ's least-squares line (a ramp, the edge
    term's shape) and linearises the motor in the frame it sets, so P and Q are the response to the latent θ less that
    line: fit with the edge term, the model is then exact.  ``source`` "phases": the latent inputs instead the
    window's own clean ones with each bin's phase (both channels alike) drawn at random: their per-bin content kept,
    the coherence across bins (edges, steps) taken away.  "segment": a segment from the middle of a circular Gaussian
    draw eight times as long (the same spectrum, interpolated onto its finer bins), P and Q its response there: a
    stationary Gaussian process with the edges of a finite segment, which the independent bins model only
    approximately."""
    dt = float(np.median(np.diff(w.t)))
    k0 = int(math.ceil(skip_s / dt - 1e-9))
    l = w.V.size - k0
    sx = signal_spectrum(*long_inputs(case, 300.0), l)
    z = (rng.standard_normal((sx.shape[0], 2)) + 1j * rng.standard_normal((sx.shape[0], 2))) / math.sqrt(2.0)
    z[0] = 0.0
    if l % 2 == 0:
        z[-1] = z[-1].real * math.sqrt(2.0)
    x = np.einsum("kij,kj->ki", _root(sx), z)
    seg_pq = None
    if source == "segment":
        big = 8 * l
        sxl = _on_grid(sx, big)
        zl = (rng.standard_normal((sxl.shape[0], 2)) + 1j * rng.standard_normal((sxl.shape[0], 2))) / math.sqrt(2.0)
        zl[0] = 0.0
        xl = np.einsum("kij,kj->ki", _root(sxl), zl)
        xt = np.fft.irfft(xl * math.sqrt(big), big, axis=0)  # (big, 2)
        start = (big - l) // 2
        x = np.fft.rfft(xt[start:start + l], axis=0) / math.sqrt(l)
        seg_pq = (xl, start, big)
    if source == "phases":
        cl = WindowDFT(case.clean.V, case.clean.theta, case.clean.P, case.clean.Q, dt, case.clean.f0, skip_s)
        x = np.fft.rfft(cl.u[:, k0:], axis=1).T / math.sqrt(l) * np.exp(2j * np.pi * rng.random(sx.shape[0]))[:, None]
        x[0] = 0.0
        if l % 2 == 0:
            x[-1] = x[-1].real
    sd = [float(np.std(getattr(w, ch) - getattr(case.clean, ch))) for ch in ("V", "theta")]
    V = float(case.clean.V.mean()) + np.fft.irfft(x[:, 0] * math.sqrt(l), l) + sd[0] * rng.standard_normal(l)
    theta = np.fft.irfft(x[:, 1] * math.sqrt(l), l) + sd[1] * rng.standard_normal(l)
    d = np.asarray(case.truth.d, float)
    cp, cq = static_slopes(WindowDFT(case.clean.V, case.clean.theta, case.clean.P, case.clean.Q, dt, case.clean.f0,
                                     skip_s), d)
    win = WindowDFT(V, theta, V, V, dt, case.clean.f0, 0.0)
    win.zeta = np.exp(2j * np.pi * np.arange(sx.shape[0]) / l)  # every bin, for G
    t = np.arange(l) * dt
    line = np.polyval(np.polyfit(t, theta, 1), t)
    if seg_pq is None:
        g = response(win, d, cp, cq)[0]
        x[:, 1] -= np.fft.rfft(line) / math.sqrt(l)
        x[0] = 0.0
        y = np.fft.irfft(np.einsum("kij,kj->ki", g, x) * math.sqrt(l), l, axis=0)
    else:  # the long draw's circular response, its segment, less the motor's response to θ's line there
        xl, start, big = seg_pq
        win.zeta = np.exp(2j * np.pi * np.arange(xl.shape[0]) / big)
        g = response(win, d, cp, cq)[0]
        y = np.fft.irfft(np.einsum("kij,kj->ki", g, xl) * math.sqrt(big), big, axis=0)[start:start + l]
        win.u = np.stack([np.zeros(l), line])
        y = y - linear_playback(win, linear_motor(d, win.v0, win.w_off, win.omega0))
    P = float(case.clean.P.mean()) + y[:, 0] + p_std * rng.standard_normal(l)
    Q = float(case.clean.Q.mean()) + y[:, 1] + q_std * rng.standard_normal(l)
    return V, theta, P, Q


def misfit(case) -> dict:
    """On the clean record at the truth: P's and Q's |Y − G·X − T·Δ|² / |Y|² per :data:`MISFIT_BANDS` band, with Δ by
    least squares (``transient``) and without it (``none``)."""
    w = case.clean
    dt = float(np.median(np.diff(w.t)))
    d = np.asarray(case.truth.d, float)
    win = WindowDFT(w.V, w.theta, w.P, w.Q, dt, w.f0, 1.0)
    cp, cq = static_slopes(win, d)
    g, t = response(win, d, cp, cq)
    y = win.z[:, 2:] - np.einsum("kij,kj->ki", g, win.z[:, :2])
    tt = t.reshape(-1, 3)
    a = np.vstack([tt.real, tt.imag])
    delta = np.linalg.lstsq(a, np.r_[y.ravel().real, y.ravel().imag], rcond=None)[0]
    out = {}
    for name, r in (("none", y), ("transient", y - t @ delta)):
        out[name] = [[float(np.sum(np.abs(r[sel, j]) ** 2) / np.sum(np.abs(win.z[sel, 2 + j]) ** 2))
                      for lo_, hi_ in MISFIT_BANDS for sel in [(win.freqs > lo_) & (win.freqs <= hi_)]]
                     for j in range(2)]
    return out


def summarise(rows: list[dict], name: str) -> dict:
    """μ and σ of D/D_real over the rows; with the stored bounds, σ over the RMS structural bound and over the RMS
    learnt bound below 5 Hz, the robust spread 1.4826·MAD of the errors over each window's structural bound, and the
    windows more than 3 bounds off in some parameter."""
    r = np.array([row[name] for row in rows])
    s = {"n": len(rows), "mu": r.mean(axis=0).tolist(), "sigma": r.std(axis=0, ddof=1).tolist()}
    if "bound_var" in rows[0]:
        var = np.array([row["bound_var"] for row in rows])
        s["sigma_over_bound"] = (r.std(axis=0, ddof=1) / np.sqrt(var.mean(axis=0))).tolist()
        z = (r - 1.0) / np.sqrt(var)
        s["z_mad"] = (1.4826 * np.median(np.abs(z - np.median(z, axis=0)), axis=0)).tolist()
        s["n_far_3"] = int(np.sum(np.max(np.abs(z), axis=1) > 3.0))
        var = np.array([row["bound_var_learnt_below_5hz"] for row in rows])
        s["sigma_over_learnt_below_5hz"] = (r.std(axis=0, ddof=1) / np.sqrt(var.mean(axis=0))).tolist()
    return s


def report(cells: dict) -> dict:
    """:func:`summarise` per cell and estimator, printed."""
    summ = {}
    for key, rows in cells.items():
        summ[key] = {name: summarise(rows, name) for name in ("default", "fdml")}
        for name, s in summ[key].items():
            print(f"{key:24s} {name:8s} n {s['n']} μ {np.round(s['mu'], 3)} σ {np.round(s['sigma'], 4)}"
                  + (f" σ/bound {np.round(s['sigma_over_bound'], 2)} (learnt below 5 Hz "
                     f"{np.round(s['sigma_over_learnt_below_5hz'], 2)}) z_mad {np.round(s['z_mad'], 2)} "
                     f"far {s['n_far_3']}" if "z_mad" in s else ""))
    return summ


#: Stop 59's check of the default against this estimator, fixed before its runs on windows no likelihood run had fit
#: (:func:`likelihood_verdict`; development: windows 0-49, docs/numerics.md "Stop 59: the default against the joint
#: likelihood in every noisy cell").
LIKELIHOOD_RULE = ("seed 43's windows 50-99, every noisy cell (DL 1-3 x 0.03 % / 3e-4 rad and 0.1 % / 1e-3 rad), this "
                   "tree's default and this estimator with --nonlinear 2 from the default's D: in at least 22 of the 24 "
                   "cells x parameters the default's sigma of D/D_true is at most 1.3 x the likelihood's, and in none more "
                   "than 1.6 x")
#: The runs the rule reads (``--first 50 --n 50``, one per PMU class, the three DLs each).
LIKELIHOOD_RUNS = ("input_noise_fdml_seed43_w50_003_nl", "input_noise_fdml_seed43_w50_01_nl")


def likelihood_verdict(cells: dict) -> dict:
    """:data:`LIKELIHOOD_RULE` on the per-window rows of the rule's runs ({cell: rows}): per cell the default's σ over the
    likelihood's, per parameter."""
    ratios = {}
    for key, rows in sorted(cells.items()):
        if {row["i"] for row in rows} != set(range(50, 100)):
            raise ValueError(f"{key}: the rule's windows are 50-99")
        sd = {name: np.array([row[name] for row in rows]).std(axis=0, ddof=1) for name in ("default", "fdml")}
        ratios[key] = (sd["default"] / sd["fdml"]).tolist()
    flat = [x for v in ratios.values() for x in v]
    met = len(ratios) == 6 and sum(x <= 1.3 for x in flat) >= 22 and max(flat) <= 1.6
    return {"rule": LIKELIHOOD_RULE, "ratios": ratios, "within_1_3": sum(x <= 1.3 for x in flat), "n": len(flat),
            "max": max(flat), "met": met}


#: Stop 60's check of the default's efficiency against this estimator, fixed (with its thresholds, tuned on seed 43's
#: windows 0-99) before its runs on windows of a seed no run had drawn (:func:`efficiency_verdict`; docs/numerics.md,
#: "Stop 60: the default's efficiency against the joint likelihood").  Stop 59's rule above counted cells whose σ ratio
#: over 50 windows stayed within 1.3; on seed 43's windows 0-99 the default meets it in 16 % of resamples of 50 windows
#: (``--efficiency-development``):
#: one far window decides a cell's σ, so that count mostly measured the draw.
EFFICIENCY_RULE = ("generator seed 100's windows 0-99, every noisy cell (DL 1-3 x 0.03 % / 3e-4 rad and 0.1 % / 1e-3 "
                   "rad), this tree's default and this estimator with --nonlinear 2 from the default's D; per cell x "
                   "parameter the ratio of the default's sigma of D/D_true to the likelihood's: (1) their geometric mean "
                   "over the 24 is at most 1.15; (2) in none of the 24 does the ratio's paired bootstrap 95 % interval "
                   "(windows resampled, 2,000 draws) lie wholly above 1.3; (3) the control, the default without its "
                   "S-weighted refinement (input_weighting='none'), fails (1) or (2) on the same windows")
#: The runs the rule reads (``--seed 100 --n 100``, one per PMU class, the three DLs each).
EFFICIENCY_RUNS = ("input_noise_fdml_seed100_003_nl", "input_noise_fdml_seed100_01_nl")
#: :data:`EFFICIENCY_RULE`'s thresholds and bootstrap.
EFFICIENCY_GEO_MAX, EFFICIENCY_CELL_MAX, EFFICIENCY_DRAWS = 1.15, 1.3, 2000


def _efficiency(cells: dict, name: str, rng: np.random.Generator) -> dict:
    """Per cell ``name``'s σ of D/D_true over the likelihood's (per parameter), the ratios' paired bootstrap 2.5th
    percentile, their geometric mean, and whether :data:`EFFICIENCY_RULE`'s (1) and (2) hold for ``name``."""
    ratios, lows = {}, {}
    for key, rows in sorted(cells.items()):
        x = np.array([row[name] for row in rows])
        f = np.array([row["fdml"] for row in rows])
        ratios[key] = (x.std(axis=0, ddof=1) / f.std(axis=0, ddof=1)).tolist()
        idx = rng.integers(0, len(rows), (EFFICIENCY_DRAWS, len(rows)))
        boot = x[idx].std(axis=1, ddof=1) / f[idx].std(axis=1, ddof=1)
        lows[key] = np.percentile(boot, 2.5, axis=0).tolist()
    flat = np.array([v for r in ratios.values() for v in r])
    geo = float(np.exp(np.mean(np.log(flat))))
    above = [f"{k} {'a b H2 Tm'.split()[j]}" for k, lo in lows.items() for j, v in enumerate(lo)
             if v > EFFICIENCY_CELL_MAX]
    return {"ratios": ratios, "bootstrap_low": lows, "geometric_mean": geo, "wholly_above_1_3": above,
            "passes": len(flat) == 24 and geo <= EFFICIENCY_GEO_MAX and not above}


#: The development runs the efficiency rule's thresholds were read from: seed 43's windows 0-99, every noisy cell.
EFFICIENCY_DEV_RUNS = ("input_noise_fdml_seed43_dl12_003_nl", "input_noise_fdml_seed43_dl12_01_nl",
                       "input_noise_fdml_seed43_dl3_003_nl_s59", "input_noise_fdml_seed43_dl3_01_nl_s59", *LIKELIHOOD_RUNS)


def efficiency_development(resamples: int = 1000) -> dict:
    """:data:`EFFICIENCY_RULE`'s development reading: the stored likelihood answers of :data:`EFFICIENCY_DEV_RUNS`
    against this tree's default and control on the same windows and draws, their :func:`_efficiency`, and how often
    :data:`LIKELIHOOD_RULE`'s count is met by the default on ``resamples`` draws of 50 of the 100 windows."""
    stored: dict = {}
    for name in EFFICIENCY_DEV_RUNS:
        for key, rows in json.loads((common.RESULTS / f"{name}.json").read_text())["cells"].items():
            stored.update({(key, row["i"]): row["fdml"] for row in rows})
    cases = {level: common.cases(100, level=level, seed=43) for level in LEVELS}
    cells: dict[str, list] = {}
    for i, _level, _cls, key, c, w, r in identified_draws(noisy_draws(cases, 43, 100, LEVELS), 0, None, DEFAULT):
        truth = np.asarray(c.truth.d, float)
        cells.setdefault(key, []).append({"i": i, "fdml": stored[key, i], "default": (r.d / truth).tolist(),
                                          "control": (identify(w, config=CONTROL).d / truth).tolist()})
    rng = np.random.default_rng(43)
    out = {name: _efficiency(cells, name, rng) for name in ("default", "control")}
    met = 0
    for _ in range(resamples):
        idx = {key: rng.integers(0, len(rows), 50) for key, rows in cells.items()}
        flat = [x for key, rows in sorted(cells.items()) for x in
                np.array([rows[k]["default"] for k in idx[key]]).std(axis=0, ddof=1)
                / np.array([rows[k]["fdml"] for k in idx[key]]).std(axis=0, ddof=1)]
        met += sum(x <= 1.3 for x in flat) >= 22 and max(flat) <= 1.6
    return {**out, "likelihood_rule_met_fraction": met / resamples, "resamples": resamples,
            "issue_targets": issue_targets(cells, 43)}


def issue_targets(cells: dict, seed: int) -> dict:
    """Issue 11's σ targets on the windows of ``cells`` ({cell: rows} with ``default`` and ``fdml``, D/D_true, windows 0
    to n−1 of generator ``seed``), a reading beside :data:`EFFICIENCY_RULE`: σ ≤ 0.05 at 0.1 % / 1e-3 rad, σ ≤ 1.3 × the
    default's σ on the same windows with exact V and θ at 0.03 % / 3e-4 rad; per cell the target, both estimators' σ,
    and which parameters each meets."""
    n = 1 + max(row["i"] for rows in cells.values() for row in rows)
    exact = {}
    for level in LEVELS:
        cs = common.cases(n, level=level, seed=seed)
        exact[level] = np.array([identify(c.window, config=DEFAULT).d / np.asarray(c.truth.d, float)
                                 for c in cs]).std(axis=0, ddof=1)
    out = {}
    for key, rows in sorted(cells.items()):
        level = int(key.split("|")[0])
        target = np.full(4, 0.05) if key.endswith("0.1 % / 1e-3 rad") else 1.3 * exact[level]
        sd = {name: np.array([row[name] for row in rows]).std(axis=0, ddof=1) for name in ("default", "fdml")}
        out[key] = {"target": target.tolist(), **{name: v.tolist() for name, v in sd.items()},
                    **{f"{name}_meets": (v <= target).tolist() for name, v in sd.items()}}
    return out


def _print_targets(targets: dict) -> None:
    """:func:`issue_targets`' reading, printed."""
    for key, t in targets.items():
        print(f"{key:24s} target " + " / ".join(f"{x:.3f}" for x in t["target"]) + " | default "
              + " / ".join(f"{x:.3f}{'' if m else '*'}" for x, m in zip(t["default"], t["default_meets"], strict=True))
              + " | likelihood "
              + " / ".join(f"{x:.3f}{'' if m else '*'}" for x, m in zip(t["fdml"], t["fdml_meets"], strict=True)))
    print("(* : above issue 11's target; a reading, not part of the rule)")


def _print_efficiency(v: dict) -> None:
    """The default's and the control's :func:`_efficiency`, printed."""
    for name in ("default", "control"):
        e = v[name]
        for key, r in e["ratios"].items():
            print(f"{name:8s} {key:24s} sigma / likelihood's: " + " / ".join(f"{x:.2f}" for x in r)
                  + "  (bootstrap 2.5 %: " + " / ".join(f"{x:.2f}" for x in e["bootstrap_low"][key]) + ")")
        print(f"{name}: geometric mean {e['geometric_mean']:.3f}; wholly above 1.3: "
              f"{', '.join(e['wholly_above_1_3']) or 'none'}; passes (1) and (2): {e['passes']}")


def efficiency_verdict(cells: dict) -> dict:
    """:data:`EFFICIENCY_RULE` on the per-window rows of its runs ({cell: rows}, each row with ``default``, ``fdml``
    and ``control``, D/D_true): the default's and the control's :func:`_efficiency`, and the verdict."""
    for key, rows in cells.items():
        if sorted(row["i"] for row in rows) != list(range(100)):
            raise ValueError(f"{key}: the rule's windows are 0-99")
    out = {name: _efficiency(cells, name, np.random.default_rng(60)) for name in ("default", "control")}
    met = len(cells) == 6 and out["default"]["passes"] and not out["control"]["passes"]
    return {"rule": EFFICIENCY_RULE, **out, "met": met}


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--seed", type=int, default=41, help="windows (default 41, a development seed)")
    ap.add_argument("--cells", nargs="*", default=None, help="'level|class' keys (default: every noisy cell)")
    ap.add_argument("--check", action="store_true", help="the model's misfit on the clean records at the truth")
    ap.add_argument("--nonlinear", type=int, default=0, help="rounds of the motor's nonlinear remainder (0: none)")
    ap.add_argument("--oracle-noise", action="store_true", help="the injected noise variances instead of the floors")
    ap.add_argument("--oracle-spectrum", action="store_true",
                    help="the inputs' spectrum's shape from a 300 s clean realisation instead of the window's own")
    ap.add_argument("--own-model", action="store_true",
                    help="P, Q from the candidate's own linear model (own_model_pq), from the truth, with oracle noise")
    ap.add_argument("--circular", nargs="?", const="gaussian", choices=("gaussian", "phases", "segment"), default=None,
                    help="V, θ, P, Q drawn from the candidate's own frequency-domain model (circular_draw; 'phases': "
                         "the window's own inputs with random phases; 'segment': a stationary Gaussian segment), from "
                         "the truth, oracle noise; use with --edge")
    ap.add_argument("--exact", type=int, default=None, metavar="DL",
                    help="the windows of this level with exact V and θ (noise on P and Q only) instead of the noisy cells")
    ap.add_argument("--report", default=None, help="print the summary of a stored run (its JSON name); no run")
    ap.add_argument("--difference", action="store_true", help="the DFTs of the differenced signals (less leakage)")
    ap.add_argument("--edge", nargs="*", default=None, metavar="POLE",
                    help="the inputs' edge term, profiled out: the poles [1/s, complex as a+bj] of the process it is "
                         "the transient of (none given: 0, the integrator; two real unknowns a real pole, four a pair)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--likelihood-verdict", action="store_true", help="judge LIKELIHOOD_RUNS by LIKELIHOOD_RULE; no run")
    ap.add_argument("--efficiency-development", action="store_true",
                    help="EFFICIENCY_RULE's reading on its development runs, with this tree's default and control")
    ap.add_argument("--efficiency-verdict", action="store_true", help="judge EFFICIENCY_RUNS by EFFICIENCY_RULE; no run")
    args = ap.parse_args(argv)
    if args.report:
        return report(json.loads((common.RESULTS / f"{args.report}.json").read_text())["cells"])
    if args.likelihood_verdict:
        cells = {k: v for name in LIKELIHOOD_RUNS
                 for k, v in json.loads((common.RESULTS / f"{name}.json").read_text())["cells"].items()}
        v = likelihood_verdict(cells)
        for key, r in v["ratios"].items():
            print(f"{key:24s} default sigma / likelihood's: " + " / ".join(f"{x:.2f}" for x in r))
        print(f"within 1.3 x: {v['within_1_3']} of {v['n']}; largest {v['max']:.2f}; verdict: "
              f"{'met' if v['met'] else 'not met'}")
        common.write_json("input_noise_fdml_likelihood_verdict", v)
        return v
    if args.efficiency_development:
        v = efficiency_development()
        _print_efficiency(v)
        _print_targets(v["issue_targets"])
        print(f"stop 59's likelihood rule met by the default on {v['likelihood_rule_met_fraction']:.1%} of "
              f"{v['resamples']} draws of 50 windows")
        if not args.no_write:
            common.write_json("input_noise_fdml_efficiency_development", v)
        return v
    if args.efficiency_verdict:
        cells = {k: v for name in EFFICIENCY_RUNS
                 for k, v in json.loads((common.RESULTS / f"{name}.json").read_text())["cells"].items()}
        v = efficiency_verdict(cells)
        _print_efficiency(v)
        v["issue_targets"] = issue_targets(cells, 100)
        _print_targets(v["issue_targets"])
        print(f"verdict: {'met' if v['met'] else 'not met'}")
        common.write_json("input_noise_fdml_efficiency_verdict", v)
        return v
    edge = () if args.edge is None else tuple(complex(x) for x in args.edge) or (0j,)
    n = 2 if args.quick else args.n
    cases = {level: common.cases(args.first + n, level=level, seed=args.seed) for level in LEVELS}
    t0 = time.perf_counter()
    if args.check:
        mis = [misfit(cases[3][i]) for i in range(args.first, args.first + n)]
        for name in ("none", "transient"):
            arr = np.array([m[name] for m in mis])
            for j, ch in enumerate("PQ"):
                print(f"{name:9s} {ch}: " + ", ".join(
                    f"{lo_:g}–{hi_:g} Hz {np.median(arr[:, j, b]):.2g} [max {arr[:, j, b].max():.2g}]"
                    for b, (lo_, hi_) in enumerate(MISFIT_BANDS)))
        return {"misfit": mis}
    bounds = None
    if args.seed == 43:
        stored = json.loads((common.RESULTS / "input_noise_bound_n300.json").read_text())
        bounds = stored["per_window_relative_variance"]
        learnt = json.loads((common.RESULTS / "input_noise_bound_spectrum.json").read_text())
        learnt = learnt["per_window_relative_variance"]
    cells: dict[str, list] = {}
    draws = noisy_draws(cases, args.seed, args.first + n, LEVELS)
    if args.exact is not None:
        bounds = None
        draws = ((i, args.exact, "none", c, c.window) for i, c in enumerate(cases[args.exact]))
    for i, level, cls, key, c, w, r in identified_draws(draws, args.first, args.cells, DEFAULT):
        dt = float(np.median(np.diff(w.t)))
        skip_s = float(r.quality.get("skip_s", 1.0))
        P, Q, start, nonlinear = w.P, w.Q, r.d, args.nonlinear
        p_std, q_std = float(np.std(w.P - c.clean.P)), float(np.std(w.Q - c.clean.Q))
        if args.own_model:
            P, Q = own_model_pq(c, np.random.default_rng([args.seed, i, level, 7]), p_std, q_std)
            start, nonlinear = np.asarray(c.truth.d, float), 0
        V, theta = w.V, w.theta
        if args.circular:
            V, theta, P, Q = circular_draw(c, w, np.random.default_rng([args.seed, i, level, 8]), skip_s, p_std, q_std,
                                           args.circular)
            start, nonlinear, skip_s = np.asarray(c.truth.d, float), 0, 0.0
        noise_var = spectrum = None
        if args.oracle_noise or args.own_model or args.circular:
            noise_var = np.array([np.var(w.V - c.clean.V), np.var(w.theta - c.clean.theta), p_std**2, q_std**2])
        if args.oracle_spectrum:
            k0 = int(math.ceil(skip_s / dt - 1e-9))
            spectrum = signal_spectrum(*long_inputs(c, 300.0), V.size - k0)
        t1 = time.perf_counter()
        d, rec = fdml(V, theta, P, Q, dt, w.f0, start, skip_s=skip_s, nonlinear=nonlinear, noise_var=noise_var,
                      spectrum=spectrum, difference=args.difference, edge=edge)
        rec["s"] = time.perf_counter() - t1
        row = {"i": i, "default": (r.d / c.truth.d).tolist(), "fdml": (d / c.truth.d).tolist(),
               "control": (identify(w, config=CONTROL).d / c.truth.d).tolist(), **rec}
        if bounds is not None:
            row["bound_var"] = bounds[i][str(level)][f"{cls}|structural"]
            row["bound_var_learnt_below_5hz"] = learnt[i][str(level)][f"{cls}|learnt_0.5_below_5hz"]
        cells.setdefault(key, []).append(row)
        print(f"{i} {key} default {np.round(r.d / c.truth.d, 3)} fdml {np.round(d / c.truth.d, 3)} "
              f"({rec['s']:.1f} s, {rec['nit']} it, {rec['message'][:30]}, nll {rec['nll0']:.1f} -> "
              f"{rec['nll']:.1f})", flush=True)
    summ = report(cells)
    out = {"machine": common.machine(), "n": n, "first": args.first, "seed": args.seed, "width_hz": WIDTH_HZ,
           "top_hz": TOP_HZ, "summary": summ, "cells": cells, "total_s": time.perf_counter() - t0}
    if not args.no_write and not args.quick:
        common.write_json(args.out or f"input_noise_fdml_seed{args.seed}", out)
    return out


if __name__ == "__main__":
    main()
