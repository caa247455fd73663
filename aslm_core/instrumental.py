"""Instrumental-variable prediction error: the AR disturbance model through an algebraic loop.

The network has no delay, so the load's own fluctuation moves V and θ in the same sample as it moves P and Q.
After the AR whitening of :mod:`aslm_core.disturbance` the residual is the own process's innovation e(t), and
the whitened regressors at t (the sensitivities ∂m/∂D and the static regressors Φ(V), both functions of V(t))
carry that same e(t): the least-squares (prediction-error) estimate is biased, most for step-like own
processes whose innovations are large single-sample jumps.  Here the normal equations are replaced by
Σ_t ζ(t)·ε(t; D, β) = 0 with instruments ζ(t) = the whitened regressors lagged by ℓ = 1 … L samples (and a
constant): they depend on V only up to t − ℓ, so not on e(t), while the grid-driven part of V is smooth and
keeps its whitened regressors correlated from one sample to the next.  With more instruments than
parameters this is the two-stage least-squares criterion ‖P_Z·ε‖² (the extended IV with the weight
(ZᵀZ)⁻¹), a least-squares problem in the instrument space: the static part β is projected out there
(variable projection) and D descends by the same constrained Levenberg–Marquardt.  The instruments are
computed at the start of each pass (fixed within it) and renewed with the AR models.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from aslm_core import disturbance

#: Number of instrument lags: FIRST_LAG … FIRST_LAG + IV_LAGS − 1 samples.
IV_LAGS = 2
#: Shortest instrument lag [samples].  Not 1: the model's state at t is integrated with the cubic midpoint
#: between t − 1 and t, which reads V(t + 1), so the sensitivities at t − 1 already carry V(t) and with it the
#: own innovation e(t) (measured: with lag-1 instruments the IV criterion at the true D is 10–30 × its χ²
#: expectation on the ANDES switching windows; from lag 2 on it is at the expectation).
FIRST_LAG = 2


def _orthonormal(x: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """An orthonormal basis of the column span of x (rank-revealing, so duplicate instruments drop out)."""
    u, s, _ = np.linalg.svd(x, full_matrices=False)
    return u[:, s > rtol * s[0]]


def instruments(zf: np.ndarray, lags: int, first: int = FIRST_LAG) -> np.ndarray:
    """Instrument matrix of one channel: a constant and the whitened regressors lagged by ``first`` … ``first +
    lags − 1`` samples.

    Parameters
    ----------
    zf : ndarray
        Whitened columns [residual, ∂residual/∂D (4), static basis] (:func:`disturbance.whitened_columns`).
    lags : int
        Number of lags.
    first : int
        Shortest lag [samples].

    Returns
    -------
    ndarray of shape (rows − first − lags + 1, 1 + lags·(columns − 1)), aligned with ``zf[first + lags − 1:]``.
    """
    top = first + lags - 1
    n = zf.shape[0] - top
    cols = [np.ones((n, 1))] + [zf[top - k:top - k + n, 1:] for k in range(first, top + 1)]
    return np.hstack(cols)


class Instrumented:
    """The whitened identification problem projected onto fixed instruments (two-stage least squares).

    Parameters
    ----------
    problem : aslm_core.identify.Problem
    polys : tuple of ndarray
        A(q) of P and of Q.
    d_ref : ndarray
        D at which the instruments (and the channel weights) are computed.
    lags : int
        Number of instrument lags.
    first : int
        Shortest instrument lag [samples].
    """

    def __init__(self, problem, polys: tuple[np.ndarray, np.ndarray], d_ref: np.ndarray, lags: int = IV_LAGS,
                 first: int = FIRST_LAG) -> None:
        self.pb = problem
        self.polys = polys
        self.lags = lags
        self.top = first + lags - 1  # rows before the first with every lag
        self.skip = max(len(a) for a in polys) - 1
        self.evaluations = 1
        zs = disturbance.whitened_columns(problem, polys, d_ref, self.skip)
        if zs is None:
            raise ValueError("the instruments' reference D cannot be simulated")
        self.bases = [_orthonormal(instruments(zf, lags, first)) for zf in zs]
        self.n_static = zs[0].shape[1] - 5  # static regressors, estimated in the instrument space too
        # Channel variances from the structural (not the projected) residual at d_ref: ε = y − Φβ̂ with β̂ the
        # 2SLS static part, since ‖P_Z·ε‖² is a small share of ‖ε‖² when the instrument is weak.
        self.var = []
        for zf, q in zip(zs, self.bases, strict=True):
            zl = zf[self.top:]
            u = q.T @ zl
            beta, *_ = np.linalg.lstsq(u[:, 5:], u[:, 0], rcond=None)
            eps = zl[:, 0] - zl[:, 5:] @ beta
            self.var.append(max(float(eps @ eps) / eps.size, 1e-300))
        self.strength = self._strength(zs)

    def _strength(self, zs: list[np.ndarray]) -> list[float]:
        """Per channel, the smallest share of D's whitened information the instruments keep (0: none, 1: all)."""
        out = []
        for zf, q in zip(zs, self.bases, strict=True):
            zl = zf[self.top:]
            full = _off(zl[:, 1:5], zl[:, 5:])
            u = q.T @ zl
            kept = _off(u[:, 1:5], u[:, 5:])
            try:
                lo = np.linalg.cholesky(full.T @ full)
                li = np.linalg.inv(lo)
                out.append(float(np.linalg.eigvalsh(li @ (kept.T @ kept) @ li.T).min()))
            except np.linalg.LinAlgError:
                out.append(0.0)
        return out

    def residuals(self, d: np.ndarray):
        """Residuals and Jacobians of P and Q in the instrument space, the static part projected out there."""
        self.evaluations += 1
        zs = disturbance.whitened_columns(self.pb, self.polys, d, self.skip)
        if zs is None:
            return None
        es, js = [], []
        for zf, q in zip(zs, self.bases, strict=True):
            u = q.T @ zf[self.top:]
            proj = _off(u[:, :5], u[:, 5:])
            es.append(proj[:, 0])
            js.append(proj[:, 1:])
        return es, js

    def cost(self, es: list[np.ndarray]) -> float:
        """The 2SLS criterion, each channel weighted by its innovation variance."""
        return 0.5 * sum(float(e @ e) / v for e, v in zip(es, self.var, strict=True))

    def weights(self, es: list[np.ndarray]) -> list[float]:
        """1/σ_c²: fixed within the pass, so the Fisher term is the IV covariance σ²(X̂ᵀX̂)⁻¹."""
        return [1.0 / v for v in self.var]

    def spectral_moments(self, d: np.ndarray, smooth_hz: float) -> tuple[np.ndarray, float] | None:
        """Covariance of D from the IV moment conditions and Hansen's over-identification statistic, both robust
        to colour left in the innovations; None when D cannot be simulated.

        At the optimum Σ_c w_c·X̂_cᵀ·ε_c = 0, with X̂_c the whitened Jacobian projected onto the instruments and
        off the static part (in time) and ε_c the whitened structural residual; so cov = B⁻¹·M·B⁻¹ with
        B = Σ_c w_c·X̂_cᵀX̂_c and M the covariance of the score Σ_c w_c·X̂_cᵀε_c, from the residuals' smoothed
        cross-periodogram (P with Q: the own fluctuation moves both).  J = gᵀS⁻¹g with g the instrument moments
        Z_cᵀε_c and S their covariance from the same spectra: Sargan's 2 × criterion when ε is white.  The
        white-noise forms assume white ε; after a low-pass or an input smoother it is not (a low-pass's zeros
        cannot be whitened by an AR model): their ±1.96 SE intervals covered 33–58 %, and Sargan's statistic was
        5–17 × its degrees of freedom on windows whose instruments are valid (docs/numerics.md).

        Returns
        -------
        cov : ndarray, shape (4, 4)
        j : float
            Hansen's statistic [-] (χ² with instruments − parameters degrees of freedom when they are valid).
        """
        from aslm_core.identify import _reflected_mean  # a function import: identify imports this module

        zs = disturbance.whitened_columns(self.pb, self.polys, d, self.skip)
        if zs is None:
            return None
        xs, eps = [], []
        for zf, q in zip(zs, self.bases, strict=True):
            zl = zf[self.top:]
            u = q.T @ zl
            beta, *_ = np.linalg.lstsq(u[:, 5:], u[:, 0], rcond=None)
            xs.append(q @ _off(u[:, 1:5], u[:, 5:]))
            eps.append(zl[:, 0] - zl[:, 5:] @ beta)
        l = eps[0].size
        width = max(1, int(round(smooth_hz * l * self.pb.dt)))
        kernel = np.ones(2 * (width // 2) + 1) / (2 * (width // 2) + 1)
        mult = np.full(l // 2 + 1, 2.0)  # one-sided spectrum: inner bins stand for two of the full DFT's
        mult[0] = 1.0
        if l % 2 == 0:
            mult[-1] = 1.0
        fe = [np.fft.rfft(e) for e in eps]
        spectra = {}
        for a in range(2):
            for b in range(2):
                cross = fe[a] * fe[b].conj()
                spectra[a, b] = mult * (_reflected_mean(cross.real, kernel) + 1j * _reflected_mean(cross.imag, kernel))
        # The fitted D and static part take their share of the residual's power.
        dof = l / max(l - 4 - self.n_static, 1)

        def blocks(cols: list[np.ndarray]) -> dict:
            """Covariances of Σ_t cols_a(t)·ε_a(t) with Σ_t cols_b(t)·ε_b(t), per channel pair."""
            f = [np.fft.rfft(c, axis=0) for c in cols]
            return {ab: dof * (f[ab[0]].conj().T @ (s[:, None] * f[ab[1]])).real / (l * l) for ab, s in spectra.items()}

        w = self.weights([])
        bread = sum(wc * (x.T @ x) for wc, x in zip(w, xs, strict=True))
        meat = sum(w[a] * w[b] * m for (a, b), m in blocks(xs).items())
        g = np.concatenate([q.T @ e for q, e in zip(self.bases, eps, strict=True)])
        bq = blocks(self.bases)
        s_g = np.block([[bq[0, 0], bq[0, 1]], [bq[1, 0], bq[1, 1]]])
        try:
            binv = np.linalg.inv(bread)
            cov = binv @ meat @ binv.T
        except np.linalg.LinAlgError:
            cov = np.full((4, 4), np.inf)
        try:
            j = float(g @ np.linalg.solve(s_g, g))
        except np.linalg.LinAlgError:
            j = math.inf
        return cov, j


def _off(x: np.ndarray, basis_cols: np.ndarray) -> np.ndarray:
    """x with the span of ``basis_cols`` projected out."""
    q, _ = np.linalg.qr(basis_cols)
    return x - q @ (q.T @ x)


def fit(problem, d0: np.ndarray, max_iter: int = 40, xtol: float = 1e-7, margin: float = 1e-3,
        reestimate: int = 2, max_order: int = disturbance.AR_MAX_ORDER, lags: int = IV_LAGS,
        first_lag: int = FIRST_LAG, se_smooth_hz: float | None = None) -> dict:
    """IV prediction-error fit of D from an output-error optimum d0; AR models and instruments renewed per pass.

    ``first_lag``: the shortest instrument lag [samples]; ``se_smooth_hz``: the covariance of D and the
    over-identification statistic robust to coloured innovations (:meth:`Instrumented.spectral_moments`, the
    periodogram averaged over this width [Hz]); None: their white-innovation forms (as before issue 20's gate).

    Returns
    -------
    dict as :func:`aslm_core.disturbance.fit` (d, cost, iterations, evaluations, status, polys, cov, resid),
    ``strength`` (per channel, the instruments' smallest kept share of D's information) [-], ``overid`` (Sargan's
    over-identification statistic over its degrees of freedom: near 1 when the instruments are valid) [-] and
    ``overid_p`` (its χ² upper-tail probability) [-], both robust with ``se_smooth_hz``, and ``overid_white`` (Sargan's
    white-innovation statistic over its degrees of freedom) [-].
    """
    def make(pb, polys, d):
        try:
            return Instrumented(pb, polys, d, lags, first_lag)
        except ValueError:
            return None

    def finish(wp: Instrumented, state: dict) -> None:
        # Sargan's statistic: 2·cost is χ² with (instruments − parameters) degrees of freedom when the
        # instruments are uncorrelated with white innovations; far above it, they are not (the IV is biased).
        dof = max(sum(q.shape[1] - wp.n_static for q in wp.bases) - len(state["d"]), 1)
        stat = 2.0 * state["cost"] if math.isfinite(state["cost"]) else math.inf
        state.update(strength=wp.strength, overid_white=stat / dof)
        robust = wp.spectral_moments(state["d"], se_smooth_hz) if se_smooth_hz and math.isfinite(stat) else None
        if robust is not None:
            state["cov"], stat = robust
        state.update(overid=stat / dof, overid_p=float(chi2.sf(stat, dof)))

    return disturbance.passes(problem, d0, make, max_iter=max_iter, xtol=xtol, margin=margin,
                              reestimate=reestimate, max_order=max_order, finish=finish)
