"""The Cramér–Rao bound of D for a window whose disturbance has a known (coloured, cross-channel) covariance.

The data-generating process of a window is y = m(D; V, θ) + Φ·β + v: the motor's P and Q driven by the
measured inputs, the static part on the regressors Φ (a nuisance), and a zero-mean Gaussian disturbance v of
both channels, the load's own fluctuation plus the white measurement floor, with covariance Σ.  The Fisher
information of D, with β estimated alongside, is the Schur complement

    I(D) = J̃ᵀ·(I − Ñ·(ÑᵀÑ)⁻¹·Ñᵀ)·J̃,    J̃ = L⁻¹·∂m/∂D,   Ñ = L⁻¹·Φ,   Σ = L·Lᵀ,

(whiten by Σ's Cholesky factor, then project out the whitened nuisance columns), and cov(D̂) ⪰ I(D)⁻¹ for
every unbiased estimator.  A prediction-error method with the true noise model reaches it asymptotically
(also in closed loop, where the input V depends on past disturbances), so it is the bound an estimator's
spread is measured against.  With a white Σ = σ²·I and no nuisance this is σ²·(JᵀJ)⁻¹.

**Noisy inputs.**  A PMU measures the inputs too: x_m = x + n, x = (V [pu], θ [rad]) the true sequences of n
samples each, n white with Σ_n = diag(σ_V², σ_θ²) ⊗ I.  Linearised about the true x, y = m(D; x) + Φβ + v
≈ m(D; x̂) + Φβ + A·(x − x̂) + v with A = ∂[P; Q]/∂[V; θ] [pu/pu, pu/rad] (:func:`input_jacobian`, the motor's
dynamics and the static part at the true β) and x̂ = E[x | x_m].  If x is a Gaussian process of covariance Σ_x
(the *structural* model), (x_m, y) are jointly Gaussian and, given x_m, y is Gaussian with mean m(D; x̂) + Φβ
and covariance S = Σ_v + A·P_x·Aᵀ, P_x = Σ_x − Σ_x·(Σ_x + Σ_n)⁻¹·Σ_x the error of the perfect Wiener smoother;
x_m's own density does not depend on D, so I(D) is the formula above with Σ replaced by S
(:func:`input_posterior_covariance`, :func:`input_noise_covariance`).  Without a prior (the *functional*
model: x an unknown sequence, estimated alongside D from x_m and y) the Schur complement of the joint
information of (D, β, x) is the same with P_x = Σ_n (Woodbury).  Both drop the information in S's own
dependence on D (through A; second order at PMU noise levels) and hold to first order in the input errors
(the model's response to 0.1 % / 1e-3 rad white errors is linear to ~0.2 %).  With Σ_n = 0 they are the
exact-input bound.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import linalg

from aslm_core import motor, static
from aslm_core.identify import Problem
from aslm_core.preprocess import prepare
from aslm_core.result import IdentifyConfig
from aslm_core.window import Window

__all__ = ["cramer_rao", "disturbance_covariance", "fisher_information", "input_jacobian", "input_noise_covariance",
           "input_posterior_covariance", "model_jacobian", "model_response", "relative_bound", "stationary_input_covariance"]


def fisher_information(jac: np.ndarray, nuisance: np.ndarray | None, cov: np.ndarray) -> np.ndarray:
    """Fisher information of the parameters behind ``jac`` with the ``nuisance`` columns estimated alongside.

    Parameters
    ----------
    jac : ndarray, shape (n, p)
        ∂(model)/∂(parameters) of the stacked channels [signal unit / parameter unit].
    nuisance : ndarray, shape (n, q), or None
        Columns of the linear nuisance parameters (the static regressors of each channel).
    cov : ndarray, shape (n, n)
        Covariance of the stacked disturbance [signal unit²], positive definite.

    Returns
    -------
    ndarray, shape (p, p)
        I = J̃ᵀ·P⊥·J̃ with J̃ = L⁻¹·J and P⊥ the projection off L⁻¹·nuisance [1 / parameter unit²].
    """
    chol = linalg.cholesky(cov, lower=True)
    jw = linalg.solve_triangular(chol, jac, lower=True)
    if nuisance is not None and nuisance.shape[1]:
        q, _ = np.linalg.qr(linalg.solve_triangular(chol, nuisance, lower=True))
        jw = jw - q @ (q.T @ jw)
    return jw.T @ jw


def cramer_rao(jac: np.ndarray, nuisance: np.ndarray | None, cov: np.ndarray) -> np.ndarray:
    """The Cramér–Rao bound I⁻¹ (see :func:`fisher_information`; inf where I is singular) [parameter unit²]."""
    try:
        return np.linalg.inv(fisher_information(jac, nuisance, cov))
    except np.linalg.LinAlgError:
        return np.full((jac.shape[1], jac.shape[1]), np.inf)


def disturbance_covariance(own_cov: np.ndarray, own_gain: tuple[float, float], white_var: tuple[float, float],
                           cross: bool = True, coherence: float = 1.0) -> np.ndarray:
    """Covariance of the stacked [P; Q] disturbance: one own process in both channels plus white floors.

    Parameters
    ----------
    own_cov : ndarray, shape (l, l)
        Covariance of the own process over the window's regression samples [pu²] (of its P part).
    own_gain : (float, float)
        The own process's weight in P and in Q (e.g. 1 and ΔQ/ΔP) [-].
    white_var : (float, float)
        White measurement-noise variance of P and of Q [pu²].
    cross : bool
        Keep the P–Q cross-covariance (the true process).  False gives each channel its own spectrum only:
        the bound for estimators that model the channels separately.
    coherence : float
        Correlation of the own process's P and Q parts (1: one process in both) [-].

    Returns
    -------
    ndarray, shape (2l, 2l)
        Σ = G ⊗ own_cov + diag(white_var) ⊗ I, G = g·gᵀ with its off-diagonal × ``coherence`` (0 without ``cross``).
    """
    g = np.asarray(own_gain, dtype=np.float64)
    mix = np.outer(g, g) * (np.array([[1.0, coherence], [coherence, 1.0]]) if cross else np.eye(2))
    return np.kron(mix, own_cov) + np.kron(np.diag(np.asarray(white_var, dtype=np.float64)), np.eye(own_cov.shape[0]))


def model_jacobian(window: Window, d: np.ndarray, config: IdentifyConfig | None = None,
                   skip_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """∂[P; Q]/∂D of the motor over a window's regression samples, and the static regressors as nuisance.

    Parameters
    ----------
    window : Window
        The measured inputs V [pu], θ [rad] drive the model (as in the identifier).
    d : ndarray
        D = [a, b, H2, Tm] at which to differentiate (the truth, for the bound).
    config : IdentifyConfig, optional
        Preprocessing, static model and integrator as the estimator uses them.
    skip_s : float, optional
        Samples skipped at the start [s] (default the config's ``skip_s``).

    Returns
    -------
    jac : ndarray, shape (2l, 4)
        Stacked ∂P_im/∂D and ∂Q_im/∂D [pu per unit of each parameter].
    nuisance : ndarray, shape (2l, 2m)
        Block-diagonal static regressors of P and Q.
    """
    _, jac, nuisance, _ = model_response(window, d, config, skip_s)
    return jac, nuisance


def model_response(window: Window, d: np.ndarray, config: IdentifyConfig | None = None,
                   skip_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The motor's [P; Q] over a window's regression samples with its D-Jacobian, the static regressors and
    the measured [P; Q] there (:func:`model_jacobian`'s parameters).

    Returns
    -------
    model : ndarray, shape (2l,)
        Stacked P_im, Q_im [pu].
    jac : ndarray, shape (2l, 4)
        ∂model/∂D [pu per unit of each parameter].
    nuisance : ndarray, shape (2l, 2m)
        Block-diagonal static regressors of P and Q (orthonormal columns).
    measured : ndarray, shape (2l,)
        Stacked measured P, Q [pu].
    """
    config = config or IdentifyConfig()
    if skip_s is not None:
        config = replace(config, skip_s=skip_s)
    prep = prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=config.min_duration_s,
                   lowpass_hz=config.lowpass_hz)
    pb = Problem(prep, window.f0, config)
    d = np.asarray(d, dtype=np.float64)
    if not motor.simulate_kernel(pb.vd, pb.vq, pb.vdm, pb.vqm, d, pb.dt, pb.omega0, pb.rk4, True, pb._p, pb._q,
                                 pb._dp, pb._dq, pb._x, True, pb.k0, pb.p_meas, pb.q_meas, pb._dp):
        raise ValueError("the model cannot be simulated at this D on this window")
    phi = pb.basis
    zero = np.zeros_like(phi)
    jac = np.vstack([pb._dp[pb.k0:], pb._dq[pb.k0:]])
    return (np.concatenate([pb._p[pb.k0:], pb._q[pb.k0:]]), jac, np.block([[phi, zero], [zero, phi]]),
            np.concatenate([pb.p_meas, pb.q_meas]))


def relative_bound(bound: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Standard deviations of the bound relative to D [-] (√diag / |D|)."""
    return np.array([math.sqrt(max(v, 0.0)) for v in np.diag(bound)]) / np.abs(np.asarray(d, dtype=np.float64))


def input_jacobian(window: Window, d: np.ndarray, static_p: np.ndarray, static_q: np.ndarray,
                   config: IdentifyConfig | None = None, step: float = 1e-5) -> np.ndarray:
    """∂[P; Q]/∂[V; θ] of the whole load model over a window's regression samples, per input sample.

    Parameters
    ----------
    window : Window
        The inputs V [pu], θ [rad] about which to linearise (the true ones, for the bound).
    d : ndarray
        D = [a, b, H2, Tm] of the motor.
    static_p, static_q : ndarray
        Static coefficients of P and of Q on the configured regressors (ZIP: [1, V, V²]) [pu].
    config : IdentifyConfig, optional
        Preprocessing, static model, integrator and ``skip_s`` as the estimator uses them.
    step : float
        Central-difference step of each input sample [pu, rad].

    Returns
    -------
    ndarray, shape (2l, 2n)
        Columns: the n samples of V, then the n samples of θ; rows: P then Q at the l regression samples
        [pu per pu, pu per rad].  The motor part by central differences through the compiled simulator
        (the cubic interpolation inside the RK4 steps and the initial steady state included), the static
        part analytically (∂Φ(V_k)·β/∂V_k on the diagonal).
    """
    config = config or IdentifyConfig()
    prep = prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=config.min_duration_s,
                   lowpass_hz=config.lowpass_hz)
    pb = Problem(prep, window.f0, config)
    n, k0, l = prep.V.size, pb.k0, pb.l
    p, q = np.empty(n), np.empty(n)
    dp, dq, xs = np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 3))
    d = np.asarray(d, dtype=np.float64)

    def output(v: np.ndarray, th: np.ndarray) -> np.ndarray:
        vd, vq, vdm, vqm = motor.dq_inputs(v, th, pb.substeps)
        if not motor.simulate_kernel(vd, vq, vdm, vqm, d, pb.dt, pb.omega0, pb.rk4, False, p, q, dp, dq, xs,
                                     True, k0, pb.p_meas, pb.q_meas, dp):
            raise ValueError("the model cannot be simulated at this D on this window")
        return np.concatenate([p[k0:], q[k0:]])

    a = np.empty((2 * l, 2 * n))
    for c, x in enumerate((prep.V, prep.theta)):
        for j in range(n):
            up, down = x.copy(), x.copy()
            up[j] += step
            down[j] -= step
            args_up = (up, prep.theta) if c == 0 else (prep.V, up)
            args_down = (down, prep.theta) if c == 0 else (prep.V, down)
            a[:, c * n + j] = (output(*args_up) - output(*args_down)) / (2.0 * step)
    # The static part responds to V in the same sample only: finite differences of its regressors.
    v = prep.V[k0:]
    dphi = (static.regressors(v + step, config.static) - static.regressors(v - step, config.static)) / (2 * step)
    rows = np.arange(l)
    a[rows, k0 + rows] += dphi @ np.asarray(static_p, dtype=np.float64)
    a[l + rows, k0 + rows] += dphi @ np.asarray(static_q, dtype=np.float64)
    return a


def stationary_input_covariance(v: np.ndarray, theta: np.ndarray, n: int, level_var: float = 1.0) -> np.ndarray:
    """Joint covariance of n consecutive samples of (V, θ) from a long record of the stationary process.

    Parameters
    ----------
    v, theta : ndarray
        A long clean realisation of V [pu] and θ [rad] (each detrended by its mean and line here).
    n : int
        Samples per window (n ≪ the record's length, so the lagged products are well averaged).
    level_var : float
        Variance of each channel's level [pu², rad²]: a wide prior, since a window's mean V and θ are not
        known in advance (only the fluctuation about them is the stationary process).

    Returns
    -------
    ndarray, shape (2n, 2n)
        Block-Toeplitz [[C_VV, C_Vθ], [C_θV, C_θθ]] from the biased lagged products (positive
        semi-definite by construction), plus level_var on each channel's constant [pu², pu·rad, rad²].
    """
    x = np.vstack([v, theta]).astype(np.float64)
    m = x.shape[1]
    t = np.arange(m, dtype=np.float64)
    x = x - np.polynomial.polynomial.polyval(t, np.polynomial.polynomial.polyfit(t, x.T, 1))
    nfft = 1 << int(math.ceil(math.log2(m + n)))
    f = np.fft.rfft(x, nfft)
    blocks = []
    for i in range(2):
        row = []
        for j in range(2):
            c = np.fft.irfft(f[i] * np.conj(f[j]), nfft) / m  # c[k] = E[x_i(t + k)·x_j(t)]
            row.append(linalg.toeplitz(c[:n], np.r_[c[0], c[-1:-n:-1]]))  # negative lags wrap to the end
        blocks.append(row)
    cov = np.block(blocks)
    ones = np.kron(np.eye(2), np.ones((n, 1)))
    return cov + level_var * ones @ ones.T


def input_posterior_covariance(noise_var: tuple[float, float], n: int, prior_cov: np.ndarray | None = None
                               ) -> np.ndarray:
    """Covariance P_x of the true inputs x = (V, θ) given their measurement x_m = x + white noise.

    Parameters
    ----------
    noise_var : (float, float)
        White-noise variance of the measured V [pu²] and θ [rad²].
    n : int
        Samples per channel.
    prior_cov : ndarray, shape (2n, 2n), optional
        Prior covariance Σ_x of x (:func:`stationary_input_covariance`): the *structural* bound, where P_x is
        what a perfect Wiener smoother leaves, Σ_n − Σ_n·(Σ_x + Σ_n)⁻¹·Σ_n (= Σ_x − Σ_x·(Σ_x + Σ_n)⁻¹·Σ_x,
        the form that stays positive definite when Σ_x is nearly singular).  None: the *functional* bound,
        x an unknown sequence with no prior, P_x = Σ_n.

    Returns
    -------
    ndarray, shape (2n, 2n)
        P_x [pu², pu·rad, rad²].
    """
    sn = np.repeat(np.asarray(noise_var, dtype=np.float64), n)
    if prior_cov is None:
        return np.diag(sn)
    chol = linalg.cho_factor(prior_cov + np.diag(sn), lower=True)
    px = np.diag(sn) - sn[:, None] * linalg.cho_solve(chol, np.diag(sn))
    return 0.5 * (px + px.T)


def input_noise_covariance(white_var: tuple[float, float], a: np.ndarray, p_x: np.ndarray) -> np.ndarray:
    """Covariance S = Σ_v + A·P_x·Aᵀ of the stacked [P; Q] disturbance with noisy inputs.

    Parameters
    ----------
    white_var : (float, float)
        White measurement-noise variance of P and of Q [pu²].
    a : ndarray, shape (2l, 2n)
        ∂[P; Q]/∂[V; θ] (:func:`input_jacobian`).
    p_x : ndarray, shape (2n, 2n)
        Covariance of the true inputs given the measured ones (:func:`input_posterior_covariance`).

    Returns
    -------
    ndarray, shape (2l, 2l)
        S [pu²].
    """
    l = a.shape[0] // 2
    s = a @ p_x @ a.T
    s[np.diag_indices_from(s)] += np.repeat(np.asarray(white_var, dtype=np.float64), l)
    return 0.5 * (s + s.T)
