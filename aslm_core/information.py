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
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import linalg

from aslm_core import motor
from aslm_core.identify import Problem
from aslm_core.preprocess import prepare
from aslm_core.result import IdentifyConfig
from aslm_core.window import Window

__all__ = ["cramer_rao", "disturbance_covariance", "fisher_information", "model_jacobian", "relative_bound"]


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
                           cross: bool = True) -> np.ndarray:
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

    Returns
    -------
    ndarray, shape (2l, 2l)
        Σ = g·gᵀ ⊗ own_cov + diag(white_var) ⊗ I.
    """
    g = np.asarray(own_gain, dtype=np.float64)
    mix = np.outer(g, g) if cross else np.diag(g * g)
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
    return jac, np.block([[phi, zero], [zero, phi]])


def relative_bound(bound: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Standard deviations of the bound relative to D [-] (√diag / |D|)."""
    return np.array([math.sqrt(max(v, 0.0)) for v in np.diag(bound)]) / np.abs(np.asarray(d, dtype=np.float64))
