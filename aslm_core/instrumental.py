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
from scipy import linalg
from scipy.stats import chi2

from aslm_core import disturbance
from aslm_core.noise import reflected_mean

#: Number of instrument lags: FIRST_LAG … FIRST_LAG + IV_LAGS − 1 samples.
IV_LAGS = 2
#: Shortest instrument lag [samples].  Not 1: the model's state at t is integrated with the cubic midpoint
#: between t − 1 and t, which reads V(t + 1), so the sensitivities at t − 1 already carry V(t) and with it the
#: own innovation e(t) (measured: with lag-1 instruments the IV criterion at the true D is 10–30 × its χ²
#: expectation on the ANDES switching windows; from lag 2 on it is at the expectation).
FIRST_LAG = 2
#: Hansen's statistic over its degrees of freedom (``iv_overid``) up to which the instruments' moments scatter as
#: their covariance S says; above it the IV's covariance of D is scaled by ``iv_overid`` / this.  Valid
#: instruments give about 1, a little more with the spectral S (few degrees of freedom per instrument: medians
#: 1.0–2.4 on the ANDES windows where the IV is consistent).  Tuned on development records (synthetic seed 43,
#: ANDES own seed 1): pooled coverage of ±1.96 SE 94–96 % on both at 1.25 (88–93 % unscaled, 90–96 % at 1.5,
#: 94–98 % at 1); docs/numerics.md, "Standard errors that cover under own fluctuation".
OVERID_EXPECTED = 1.25


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


class _Weighted:
    """A 2SLS criterion over residual blocks (channels, or windows and channels) with fixed innovation variances
    ``var``, one per block."""

    var: list[float]

    def cost(self, es: list[np.ndarray]) -> float:
        """The 2SLS criterion (summed over blocks), each block weighted by its innovation variance."""
        return 0.5 * sum(float(e @ e) / v for e, v in zip(es, self.var, strict=True))

    def weights(self, es: list[np.ndarray]) -> list[float]:
        """1/σ² per block: fixed within the pass, so the Fisher term is the IV covariance σ²(X̂ᵀX̂)⁻¹."""
        return [1.0 / v for v in self.var]


class Instrumented(_Weighted):
    """The whitened identification problem projected onto fixed instruments (two-stage least squares).

    Parameters
    ----------
    problem : aslm_core.problem.Problem
    polys : tuple of ndarray
        A(q) of P and of Q.
    d_ref : ndarray
        D at which the instruments (and the channel weights) are computed.
    lags : int
        Number of instrument lags.
    first : int
        Shortest instrument lag [samples].
    mix : float
        The second channel is Q − mix·P [-] (:func:`aslm_core.disturbance.whitened_columns`).
    """

    def __init__(self, problem, polys: tuple[np.ndarray, np.ndarray], d_ref: np.ndarray, lags: int = IV_LAGS,
                 first: int = FIRST_LAG, mix: float = 0.0) -> None:
        self.pb = problem
        self.polys = polys
        self.mix = mix
        self.lags = lags
        self.top = first + lags - 1  # rows before the first with every lag
        self.skip = max(len(a) for a in polys) - 1
        self.evaluations = 1
        zs = disturbance.whitened_columns(problem, polys, d_ref, self.skip, mix)
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
        zs = disturbance.whitened_columns(self.pb, self.polys, d, self.skip, self.mix)
        if zs is None:
            return None
        es, js = [], []
        for zf, q in zip(zs, self.bases, strict=True):
            u = q.T @ zf[self.top:]
            proj = _off(u[:, :5], u[:, 5:])
            es.append(proj[:, 0])
            js.append(proj[:, 1:])
        return es, js

    def spectral_parts(self, d: np.ndarray, smooth_hz: float) -> tuple[np.ndarray, np.ndarray, float] | None:
        """The IV moment conditions' sandwich parts and Hansen's over-identification statistic, robust to colour
        left in the innovations; None when D cannot be simulated.

        At the optimum Σ_c w_c·X̂_cᵀ·ε_c = 0, with X̂_c the whitened Jacobian projected onto the instruments and
        off the static part (in time) and ε_c the whitened structural residual; so cov(D) = B⁻¹·M·B⁻¹
        (:func:`sandwich`) with B = Σ_c w_c·X̂_cᵀX̂_c and M the covariance of the score Σ_c w_c·X̂_cᵀε_c, from the
        residuals' smoothed cross-periodogram (P with Q: the own fluctuation moves both).  J = gᵀS⁻¹g with g the
        instrument moments Z_cᵀε_c and S their covariance from the same spectra: Sargan's 2 × criterion when ε
        is white.  The white-noise forms assume white ε; after a low-pass or an input smoother it is not (a
        low-pass's zeros cannot be whitened by an AR model): their ±1.96 SE intervals covered 33–58 %, and
        Sargan's statistic was 4–17 × its degrees of freedom on windows whose instruments are valid
        (docs/numerics.md).

        Returns
        -------
        bread, meat : ndarray, shape (4, 4)
        j : float
            Hansen's statistic [-] (χ² with instruments − parameters degrees of freedom when they are valid).
        """

        zs = disturbance.whitened_columns(self.pb, self.polys, d, self.skip, self.mix)
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
                spectra[a, b] = mult * (reflected_mean(cross.real, kernel) + 1j * reflected_mean(cross.imag, kernel))
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
            j = float(g @ np.linalg.solve(s_g, g))
        except np.linalg.LinAlgError:
            j = math.inf
        return bread, meat, j

    def overid_dof(self) -> int:
        """Over-identifying restrictions of this window: instruments beyond the static part, both channels."""
        return sum(q.shape[1] - self.n_static for q in self.bases)


class Liml(Instrumented):
    """The instrumented problem by limited-information maximum likelihood (LIML) instead of 2SLS.

    2SLS minimises ‖P_Z·ε‖²/σ² with σ² fixed.  With weak instruments its criterion's expectation holds a
    term (instruments)·σ²(D), the variance of the structural residual at D, which is smallest toward the
    least-squares answer: that is the finite-sample pull of 2SLS toward least squares, growing with the
    number of instruments (docs/numerics.md, "Instrumental variables through the algebraic loop").  LIML divides by the residual's variance
    outside the instruments at the same D, ρ(D) = min_β ε'P_Zε / ε'M_Zε (ε = r(D) − Φβ, the constant, which
    is exogenous and an instrument, projected out of all), so that term no longer depends on D; its normal
    equations are the k-class ones with k = 1 + ρ.  Per channel the criterion is ½·ν·ρ with ν the rows
    outside the instruments (≈ ½‖P_Z·ε‖²/σ², so 2 × the criterion is the Anderson–Rubin over-identification
    statistic); ρ and the static part come from the smallest generalised eigenvalue of the (r, Φ) block of
    the instrument-space and outside Gram matrices, the gradient by the envelope theorem and the
    Gauss–Newton matrix from the k-class form W = G_P − ρ·G_M with the static part concentrated out.
    The residuals are per channel :class:`_Grams` (what the criterion and its normal equations need); the
    Jacobians those of 2SLS in the instrument space, for the white-noise covariance at the end (LIML and
    2SLS share their first-order covariance).
    """

    def residuals(self, d: np.ndarray):
        """Per channel the Gram matrices of [r, ∂r/∂D, Φ] (centred) in and outside the instruments, and the
        2SLS instrument-space Jacobian."""
        self.evaluations += 1
        zs = disturbance.whitened_columns(self.pb, self.polys, d, self.skip, self.mix)
        if zs is None:
            return None
        gs, js = [], []
        for zf, q in zip(zs, self.bases, strict=True):
            zl = zf[self.top:]
            u = q.T @ zl
            js.append(_off(u[:, 1:5], u[:, 5:]))
            # The constant is exogenous and in the instruments' span: centred columns are orthogonal to it, so
            # their instrument-space part is (P_Z − P_1)·y.  Centred before the products (the residual's mean is
            # large against its fluctuation: subtracting n·m·mᵀ from the Gram matrices loses the digits).
            zc = zl - zl.mean(axis=0)
            uc = q.T @ zc
            g_i = zc.T @ zc
            g_p = uc.T @ uc
            g_m = g_i - g_p
            # The constant (whitened, still a constant) leaves a null direction in the static block: drop it.
            lam, vec = np.linalg.eigh(g_i[5:, 5:])
            kept = lam > 1e-10 * max(float(lam[-1]), 1e-300)
            t = np.zeros((zl.shape[1], 5 + int(kept.sum())))
            t[:5, :5] = np.eye(5)
            t[5:, 5:] = vec[:, kept] / np.sqrt(lam[kept])
            g = _Grams(t.T @ g_p @ t, t.T @ g_m @ t, zl.shape[0] - q.shape[1])
            if not g.solve():
                return None
            gs.append(g)
        return gs, js

    def cost(self, es: list) -> float:
        """½ Σ_c ν_c·ρ_c: LIML's criterion per channel, summed."""
        return _liml_cost(es)

    def normal_equations(self, es: list, js: list) -> tuple[np.ndarray, np.ndarray]:
        """Gradient of :meth:`cost` in D and its Gauss–Newton matrix (k-class, static part concentrated)."""
        return _liml_normal_equations(es)


def _liml_cost(gs: list) -> float:
    """½ Σ ν·ρ over channels (and windows) of :class:`_Grams`."""
    return 0.5 * sum(g.nu * g.rho for g in gs)


def _liml_normal_equations(gs: list) -> tuple[np.ndarray, np.ndarray]:
    """Summed gradients and Gauss–Newton matrices of :class:`_Grams`."""
    return sum(g.gradient for g in gs), sum(g.hessian for g in gs)


class _Grams:
    """One channel's LIML quantities at a D (:class:`Liml`): Gram matrices of y = [r, ∂r/∂D (4), Φ] in the
    instrument space (``g_p``) and outside it (``g_m``), and ν, the rows outside the instruments."""

    def __init__(self, g_p: np.ndarray, g_m: np.ndarray, nu: int) -> None:
        self.g_p, self.g_m, self.nu = g_p, g_m, max(nu, 1)
        self.rho = math.inf
        self.gradient = np.zeros(4)
        self.hessian = np.zeros((4, 4))

    def solve(self) -> bool:
        """ρ, the static part and the criterion's derivatives in D; False where the Gram matrices are singular."""
        s = np.r_[0, 5:self.g_p.shape[0]]
        try:
            lam, vec = linalg.eigh(self.g_p[np.ix_(s, s)], self.g_m[np.ix_(s, s)], check_finite=False)
        except (linalg.LinAlgError, ValueError):
            return False
        v = vec[:, 0]
        if abs(v[0]) < 1e-12 * np.abs(v).max():
            return False
        a = np.zeros(self.g_p.shape[0])
        a[s] = v / v[0]
        self.rho = max(float(lam[0]), 0.0)
        w = self.g_p - self.rho * self.g_m
        scale = self.nu / float(a @ self.g_m @ a)
        self.gradient = scale * (w[1:5] @ a)
        st = slice(5, None)
        try:
            conc = w[1:5, st] @ np.linalg.solve(w[st, st], w[st, 1:5]) if w.shape[0] > 5 else 0.0
        except np.linalg.LinAlgError:
            return False
        self.hessian = scale * (w[1:5, 1:5] - conc)
        return True


class Stacked(_Weighted):
    """Several windows' instrumented problems with one D (pooled): criteria summed, the windows independent.

    Parameters
    ----------
    pool
        Gives the common ``lower``, ``upper``, ``v_min`` and ``feasible`` of D (:class:`aslm_core.pooled._Pool`).
    parts : list of Instrumented
        One per window, each with its own AR models, instruments and channel variances.
    """

    def __init__(self, pool, parts: list[Instrumented]) -> None:
        self.pb = pool
        self.parts = parts
        self.var = [v for p in parts for v in p.var]
        self.strength = [min(s) for s in zip(*(p.strength for p in parts), strict=True)]
        self.evaluations = 0

    def cost(self, es: list) -> float:
        """The windows' criteria summed (2SLS or LIML, as the parts are)."""
        if es and isinstance(es[0], _Grams):
            return _liml_cost(es)
        return super().cost(es)

    def normal_equations(self, es: list, js: list) -> tuple[np.ndarray, np.ndarray]:
        """Gradient and Gauss–Newton matrix of :meth:`cost` (:func:`aslm_core.disturbance.normal_equations`)."""
        if es and isinstance(es[0], _Grams):
            return _liml_normal_equations(es)
        return disturbance.weighted_normal_equations(self.weights(es), es, js)

    def residuals(self, d: np.ndarray):
        """Every window's residuals and Jacobians in its instrument space, in one list per kind."""
        self.evaluations += len(self.parts)
        es, js = [], []
        for p in self.parts:
            out = p.residuals(d)
            if out is None:
                return None
            es += out[0]
            js += out[1]
        return es, js

    def spectral_parts(self, d: np.ndarray, smooth_hz: float) -> tuple[np.ndarray, np.ndarray, float] | None:
        """Summed sandwich parts and Hansen's statistic of the windows (:meth:`Instrumented.spectral_parts`)."""
        parts = [p.spectral_parts(d, smooth_hz) for p in self.parts]
        if any(p is None for p in parts):
            return None
        return sum(p[0] for p in parts), sum(p[1] for p in parts), sum(p[2] for p in parts)

    def overid_dof(self) -> int:
        return sum(p.overid_dof() for p in self.parts)


#: The IV criteria by name (``IdentifyConfig.iv_estimator``).
_ESTIMATORS = {"2sls": Instrumented, "liml": Liml}


def sandwich(bread: np.ndarray, meat: np.ndarray) -> np.ndarray:
    """B⁻¹·M·B⁻¹ (inf where B is singular)."""
    try:
        binv = np.linalg.inv(bread)
    except np.linalg.LinAlgError:
        return np.full((4, 4), np.inf)
    return binv @ meat @ binv.T


def _off(x: np.ndarray, basis_cols: np.ndarray) -> np.ndarray:
    """x with the span of ``basis_cols`` projected out."""
    q, _ = np.linalg.qr(basis_cols)
    return x - q @ (q.T @ x)


def fit(problem, d0: np.ndarray, max_iter: int = 40, xtol: float = 1e-7, margin: float = 1e-3,
        reestimate: int = 2, max_order: int = disturbance.AR_MAX_ORDER, lags: int = IV_LAGS,
        first_lag: int = FIRST_LAG, se_smooth_hz: float | None = None, couple: bool = False,
        estimator: str = "2sls", whitening: str = "residual") -> dict:
    """IV prediction-error fit of D from an output-error optimum d0; AR models and instruments renewed per pass.

    ``estimator``: ``"2sls"`` (:class:`Instrumented`) or ``"liml"`` (:class:`Liml`); ``whitening``: the AR models of
    the residual (``"residual"``) or of its own part alone (``"own"``, :func:`aslm_core.disturbance.own_whitener`).

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
    def make(pb, polys, d, mix):
        try:
            return _ESTIMATORS[estimator](pb, polys, d, lags, first_lag, mix)
        except ValueError:
            return None

    def finish(wp: Instrumented, state: dict) -> None:
        _overid_and_covariance(wp, state, se_smooth_hz)

    return disturbance.passes(problem, d0, make, max_iter=max_iter, xtol=xtol, margin=margin,
                              reestimate=reestimate, max_order=max_order, finish=finish, couple=couple,
                              whitening=whitening)


def covariance_scale(overid: float) -> float:
    """The factor on the IV's spectral covariance of D for Hansen's statistic over its degrees of freedom.

    max(1, ``overid`` / :data:`OVERID_EXPECTED`): the reduced χ² of the over-identifying moments above what valid
    instruments give (docs/numerics.md, "Standard errors that cover under own fluctuation").
    """
    return max(1.0, overid / OVERID_EXPECTED)


def _overid_and_covariance(wp: Instrumented | Stacked, state: dict, se_smooth_hz: float | None) -> None:
    """Add ``strength``, ``overid``, ``overid_p``, ``overid_white`` to a fit's result; with ``se_smooth_hz`` its
    ``cov`` and ``overid`` from the spectral moment conditions.

    The spectral ``cov`` is scaled by max(1, ``overid`` / :data:`OVERID_EXPECTED`) (one window or a pool).  The sandwich
    holds the innovations' own scatter only; instruments slightly correlated with the innovations (J above its
    expectation but under the rejection bound) add an error of D it does not hold.  J/dof is the reduced χ² of
    those moments, and scaling the covariance by it (as a reduced χ² scales a fit's errors) is the estimate of
    that error from the window itself: on the development windows the IV's ±1.96 SE covered 79–88 % where
    J/dof was 2–3 and 93–96 % where it was below 1.5.
    """
    # Sargan's statistic: 2·cost is χ² with (instruments − parameters) degrees of freedom when the
    # instruments are uncorrelated with white innovations; far above it, they are not (the IV is biased).
    dof = max(wp.overid_dof() - len(state["d"]), 1)
    stat = 2.0 * state["cost"] if math.isfinite(state["cost"]) else math.inf
    state.update(strength=wp.strength, overid_white=stat / dof)
    robust = wp.spectral_parts(state["d"], se_smooth_hz) if se_smooth_hz and math.isfinite(stat) else None
    if robust is not None:
        state["cov"], stat = sandwich(robust[0], robust[1]), robust[2]
        state["cov"] = state["cov"] * covariance_scale(stat / dof)
    state.update(overid=stat / dof, overid_p=float(chi2.sf(stat, dof)))


def fit_pooled(pool, problems: list, d0: np.ndarray, max_iter: int = 40, xtol: float = 1e-7, margin: float = 1e-3,
               reestimate: int = 2, max_order: int = disturbance.AR_MAX_ORDER, lags: int = IV_LAGS,
               first_lag: int = FIRST_LAG, se_smooth_hz: float | None = None, couple: bool = False,
               estimator: str = "2sls", whitening: str = "residual") -> dict:
    """IV prediction-error fit of one D from several windows: per window its AR models and instruments (and with
    ``couple`` its second channel Q − k·P, k per window: :func:`aslm_core.disturbance.coupling`).

    Parameters
    ----------
    pool
        The windows' common bounds and equilibrium set (:class:`aslm_core.pooled._Pool`).
    problems : list of aslm_core.problem.Problem
        One per window.
    d0 : ndarray
        Start (the pooled output-error optimum).

    Returns
    -------
    dict as :func:`fit` (``polys`` per window).
    """
    d = pool.into_feasible(d0)
    state: dict = {}
    total_it = evals = 0
    for _ in range(max(reestimate, 1)):
        parts = []
        for pb in problems:
            r = pb.residuals(d, jacobian=False)
            if r is None:
                break
            mix = disturbance.coupling(r[0], r[1]) if couple else 0.0
            fit_ar = disturbance.whitener(whitening)
            polys = (fit_ar(r[0], max_order), fit_ar(r[1] - mix * r[0], max_order))
            try:
                parts.append(_ESTIMATORS[estimator](pb, polys, d, lags, first_lag, mix))
            except ValueError:
                break
        if len(parts) < len(problems):
            break
        wp = Stacked(pool, parts)
        state = disturbance.constrained_lm(wp, d, max_iter, xtol, margin)
        total_it += state["iterations"]
        evals += wp.evaluations + len(parts)
        d = state["d"]
        state["polys"] = [p.polys for p in parts]
        _overid_and_covariance(wp, state, se_smooth_hz)
    if not state:
        return {"d": d, "cost": math.inf, "iterations": 0, "evaluations": evals, "status": "failed"}
    state["iterations"], state["evaluations"] = total_it, evals
    return state
