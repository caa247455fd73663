"""Fit a candidate on the training samples (hierarchical: regression inside, optimisation outside) and
judge it on the held-out samples.

Upper stage: ``scipy.optimize.least_squares`` (trust-region reflective, finite differences) over the
nonlinear parameters — D = [a, b, H2, Tm] in identified mode plus the candidate's own z.  Lower stage:
for given (D, z) the linear coefficients (ZIP and the candidate's linear extras) are the least-squares
solution on the training samples, so the upper stage sees the projected residual (variable projection).
Residuals are taken in the ambient band (DCT coefficients below 5 Hz, :mod:`aslm_core.diagnosis.noise`)
and weighted per coefficient by the noise model's variance (measurement noise plus the V/θ noise the model
propagates): the weighted sum of squares is the Gaussian (Whittle-type) likelihood with known noise, so P
and Q, and the frequencies, count by their information.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from aslm_core.diagnosis.candidates.base import BOUND_TOL, Candidate, Context, Prediction
from aslm_core.diagnosis.noise import NoiseModel, dct_band, n_band
from aslm_core.diagnosis.projection import Projector
from aslm_core.diagnosis.segment import Segment
from aslm_core.params import DYNAMIC_NAMES, dynamic_bounds

_FAIL = 1e8  # residual value of a failed simulation (much larger than any weighted residual)


@dataclass
class Fit:
    """A candidate fitted on one segment's training samples.

    Attributes
    ----------
    d : ndarray
        D = [a, b, H2, Tm] [1/s, 1/s, s, pu].
    z : ndarray
        The candidate's nonlinear parameters.
    beta_p, beta_q : ndarray
        Linear coefficients (static first, then the candidate's extras).
    model_p, model_q : ndarray
        Model P and Q over the whole window [pu].
    cost : float
        Weighted training sum of squares / 2.
    params : dict
        The candidate's own parameters {name: value}.
    stderr : dict
        Their standard errors (Jacobian, autocorrelation-inflated).
    ok : bool
        False when no start gave a finite model.
    nfev : int
        Upper-stage function evaluations (Jacobian evaluations not counted).
    at_bound : dict
        The parameters of D on a bound of the identifier's box {name: the bound}, identified mode only
        [1/s, 1/s, s, pu].
    """

    d: np.ndarray
    z: np.ndarray
    beta_p: np.ndarray
    beta_q: np.ndarray
    model_p: np.ndarray
    model_q: np.ndarray
    cost: float
    params: dict = field(default_factory=dict)
    stderr: dict = field(default_factory=dict)
    ok: bool = True
    nfev: int = 0
    at_bound: dict = field(default_factory=dict)

    def residuals(self, seg: Segment) -> tuple[np.ndarray, np.ndarray]:
        """Measured minus model over the whole window [pu]."""
        return seg.P - self.model_p, seg.Q - self.model_q


def _lstsq(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # Column scaling keeps the normal problem well conditioned ([1, V, V²] are nearly collinear).
    s = np.sqrt(np.sum(x * x, axis=0))
    s[s == 0] = 1.0
    beta, *_ = np.linalg.lstsq(x / s, y, rcond=1e-10)
    return beta / s


def as_noise(noise, seg: Segment) -> NoiseModel:
    """A :class:`NoiseModel` from a noise model or a pair of white-noise stds (σ_P, σ_Q) [pu]."""
    if isinstance(noise, NoiseModel):
        return noise
    return NoiseModel.white(float(noise[0]), float(noise[1]), seg.fs)


def output(cand: Candidate, seg: Segment, ctx: Context, fit: Fit) -> tuple[np.ndarray, np.ndarray] | None:
    """A fitted candidate's P and Q [pu] over a segment (parameters and linear coefficients fixed)."""
    pr = cand.predict(seg, ctx, fit.d, fit.z)
    if pr is None:
        return None
    return pr.mp + pr.xp @ fit.beta_p, pr.mq + pr.xq @ fit.beta_q


def _train_residuals(pr: Prediction, seg: Segment, noise: NoiseModel):
    """Whitened ambient-band residuals of the lower stage on the training samples.

    Returns rp, rq (weighted DCT coefficients), bp, bq (linear coefficients), xp, xq (weighted columns).
    """
    tr = seg.train
    vp, vq, _ = noise.coefficients(tr)
    out = []
    for y, m, x, v in ((seg.P, pr.mp, pr.xp, vp), (seg.Q, pr.mq, pr.xq, vq)):
        c = dct_band(np.column_stack([y[tr] - m[tr], x[tr]]), noise.fs, noise.band_hz)
        w = 1.0 / np.sqrt(v)
        yw, xw = c[:, 0] * w, c[:, 1:] * w[:, None]
        beta = _lstsq(xw, yw)
        out.append((yw - xw @ beta, beta, xw))
    (rp, bp, xwp), (rq, bq, xwq) = out
    return rp, rq, bp, bq, xwp, xwq


def fit_candidate(cand: Candidate, seg: Segment, ctx: Context, noise, *,
                  d_start: np.ndarray | None = None, z_starts: list[np.ndarray] | None = None,
                  max_nfev: int | None = None,
                  d_bounds: tuple[np.ndarray, np.ndarray] | None = None) -> Fit:
    """Fit one candidate on ``seg.train``.

    Parameters
    ----------
    cand : Candidate
    seg : Segment
    ctx : Context
        Identified mode frees D; user mode keeps ``ctx.d0``.
    noise : NoiseModel or (float, float)
        Noise of the residuals (the weights); a pair is white noise std of P and Q [pu].
    d_start : ndarray, optional
        Start of D (default ``ctx.d0``).
    z_starts : list of ndarray, optional
        Starts of z (default ``cand.starts``); the best run is kept.
    max_nfev : int, optional
        Function evaluations per start.
    d_bounds : (ndarray, ndarray), optional
        Box of D (lower, upper) [1/s, 1/s, s, pu] in identified mode (default: the identifier's,
        :func:`aslm_core.params.dynamic_bounds`); ``at_bound`` refers to it.
    """
    noise = as_noise(noise, seg)
    d0 = np.asarray(ctx.d0 if d_start is None else d_start, dtype=np.float64)
    z_starts = cand.starts(seg, ctx) if z_starts is None else z_starts
    zlo, zhi = cand.bounds(seg, ctx)
    free = ctx.free
    if free:
        dlo, dhi = dynamic_bounds(float(np.mean(seg.P))) if d_bounds is None else d_bounds
        dlo, dhi = np.array(dlo, dtype=np.float64), np.array(dhi, dtype=np.float64)
        dhi[3] = max(dhi[3], d0[3] * 1.05, 1e-6)
        lo, hi = np.concatenate([dlo, zlo]), np.concatenate([dhi, zhi])
    else:
        lo, hi = np.asarray(zlo, float), np.asarray(zhi, float)
    n_tr = n_band(seg.train.stop - seg.train.start, noise.fs, noise.band_hz)
    proj = Projector(seg, noise, _lstsq)

    def unpack(x):
        return (x[:4], x[4:]) if free else (d0, x)

    def resid(x):
        d, z = unpack(x)
        pr = cand.predict(seg, ctx, d, z)
        if pr is None:
            return np.full(2 * n_tr, _FAIL)
        r = proj.residuals(pr)
        return r if np.all(np.isfinite(r)) else np.full(2 * n_tr, _FAIL)

    best = None
    nfev = 0
    for zs in z_starts:
        x0 = np.concatenate([d0, zs]) if free else np.asarray(zs, float)
        if x0.size == 0:
            r = resid(x0)
            res = optimize.OptimizeResult(x=x0, fun=r, cost=0.5 * float(r @ r), jac=np.zeros((r.size, 0)), nfev=1)
        else:
            span = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
            x0 = np.clip(x0, lo + 1e-6 * span, hi - 1e-6 * span)
            res = optimize.least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", method="trf",
                                         max_nfev=max_nfev or cand.max_nfev, xtol=1e-8,
                                         ftol=1e-9)
        nfev += int(res.nfev)
        if best is None or res.cost < best.cost:
            best = res
    d, z = unpack(best.x)
    fit = evaluate(cand, seg, ctx, d, z, noise, res=best, nfev=nfev)
    if free:
        fit.at_bound = at_bound(fit.d, lo[:4], hi[:4])
    return fit


def at_bound(d: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float = BOUND_TOL) -> dict[str, float]:
    """The parameters of D within ``tol`` of the box's width of a bound {name: the bound} [1/s, 1/s, s, pu]."""
    out = {}
    for i, name in enumerate(DYNAMIC_NAMES):
        span = hi[i] - lo[i]
        if not span > 0:
            continue
        if d[i] - lo[i] <= tol * span:
            out[name] = float(lo[i])
        elif hi[i] - d[i] <= tol * span:
            out[name] = float(hi[i])
    return out


def evaluate(cand: Candidate, seg: Segment, ctx: Context, d: np.ndarray, z: np.ndarray,
             noise, *, res=None, nfev: int = 0) -> Fit:
    """The lower stage alone for given (D, z): linear coefficients on the training samples, model over
    the window (``res``, the upper stage's result, adds standard errors of z); ``noise`` as in
    :func:`fit_candidate`."""
    noise = as_noise(noise, seg)
    pr = cand.predict(seg, ctx, d, z)
    if pr is None:
        nan = np.full(seg.n, np.nan)
        return Fit(np.asarray(d, float), np.asarray(z, float), np.zeros(0), np.zeros(0), nan, nan, math.inf,
                   ok=False, nfev=nfev)
    rp, rq, bp, bq, xwp, xwq = _train_residuals(pr, seg, noise)
    model_p = pr.mp + pr.xp @ bp
    model_q = pr.mq + pr.xq @ bq
    cost = 0.5 * float(rp @ rp + rq @ rq)
    fit = Fit(np.array(d, float), np.array(z, float), bp, bq, model_p, model_q, cost, nfev=nfev)
    if res is None:
        res = optimize.OptimizeResult(jac=np.zeros((rp.size + rq.size, 0)))
    _parameters(fit, cand, pr, res, rp, rq, xwp, xwq, ctx.free)
    return fit


def _ar1_inflation(r: np.ndarray) -> float:
    """(1 + ρ)/(1 − ρ) for the lag-1 autocorrelation ρ of a residual (clipped to [0, 0.95])."""
    rho = float(r[1:] @ r[:-1]) / max(float(r @ r), 1e-300)
    rho = min(max(rho, 0.0), 0.95)
    return (1.0 + rho) / (1.0 - rho)


def _parameters(fit: Fit, cand: Candidate, pr: Prediction, res, rp, rq, xwp, xwq, free: bool) -> None:
    """Fill the candidate's parameters and standard errors into ``fit`` (whitened residuals and columns)."""
    params: dict[str, float] = {}
    stderr: dict[str, float] = {}
    n_static = pr.xp.shape[1] - len(cand.lin_p)
    for cols, beta, r, x in ((cand.lin_p, fit.beta_p, rp, xwp), (cand.lin_q, fit.beta_q, rq, xwq)):
        if not cols:
            continue
        var = float(r @ r) / max(r.size - x.shape[1], 1) * _ar1_inflation(r)
        try:
            xs = np.sqrt(np.sum(x * x, axis=0))
            xs[xs == 0] = 1.0
            cov = np.linalg.pinv((x / xs).T @ (x / xs)) / np.outer(xs, xs) * var
            se = np.sqrt(np.clip(np.diag(cov), 0, None))
        except np.linalg.LinAlgError:
            se = np.full(x.shape[1], np.inf)
        for i, c in enumerate(cols):
            params[c] = float(beta[n_static + i])
            stderr[c] = float(se[n_static + i])
    nz = len(cand.nl_names)
    if nz:
        j = np.asarray(res.jac)
        r = np.concatenate([rp, rq])
        s2 = float(r @ r) / max(r.size - j.shape[1], 1) * max(_ar1_inflation(rp), _ar1_inflation(rq))
        try:
            cov = np.linalg.pinv(j.T @ j) * s2
            se_all = np.sqrt(np.clip(np.diag(cov), 0, None))
        except np.linalg.LinAlgError:
            se_all = np.full(j.shape[1], np.inf)
        # A parameter the residual does not move at all is not determined by the fit; pinv would report zero
        # variance for it (kept as in the runs of record: it decides the magnitude guard in degenerate fits).
        if j.size:
            se_all = np.where(np.any(j != 0, axis=0), se_all, np.inf)
        off = 4 if free else 0
        for i, c in enumerate(cand.nl_names):
            params[c] = float(fit.z[i])
            # A scanned parameter of a discrete law has no standard error (a finite difference across one of
            # its thresholds would report a spuriously tiny one): it is left out of ``stderr``.
            if c not in cand.scanned:
                stderr[c] = float(se_all[off + i]) if off + i < se_all.size else float("inf")
    if free:
        for i, c in enumerate(DYNAMIC_NAMES):
            params.setdefault(f"D.{c}", float(fit.d[i]))
    fit.params = params
    fit.stderr = stderr


def prediction_cov(cand: Candidate, seg: Segment, ctx: Context, fit: Fit, noise,
                   rel_step: float = 1e-6) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Linearised held-out prediction uncertainty of a fitted model from its training fit.

    Parameters
    ----------
    cand : Candidate
    seg : Segment
    ctx : Context
    fit : Fit
        The model fitted on ``seg.train``.
    noise : NoiseModel or (float, float)
        Noise of the residuals (see :func:`fit_candidate`).
    rel_step : float
        Relative forward-difference step of the nonlinear parameters [-].

    Returns
    -------
    (jp, jq, cov) or None
        jp, jq: derivatives of the held-out ambient-band DCT coefficients of P and Q with respect to all
        fitted parameters (the free nonlinear ones, then the linear coefficients of P, then of Q);
        cov: the parameters' covariance from the noise-weighted training fit, (JᵀJ)⁻¹ with J the whitened
        training Jacobian.  The plain model's held-out residual is noise *plus* its own estimation error,
        whose covariance is jp·cov·jpᵀ etc.; None when the model cannot be differentiated.
    """
    noise = as_noise(noise, seg)
    pr = cand.predict(seg, ctx, fit.d, fit.z)
    if pr is None:
        return None
    x_nl = np.concatenate([fit.d, fit.z]) if ctx.free else np.asarray(fit.z, float)
    cols_p, cols_q = [], []
    base_p, base_q = pr.mp + pr.xp @ fit.beta_p, pr.mq + pr.xq @ fit.beta_q
    for j in range(x_nl.size):
        h = rel_step * max(abs(x_nl[j]), 1e-3)
        x = x_nl.copy()
        x[j] += h
        d, z = (x[:4], x[4:]) if ctx.free else (fit.d, x)
        pj = cand.predict(seg, ctx, d, z)
        if pj is None:
            return None
        cols_p.append((pj.mp + pj.xp @ fit.beta_p - base_p) / h)
        cols_q.append((pj.mq + pj.xq @ fit.beta_q - base_q) / h)
    n, kp, kq, k = seg.n, pr.xp.shape[1], pr.xq.shape[1], x_nl.size
    jp = np.zeros((n, k + kp + kq))
    jq = np.zeros((n, k + kp + kq))
    if k:
        jp[:, :k] = np.column_stack(cols_p)
        jq[:, :k] = np.column_stack(cols_q)
    jp[:, k:k + kp] = pr.xp
    jq[:, k + kp:] = pr.xq
    tr, te = seg.train, seg.test
    vp, vq, _ = noise.coefficients(tr)
    jtr = np.vstack([dct_band(jp[tr], noise.fs, noise.band_hz) / np.sqrt(vp)[:, None],
                     dct_band(jq[tr], noise.fs, noise.band_hz) / np.sqrt(vq)[:, None]])
    if not np.all(np.isfinite(jtr)):
        return None
    sc = np.sqrt(np.sum(jtr * jtr, axis=0))
    sc[sc == 0] = 1.0
    # From the SVD of J itself (JᵀJ would square the condition of the nearly collinear [1, V, V²]).
    _, sv, vt = np.linalg.svd(jtr / sc, full_matrices=False)
    keep = sv > 1e-13 * sv[0]
    cov = (vt[keep].T / sv[keep] ** 2) @ vt[keep] / np.outer(sc, sc)
    return dct_band(jp[te], noise.fs, noise.band_hz), dct_band(jq[te], noise.fs, noise.band_hz), cov


# --------------------------------------------------------------------------------------------------
# Held-out comparison
# --------------------------------------------------------------------------------------------------


def hac_variance(x: np.ndarray, lag: int) -> float:
    """Newey–West (Bartlett kernel) long-run variance of a series about its mean."""
    x = x - x.mean()
    n = x.size
    v = float(x @ x) / n
    for k in range(1, min(lag, n - 1) + 1):
        w = 1.0 - k / (lag + 1.0)
        v += 2.0 * w * float(x[k:] @ x[:-k]) / n
    return max(v, 1e-300)


@dataclass
class Comparison:
    """Held-out evidence that a candidate beats the plain model.

    Attributes
    ----------
    score_z : float
        Held-out score statistic of the plain residual r0 against the candidate's correction
        Δ = model1 − model0 in the ambient band, noise-weighted (see :func:`compare`).  Δ depends only on
        the training samples and the inputs, so with the noise model right score_z ~ N(0, 1) when the
        candidate is not needed, whatever its number of parameters.
    dm_z : float
        Diebold–Mariano statistic of the weighted squared-error differential (plain − candidate), HAC
        (reported; weaker on a few seconds of held-out data).
    gain : float
        Held-out log-likelihood gain Σ_ch (m/2)·ln(S0/S1) over the m ambient-band coefficients [nats].
    penalised_gain : float
        gain − (k/2)·ln(m) (BIC-like penalty for the k added parameters) [nats].
    reduction_p, reduction_q : float
        Held-out residual-variance reduction 1 − SSR1/SSR0 per channel [-].
    excess_p, excess_q : float or None
        Share of the held-out ambient-band residual *above the noise* removed, (S0 − S1)/(S0 − m) per
        channel (noise-weighted sums of squares) [-]; None when the channel has (almost) no excess.
    band_reduction_p, band_reduction_q : float or None
        Held-out residual-variance reduction in the ambient band, 1 − S1/S0 per channel (noise-weighted
        sums of squares of the band's coefficients) [-]: the band where the located mismatch lives, so
        the white noise above it does not dilute the figure.
    n : int
        Held-out samples.
    """

    score_z: float
    dm_z: float
    gain: float
    penalised_gain: float
    reduction_p: float
    reduction_q: float
    n: int
    excess_p: float | None = None
    excess_q: float | None = None
    band_reduction_p: float | None = None
    band_reduction_q: float | None = None


def compare(seg: Segment, plain: Fit, cand: Fit, k: int, noise, lag_s: float = 1.0, probes=None,
            plain_cov=None, gain_metric: str = "channels") -> Comparison:
    """Compare a candidate with the plain fit on the held-out samples of one segment.

    Parameters
    ----------
    seg : Segment
    plain, cand : Fit
        The plain model and the candidate, both fitted on the training samples.
    k : int
        Parameters the candidate adds (the penalty's k).
    noise : NoiseModel or (float, float)
        Noise of the residuals (see :func:`fit_candidate`).
    lag_s : float
        Newey–West bandwidth of the reported Diebold–Mariano statistic [s].
    probes : tuple of ndarray, optional
        (G0 e, G1 e): the same input-noise draws pushed through the plain model and through the candidate,
        each a pair of arrays (k, n) for P and Q (:meth:`NoiseModel.propagate`).  Given, the score and the
        gain are corrected for errors in variables (below).
    plain_cov : tuple, optional
        The plain model's held-out prediction uncertainty from :func:`prediction_cov`: its held-out residual
        is the noise plus its own estimation error, and the score's metric counts both.
    gain_metric : {"channels", "decorrelated"}
        The log-likelihood gain's two channels: P and Q as they are (each weighted by its own variance per
        coefficient), or P and Q given P — per coefficient, the noise model's P/Q covariance (the propagated
        input noise moves both) taken out by its 2×2 Cholesky factor.  The same where that covariance is zero
        (noise on P and Q only); the excess and reduction shares are the channels' in both.

    Notes
    -----
    With R0 and D the ambient-band DCT coefficients (P and Q stacked) of the plain held-out residual and of
    the candidate's correction (model1 − model0), and C the covariance of R0 when the candidate is not
    needed — the noise model's variances and P/Q covariance per coefficient plus, with ``plain_cov``, the
    plain model's prediction error — the score statistic is Dᵀ·C⁻¹·R0 / √(Dᵀ·C⁻¹·D): N(0, 1) when the
    candidate is not needed (D depends on the training samples only), and the most powerful such linear
    statistic.  The log-likelihood gain is Σ_ch (m/2)·ln(S0/S1) with S the sums of squares of the m
    coefficients weighted by 1/v.

    Errors in variables: with noisy V and θ both R0 and D carry the *held-out* input noise, R0 ⊃ −G0·e and
    D ⊃ (G1 − G0)·e, so the numerator has the expectation b = −E[((G1 − G0)e)ᵀ·C⁻¹·G0e] ≠ 0 even when the
    candidate is not needed (e.g. a candidate that smooths its input removes part of the propagated
    noise).  b, the variance of that quadratic form and of the P/Q noise against (G1 − G0)e are estimated
    from the probes; the score is (numerator − b) over the total standard deviation, and the candidate's
    held-out sum of squares S1 is raised by 2·b per channel before the gain is taken.
    """
    if gain_metric not in ("channels", "decorrelated"):
        raise ValueError(f"gain_metric must be 'channels' or 'decorrelated', not {gain_metric!r}")
    noise = as_noise(noise, seg)
    te = seg.test
    r0p, r0q = (seg.P - plain.model_p)[te], (seg.Q - plain.model_q)[te]
    r1p, r1q = (seg.P - cand.model_p)[te], (seg.Q - cand.model_q)[te]
    n = r0p.size
    if not cand.ok or not np.all(np.isfinite(r1p)) or not np.all(np.isfinite(r1q)):
        return Comparison(-math.inf, -math.inf, -math.inf, -math.inf, 0.0, 0.0, n)
    # Reported: Diebold–Mariano on the time-domain squared errors, weighted by the total noise level.
    sp, sq = noise.total_sigma("P", te), noise.total_sigma("Q", te)
    dl = (r0p**2 - r1p**2) / sp**2 + (r0q**2 - r1q**2) / sq**2
    lag = max(1, min(int(round(lag_s / seg.dt)), n // 4))
    z = float(dl.mean() / math.sqrt(hac_variance(dl, lag) / n))
    # The test: ambient band; generalised least squares in the metric of the plain residual's covariance
    # C = N + J·cov·Jᵀ (N: the noise per coefficient, P/Q correlated; J·cov·Jᵀ: the plain model's own
    # held-out prediction error), applied through Woodbury's identity (the second term has rank ≤ 10).
    vp, vq, cpq = noise.coefficients(te)
    c = dct_band(np.column_stack([r0p, r0q, r0p - r1p, r0q - r1q]), noise.fs, noise.band_hz)
    R0p, R0q, Dp, Dq = c.T
    m = R0p.size
    cinv = _gls_metric(vp, vq, cpq, plain_cov)
    wDp, wDq = cinv(Dp, Dq)
    num = float(np.sum(wDp * R0p + wDq * R0q))
    den2 = float(np.sum(wDp * Dp + wDq * Dq))
    bp = bq = 0.0
    if probes is not None:
        (g0p, g0q), (g1p, g1q) = probes
        G0p, G0q, dGp, dGq = (dct_band(x[:, te].T, noise.fs, noise.band_hz)
                              for x in (g0p, g0q, g1p - g0p, g1q - g0q))
        # Per draw: the numerator's input-noise part (C⁻¹·(G1 − G0)e)ᵀ(−G0e); its mean is the bias.
        wp, wq = cinv(dGp, dGq)
        a = -np.sum(wp * G0p + wq * G0q, axis=0)
        # The realisation's spread, plus the Monte Carlo error of the mean itself.
        var_quad = float(np.var(a, ddof=1)) * (1.0 + 1.0 / a.size) if a.size > 1 else 0.0
        var_cross = float(np.mean(np.sum(wp**2 * noise.sigma_p**2 + wq**2 * noise.sigma_q**2, axis=0)))
        num -= float(a.mean())
        den2 += var_quad + var_cross
        # Per channel, in the gain's own (diagonal) metric.
        bp = float(np.mean(-np.sum(G0p * dGp / vp[:, None], axis=0)))
        bq = float(np.mean(-np.sum(G0q * dGq / vq[:, None], axis=0)))
    score = num / math.sqrt(max(den2, 1e-300))
    S0p, S0q = float(np.sum(R0p**2 / vp)), float(np.sum(R0q**2 / vq))
    S1p = float(np.sum((R0p - Dp) ** 2 / vp)) + 2.0 * bp
    S1q = float(np.sum((R0q - Dq) ** 2 / vq)) + 2.0 * bq
    if gain_metric == "decorrelated" and np.any(cpq != 0.0):
        gain = _decorrelated_gain(vp, vq, cpq, (R0p, R0q), (Dp, Dq), (G0p, G0q, dGp, dGq) if probes is not None
                                  else None)
    else:  # the channels as they are (the same gain where P and Q are uncorrelated)
        gain = 0.5 * m * (math.log(S0p / max(S1p, 1e-300)) + math.log(S0q / max(S1q, 1e-300)))
    ex = [(s0 - s1) / (s0 - m) if s0 - m > 0.05 * m else None for s0, s1 in ((S0p, S1p), (S0q, S1q))]
    s0p, s0q, s1p, s1q = (float(r @ r) for r in (r0p, r0q, r1p, r1q))
    return Comparison(score, z, gain, gain - 0.5 * k * math.log(m), 1.0 - s1p / s0p, 1.0 - s1q / s0q, n,
                      ex[0], ex[1], 1.0 - S1p / S0p, 1.0 - S1q / S0q)


def _decorrelated_gain(vp: np.ndarray, vq: np.ndarray, cpq: np.ndarray, r0: tuple, d: tuple,
                       probes: tuple | None) -> float:
    """Held-out log-likelihood gain Σ (m/2)·ln(S0/S1) over P and Q-given-P [nats] (:func:`compare`'s
    ``gain_metric="decorrelated"``).

    Per ambient-band coefficient the noise covariance [[v_P, c], [c, v_Q]] = L·Lᵀ; u = L⁻¹·(x_P, x_Q) are
    uncorrelated with unit variance.  S0 and S1 are the sums of squares of u for the plain residual and the
    candidate's, S1 raised by twice the input noise's bias of S0 − S1 in that channel (the probes, as in
    :func:`compare`).
    """
    l00 = np.sqrt(vp)
    l10 = cpq / l00
    l11 = np.sqrt(np.maximum(vq - l10**2, 1e-9 * vq))

    def white(xp: np.ndarray, xq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, c = (x[:, None] if xp.ndim == 2 else x for x in (l00, l10, l11))  # probes: (m, draws)
        up = xp / a
        return up, (xq - b * up) / c

    u0p, u0q = white(*r0)
    udp, udq = white(*d)
    bp = bq = 0.0
    if probes is not None:
        g0p, g0q, dgp, dgq = probes
        w0p, w0q = white(g0p, g0q)
        wdp, wdq = white(dgp, dgq)
        bp = float(np.mean(-np.sum(w0p * wdp, axis=0)))
        bq = float(np.mean(-np.sum(w0q * wdq, axis=0)))
    m = u0p.size
    s0p, s0q = float(u0p @ u0p), float(u0q @ u0q)
    s1p = float(np.sum((u0p - udp) ** 2)) + 2.0 * bp
    s1q = float(np.sum((u0q - udq) ** 2)) + 2.0 * bq
    return 0.5 * m * (math.log(s0p / max(s1p, 1e-300)) + math.log(s0q / max(s1q, 1e-300)))


def _gls_metric(vp: np.ndarray, vq: np.ndarray, cpq: np.ndarray, plain_cov):
    """x ↦ C⁻¹x for the plain held-out residual's covariance C = N + J·cov·Jᵀ in the ambient band.

    N is block-diagonal per coefficient k: [[v_P, c_PQ], [c_PQ, v_Q]]; ``plain_cov`` = (jp, jq, cov) from
    :func:`prediction_cov` (or None: C = N).  The returned function takes and returns the P and Q parts
    (vectors of length m, or matrices with m rows).
    """
    det = np.maximum(vp * vq - cpq * cpq, 1e-9 * vp * vq)
    ipp, iqq, ipq = vq / det, vp / det, -cpq / det

    def ninv(xp, xq):
        if xp.ndim == 2:
            return ipp[:, None] * xp + ipq[:, None] * xq, ipq[:, None] * xp + iqq[:, None] * xq
        return ipp * xp + ipq * xq, ipq * xp + iqq * xq

    if plain_cov is None:
        return ninv
    jp, jq, cov = plain_cov
    lam, u = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = lam > 1e-14 * max(float(lam.max()), 1e-300)
    f = u[:, keep] * np.sqrt(lam[keep])
    lp, lq = jp @ f, jq @ f  # C = N + L·Lᵀ
    nlp, nlq = ninv(lp, lq)
    inner = np.linalg.inv(np.eye(lp.shape[1]) + lp.T @ nlp + lq.T @ nlq)

    def cinv(xp, xq):
        yp, yq = ninv(xp, xq)
        t = inner @ (lp.T @ yp + lq.T @ yq)
        return yp - nlp @ t, yq - nlq @ t

    return cinv


def dm_critical(alpha: float, m: int) -> float:
    """One-sided normal critical value with a Bonferroni correction over m candidates."""
    return float(stats.norm.isf(alpha / max(m, 1)))


def fd(y: np.ndarray, model: np.ndarray) -> float:
    """Fit degree of paper eq. 9: 1 − Σ(model − y)²/Σ(y − mean y)²."""
    e = model - y
    v = y - y.mean()
    return float(1.0 - (e @ e) / max(float(v @ v), 1e-300))
