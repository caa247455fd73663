"""Fit a candidate on the training samples (hierarchical: regression inside, optimisation outside) and
judge it on the held-out samples.

Upper stage: ``scipy.optimize.least_squares`` (trust-region reflective, finite differences) over the
nonlinear parameters — D = [a, b, H2, Tm] in identified mode plus the candidate's own z.  Lower stage:
for given (D, z) the linear coefficients (ZIP and the candidate's linear extras) are the least-squares
solution on the training samples, so the upper stage sees the projected residual (variable projection).
Both channels are weighted by their noise level (1/σ², σ from the noise floor): the weighted sum of
squares is the Gaussian likelihood with known per-channel noise, so P and Q count by their information.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from aslm_core.diagnosis.candidates.base import Candidate, Context, Prediction
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

    def residuals(self, seg: Segment) -> tuple[np.ndarray, np.ndarray]:
        """Measured minus model over the whole window [pu]."""
        return seg.P - self.model_p, seg.Q - self.model_q


def _lstsq(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    # Column scaling keeps the normal problem well conditioned ([1, V, V²] are nearly collinear).
    s = np.sqrt(np.sum(x * x, axis=0))
    s[s == 0] = 1.0
    beta, *_ = np.linalg.lstsq(x / s, y, rcond=1e-10)
    return beta / s


def _train_residuals(pr: Prediction, seg: Segment, sig: tuple[float, float]):
    tr = seg.train
    bp = _lstsq(pr.xp[tr], seg.P[tr] - pr.mp[tr])
    bq = _lstsq(pr.xq[tr], seg.Q[tr] - pr.mq[tr])
    rp = (seg.P[tr] - pr.mp[tr] - pr.xp[tr] @ bp) / sig[0]
    rq = (seg.Q[tr] - pr.mq[tr] - pr.xq[tr] @ bq) / sig[1]
    return rp, rq, bp, bq


def fit_candidate(cand: Candidate, seg: Segment, ctx: Context, sig: tuple[float, float], *,
                  d_start: np.ndarray | None = None, z_starts: list[np.ndarray] | None = None,
                  max_nfev: int | None = None) -> Fit:
    """Fit one candidate on ``seg.train``.

    Parameters
    ----------
    cand : Candidate
    seg : Segment
    ctx : Context
        Identified mode frees D; user mode keeps ``ctx.d0``.
    sig : (float, float)
        Noise std of P and Q [pu] (weights).
    d_start : ndarray, optional
        Start of D (default ``ctx.d0``).
    z_starts : list of ndarray, optional
        Starts of z (default ``cand.starts``); the best run is kept.
    max_nfev : int, optional
        Function evaluations per start.
    """
    d0 = np.asarray(ctx.d0 if d_start is None else d_start, dtype=np.float64)
    z_starts = cand.starts(seg, ctx) if z_starts is None else z_starts
    zlo, zhi = cand.bounds(seg, ctx)
    free = ctx.free
    if free:
        dlo, dhi = dynamic_bounds(float(np.mean(seg.P)))
        dlo, dhi = dlo.copy(), dhi.copy()
        dhi[3] = max(dhi[3], d0[3] * 1.05, 1e-6)
        lo, hi = np.concatenate([dlo, zlo]), np.concatenate([dhi, zhi])
    else:
        lo, hi = np.asarray(zlo, float), np.asarray(zhi, float)
    n_tr = seg.ks - seg.k0

    def unpack(x):
        return (x[:4], x[4:]) if free else (d0, x)

    def resid(x):
        d, z = unpack(x)
        pr = cand.predict(seg, ctx, d, z)
        if pr is None:
            return np.full(2 * n_tr, _FAIL)
        rp, rq, _, _ = _train_residuals(pr, seg, sig)
        r = np.concatenate([rp, rq])
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
    return evaluate(cand, seg, ctx, d, z, sig, res=best, nfev=nfev)


def evaluate(cand: Candidate, seg: Segment, ctx: Context, d: np.ndarray, z: np.ndarray,
             sig: tuple[float, float], *, res=None, nfev: int = 0) -> Fit:
    """The lower stage alone for given (D, z): linear coefficients on the training samples, model over
    the window (``res``, the upper stage's result, adds standard errors of z)."""
    pr = cand.predict(seg, ctx, d, z)
    if pr is None:
        nan = np.full(seg.n, np.nan)
        return Fit(np.asarray(d, float), np.asarray(z, float), np.zeros(0), np.zeros(0), nan, nan, math.inf,
                   ok=False, nfev=nfev)
    rp, rq, bp, bq = _train_residuals(pr, seg, sig)
    model_p = pr.mp + pr.xp @ bp
    model_q = pr.mq + pr.xq @ bq
    cost = 0.5 * float(rp @ rp + rq @ rq)
    fit = Fit(np.array(d, float), np.array(z, float), bp, bq, model_p, model_q, cost, nfev=nfev)
    if res is None:
        res = optimize.OptimizeResult(jac=np.zeros((rp.size + rq.size, 0)))
    _parameters(fit, cand, seg, pr, res, rp, rq, sig, ctx.free)
    return fit


def _ar1_inflation(r: np.ndarray) -> float:
    """(1 + ρ)/(1 − ρ) for the lag-1 autocorrelation ρ of a residual (clipped to [0, 0.95])."""
    rho = float(r[1:] @ r[:-1]) / max(float(r @ r), 1e-300)
    rho = min(max(rho, 0.0), 0.95)
    return (1.0 + rho) / (1.0 - rho)


def _parameters(fit: Fit, cand: Candidate, seg: Segment, pr: Prediction, res, rp, rq, sig, free: bool) -> None:
    """Fill the candidate's parameters and standard errors into ``fit``."""
    params: dict[str, float] = {}
    stderr: dict[str, float] = {}
    n_static = pr.xp.shape[1] - len(cand.lin_p)
    tr = seg.train
    for name, cols, beta, r, s in (("p", cand.lin_p, fit.beta_p, rp, sig[0]), ("q", cand.lin_q, fit.beta_q, rq, sig[1])):
        if not cols:
            continue
        x = (pr.xp if name == "p" else pr.xq)[tr]
        var = float(r @ r) / max(r.size - x.shape[1], 1) * s * s * _ar1_inflation(r)
        try:
            xs = np.sqrt(np.sum(x * x, axis=0))
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
        off = 4 if free else 0
        for i, c in enumerate(cand.nl_names):
            params[c] = float(fit.z[i])
            stderr[c] = float(se_all[off + i]) if off + i < se_all.size else float("inf")
    if free:
        for i, c in enumerate(DYNAMIC_NAMES):
            params.setdefault(f"D.{c}", float(fit.d[i]))
    fit.params = params
    fit.stderr = stderr


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
        Held-out score statistic Σ r0·Δ/σ² / sqrt(ΣΔ²/σ²) of the plain residual r0 against the
        candidate's correction Δ = model1 − model0 (both channels, noise-weighted).  Δ depends only on the
        training samples and the inputs, so with white measurement noise score_z ~ N(0, 1) when the
        candidate is not needed, whatever its number of parameters.
    dm_z : float
        Diebold–Mariano statistic of the weighted squared-error differential (plain − candidate), HAC
        (reported; weaker on a few seconds of held-out data).
    gain : float
        Held-out log-likelihood gain Σ_ch (n/2)·ln(SSR0/SSR1) [nats].
    penalised_gain : float
        gain − (k/2)·ln(n) (BIC-like penalty for the k added parameters) [nats].
    reduction_p, reduction_q : float
        Held-out residual-variance reduction 1 − SSR1/SSR0 per channel [-].
    excess_p, excess_q : float or None
        Share of the held-out residual variance *above the noise floor* removed, (SSR0 − SSR1)/(SSR0 − n·σ²)
        per channel [-]; None when the channel has (almost) no excess to remove.
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


def compare(seg: Segment, plain: Fit, cand: Fit, k: int, sig: tuple[float, float], lag_s: float = 1.0) -> Comparison:
    """Compare a candidate with the plain fit on the held-out samples of one segment."""
    te = seg.test
    r0p, r0q = (seg.P - plain.model_p)[te], (seg.Q - plain.model_q)[te]
    r1p, r1q = (seg.P - cand.model_p)[te], (seg.Q - cand.model_q)[te]
    n = r0p.size
    if not cand.ok or not np.all(np.isfinite(r1p)) or not np.all(np.isfinite(r1q)):
        return Comparison(-math.inf, -math.inf, -math.inf, -math.inf, 0.0, 0.0, n)
    dl = (r0p**2 - r1p**2) / sig[0] ** 2 + (r0q**2 - r1q**2) / sig[1] ** 2
    lag = max(1, min(int(round(lag_s / seg.dt)), n // 4))
    z = float(dl.mean() / math.sqrt(hac_variance(dl, lag) / n))
    dp, dq = r0p - r1p, r0q - r1q  # = model1 − model0
    num = float(r0p @ dp) / sig[0] ** 2 + float(r0q @ dq) / sig[1] ** 2
    den = math.sqrt(max(float(dp @ dp) / sig[0] ** 2 + float(dq @ dq) / sig[1] ** 2, 1e-300))
    score = num / den
    s0p, s0q, s1p, s1q = (float(r @ r) for r in (r0p, r0q, r1p, r1q))
    gain = 0.5 * n * (math.log(s0p / s1p) + math.log(s0q / s1q))
    ex = []
    for s0, s1, sg in ((s0p, s1p, sig[0]), (s0q, s1q, sig[1])):
        noise = n * sg * sg
        ex.append((s0 - s1) / (s0 - noise) if s0 - noise > 0.05 * noise else None)
    return Comparison(score, z, gain, gain - 0.5 * k * math.log(n), 1.0 - s1p / s0p, 1.0 - s1q / s0q, n, ex[0], ex[1])


def dm_critical(alpha: float, m: int) -> float:
    """One-sided normal critical value with a Bonferroni correction over m candidates."""
    return float(stats.norm.isf(alpha / max(m, 1)))


def fd(y: np.ndarray, model: np.ndarray) -> float:
    """Fit degree of paper eq. 9: 1 − Σ(model − y)²/Σ(y − mean y)²."""
    e = model - y
    v = y - y.mean()
    return float(1.0 - (e @ e) / max(float(v @ v), 1e-300))
