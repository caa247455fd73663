"""Pooled identification: one motor D from k windows of the same bus, jointly.

Same hierarchical framework as :mod:`aslm_core.identify`: each window keeps its own initial state (the
motor starts from its steady state at the window's first sample) and, by default, its own static part
(the lower stage is that window's projection r_i = (I − Q_i·Q_iᵀ)(y_i − m_i(D))); with ``shared_static``
one static part serves all windows (one weighted regression over the stacked samples).  The upper stage
is a box- and equilibrium-constrained Levenberg–Marquardt over D on the stacked residuals of all windows,
each window and channel weighted by the inverse of its noise variance (re-estimated at the optimum), so
the pool is the Gaussian maximum-likelihood estimate when windows differ in SNR.  Standard errors come
from the stacked Jacobians (sandwich form with each window's residual spectrum, as the single window's; its lag-1
autocorrelation with ``stderr_method="ar1"``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import get_args

import numpy as np

from aslm_core import excitation, instrumental, optimize, static
from aslm_core.errors import WindowError
from aslm_core.identify import (
    EQUILIBRIUM_MARGIN,
    IV_OVERID_MAX,
    OWN_UNMODELLED_RATIO,
    SE_SMOOTH_HZ,
    Problem,
    _transient_skip,
    identify,
    score_variance,
)
from aslm_core.params import DYNAMIC_NAMES, dynamic_bounds
from aslm_core.preprocess import prepare
from aslm_core.result import IdentifyConfig, IvEstimator, IvWhitening
from aslm_core.window import Window

# Reweighting passes: noise variances at the start, then at the optimum of the previous pass.
_PASSES = 2


@dataclass
class PooledResult:
    """One D identified from several windows of a bus.

    Attributes
    ----------
    dynamic : dict
        D = {a [1/s], b [1/s], H2 [s], Tm [pu]}.
    stderr : dict
        Standard errors of D (sandwich form over the stacked windows).
    cov : list of list
        4×4 covariance of D in the order a, b, H2, Tm.
    static : list of dict
        Static coefficients per window (one entry, shared, with ``shared_static``) [pu].
    noise_std : list of list
        Per window, the residual std of P and Q [pu] (the weights' inverse square roots).
    objective : float
        Weighted sum of squares Σ_i Σ_c ‖r_ic‖²/σ_ic² at the optimum [-] (≈ number of samples); where the IV
        answers (``disturbance`` below) the windows' IV criteria summed (2SLS: ½·Σ_i Σ_c ‖P_Z·ε_ic‖²/σ_ic²) [-].
    n_windows : int
    iterations, evaluations : int
        LM iterations and window simulations.
    status : str
        ``converged``, ``max_iter`` or ``stalled``.
    flags : list of str
        ``at_bound:NAME``, ``equilibrium_constraint_active``; where the IV ran ``iv_instruments_rejected`` (the
        pool's over-identification statistic over its degrees of freedom above
        :data:`aslm_core.identify.IV_OVERID_MAX`); ``own_fluctuation_unmodelled`` where the gate wanted the IV and
        the white-noise answer was kept (the IV rejected or failed, or ``shared_static``).
    elapsed_s : float
    own_ratio_p : float
        The load's own fluctuation over the ambient part of P at the white-noise optimum, pooled over the windows
        (:func:`pool_own_ratio`) [-]: what the gate of ``disturbance="gated"`` reads.
    disturbance : str
        The estimate returned: ``none`` (white noise per window and channel) or ``ar_iv``.
    """

    dynamic: dict[str, float]
    stderr: dict[str, float]
    cov: list[list[float]]
    static: list[dict[str, float]]
    noise_std: list[list[float]]
    objective: float
    n_windows: int
    iterations: int = 0
    evaluations: int = 0
    status: str = "converged"
    flags: list[str] = field(default_factory=list)
    elapsed_s: float = 0.0
    own_ratio_p: float = 0.0
    disturbance: str = "none"

    @property
    def d(self) -> np.ndarray:
        """D as an array [a, b, H2, Tm]."""
        return np.array([self.dynamic[k] for k in DYNAMIC_NAMES])

    def to_dict(self) -> dict:
        """Plain JSON-serialisable dict."""
        return asdict(self)


class _Pool:
    """The windows' problems, their common box and equilibrium constraint, and the stacked fit."""

    def __init__(self, problems: list[Problem], shared_static: bool) -> None:
        self.problems = problems
        self.shared = shared_static
        self.v_min = min(p.v_min for p in problems)
        # Tm ≤ mean P of the pool (each window's bound is its own mean P).
        self.lower, self.upper = dynamic_bounds(float(np.mean([p.p_mean for p in problems])))
        self.weights = np.ones((len(problems), 2))
        self.evaluations = 0

    def feasible(self, d: np.ndarray) -> bool:
        return bool(optimize.feasible(d, self.lower, self.upper, self.v_min, EQUILIBRIUM_MARGIN))

    def into_feasible(self, d: np.ndarray) -> np.ndarray:
        d = np.minimum(np.maximum(np.asarray(d, dtype=np.float64), self.lower), self.upper)
        d[3] = min(d[3], (1.0 - 2 * EQUILIBRIUM_MARGIN) * d[0] * self.v_min**2 / (2.0 * d[1]))
        return d

    def blocks(self, d: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] | None:
        """Per window: projected residuals of P and Q and their D-Jacobians; None if a simulation fails."""
        self.evaluations += len(self.problems)
        if not self.shared:
            out = []
            for p in self.problems:
                r = p.residuals(d)
                if r is None:
                    return None
                out.append(r)
            return out
        return self._shared_blocks(d)

    def _shared_blocks(self, d: np.ndarray):
        """Residuals and Jacobians with one static part: a weighted projection over the stacked samples."""
        raw = []
        for p in self.problems:
            if p.residuals(d) is None:  # fills p._p, p._q, p._dp, p._dq: the motor and its gradient
                return None
            k0 = p.k0
            raw.append((p.p_meas - p._p[k0:], p.q_meas - p._q[k0:], -p._dp[k0:], -p._dq[k0:]))
        out = [[None] * 4 for _ in raw]
        for c in range(2):
            sw = np.sqrt(self.weights[:, c])
            phi = np.vstack([sw[i] * static.regressors(p.prep.V[p.k0:], p.config.static)
                             for i, p in enumerate(self.problems)])
            q, _ = optimize.thin_qr(np.ascontiguousarray(phi))
            y = np.concatenate([sw[i] * raw[i][c] for i in range(len(raw))])
            jac = np.vstack([sw[i] * raw[i][2 + c] for i in range(len(raw))])
            y -= q @ (q.T @ y)
            jac -= q @ (q.T @ jac)
            start = 0
            for i, p in enumerate(self.problems):
                # Unweighted back, so that the stacked sums below weight every block the same way.
                out[i][c] = y[start:start + p.l] / sw[i]
                out[i][2 + c] = jac[start:start + p.l] / sw[i]
                start += p.l
        return [tuple(o) for o in out]

    def normal(self, blocks) -> tuple[float, np.ndarray, np.ndarray]:
        """Weighted cost Σ w‖r‖², gradient Σ w·Jᵀr and Gauss–Newton matrix Σ w·JᵀJ."""
        cost, g, a = 0.0, np.zeros(4), np.zeros((4, 4))
        for (rp, rq, jp, jq), (wp, wq) in zip(blocks, self.weights, strict=True):
            cost += wp * float(rp @ rp) + wq * float(rq @ rq)
            g += wp * (jp.T @ rp) + wq * (jq.T @ rq)
            a += wp * (jp.T @ jp) + wq * (jq.T @ jq)
        return cost, g, a

    def reweight(self, blocks) -> None:
        """Weights 1/σ² per window and channel from the residuals (static columns and D counted out)."""
        for i, (rp, rq, _, _) in enumerate(blocks):
            dof = max(rp.size - self.problems[i].basis.shape[1] - 4.0 / len(blocks), 1.0)
            self.weights[i] = [dof / max(float(rp @ rp), 1e-300), dof / max(float(rq @ rq), 1e-300)]


def _lm(pool: _Pool, d0: np.ndarray, max_iter: int, xtol: float) -> dict:
    """Levenberg–Marquardt over D on the stacked weighted residuals, steps by :func:`optimize.qp_step`."""
    d = pool.into_feasible(d0)
    blocks = pool.blocks(d)
    if blocks is None:
        return {"d": d, "cost": math.inf, "iterations": 0, "status": "failed", "blocks": None}
    cost, g, a = pool.normal(blocks)
    lam, nu = 1e-3, 2.0
    work, vec, ivec, step = np.empty((4, 4)), np.empty((3, 4)), np.empty((3, 4), dtype=np.int64), np.empty(4)
    status, it = "max_iter", 0
    margin = EQUILIBRIUM_MARGIN
    while it < max_iter:
        it += 1
        gc = np.array([pool.v_min**2 * (1.0 - margin), -2.0 * d[3], 0.0, -2.0 * d[1]])
        c_d = float(gc[0] * d[0] - 2.0 * d[1] * d[3])
        accepted = converged = False
        moved = 0.0
        for _ in range(14):
            m = a + lam * np.diag(np.maximum(np.diag(a), 1e-12 * np.max(np.diag(a)) + 1e-300))
            # The cost is Σ w‖r‖² (no ½): its model is cost + 2gᵀs + sᵀAs, with the same minimiser as
            # qp_step's gᵀs + ½sᵀMs.
            if not optimize.qp_step(m, g, d, pool.lower, pool.upper, gc, c_d, step, work, vec, ivec):
                lam *= nu
                nu *= 2.0
                continue
            if -(2.0 * float(g @ step) + float(step @ a @ step)) <= optimize.FTOL * cost:
                converged = True
                break
            trial = np.minimum(np.maximum(d + step, pool.lower), pool.upper)
            alpha = 1.0
            while not pool.feasible(trial) and alpha > 1e-6:
                alpha *= 0.5
                trial = np.minimum(np.maximum(d + alpha * step, pool.lower), pool.upper)
            tb = pool.blocks(trial) if pool.feasible(trial) else None
            if tb is not None:
                cost_t, g_t, a_t = pool.normal(tb)
                su = trial - d
                pred = -(2.0 * float(g @ su) + float(su @ a @ su))
                if cost_t < cost and pred > 0.0:
                    rho = (cost - cost_t) / pred
                    lam = max(lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-12)
                    nu = 2.0
                    moved = float(np.max(np.abs(trial - d) / (np.abs(d) + 1e-3)))
                    if alpha < 1.0:
                        moved = math.inf
                    d, blocks, cost, g, a = trial, tb, cost_t, g_t, a_t
                    accepted = True
                    break
            lam *= nu
            nu *= 2.0
        if converged:
            status = "converged"
            break
        if not accepted:
            status = "stalled"
            break
        if moved < xtol:
            status = "converged"
            break
    return {"d": d, "cost": cost, "iterations": it, "status": status, "blocks": blocks}


def _covariance(pool: _Pool, blocks) -> np.ndarray:
    """A⁻¹·M·A⁻¹ with A = Σ w·JᵀJ and M the summed variances of the blocks' weighted scores w·Jᵀr.

    With ``stderr_method="spectral"`` (the default, as the single window's) each block's score variance comes from its
    residual's smoothed spectrum (:func:`aslm_core.identify.score_variance`, times l/(l − static columns)); with
    ``"ar1"`` it is w·g·JᵀJ, g = (1+ρ)/(1−ρ) the lag-1 inflation (w = 1/σ²: the noise term w²·σ² reduces to w).  inf
    on the diagonal where A is singular.
    """
    a, m = np.zeros((4, 4)), np.zeros((4, 4))
    for prob, (rp, rq, jp, jq), (wp, wq) in zip(pool.problems, blocks, pool.weights, strict=True):
        for r, j, w in ((rp, jp, wp), (rq, jq, wq)):
            jj = j.T @ j
            a += w * jj
            if prob.config.stderr_method == "spectral":
                m += (w * w * r.size / max(r.size - prob.basis.shape[1], 1)) * score_variance(r, j, prob.prep.dt)
                continue
            rho = min(max(float(r[1:] @ r[:-1]) / max(float(r @ r), 1e-300), 0.0), 0.95)
            m += w * (1.0 + rho) / (1.0 - rho) * jj
    try:
        ainv = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.diag(np.full(4, np.inf))
    return ainv @ m @ ainv.T


def _static_parts(pool: _Pool, d: np.ndarray) -> list[dict[str, float]]:
    """Static coefficients at D: per window (its own regression) or one over the stacked windows."""
    rows, ys = [], []
    for p in pool.problems:
        p.residuals(d, jacobian=False)
        phi = static.regressors(p.prep.V[p.k0:], p.config.static)
        y = np.column_stack([p.p_meas - p._p[p.k0:], p.q_meas - p._q[p.k0:]])
        rows.append(phi)
        ys.append(y)
    model = pool.problems[0].config.static
    if pool.shared:
        out = []
        for c in range(2):
            sw = np.sqrt(pool.weights[:, c])
            phi = np.vstack([s * f for s, f in zip(sw, rows, strict=True)])
            y = np.concatenate([s * y[:, c] for s, y in zip(sw, ys, strict=True)])
            out.append(np.linalg.lstsq(phi, y, rcond=None)[0])
        return [static.coefficients(out[0], out[1], model)]
    parts = []
    for phi, y in zip(rows, ys, strict=True):
        beta = np.linalg.lstsq(phi, y, rcond=None)[0]
        parts.append(static.coefficients(beta[:, 0], beta[:, 1], model))
    return parts


def pool_own_ratio(pool: _Pool, blocks) -> float:
    """The load's own fluctuation over the ambient part of P, pooled over a pool's windows [-].

    Each window's split of its P channel as the single window's (:func:`aslm_core.excitation.variances`: the measured
    variance over the regression samples and the projected residual's, each less the white floor); the pool's ratio is
    √(Σ own / Σ ambient), the windows weighted by their ambient variance as a pool of one long window would weigh them.
    """
    own = amb = 0.0
    for prob, (rp, _, _, _) in zip(pool.problems, blocks, strict=True):
        white = excitation.white_variance(prob.prep.noise.get("noise_p", 0.0), 1.0 / prob.prep.dt,
                                          prob.prep.lowpass_hz)
        o, a = excitation.variances(float(np.var(prob.p_meas)), float(rp @ rp) / rp.size, white)
        own, amb = own + o, amb + a
    return math.sqrt(own / amb)


def identify_pooled(windows: Sequence[Window], *, start: np.ndarray | Sequence[float] | None = None,
                    config: IdentifyConfig | None = None, shared_static: bool = False,
                    max_iter: int | None = None, xtol: float = 1e-7, disturbance: str = "gated",
                    iv_estimator: IvEstimator = "liml", iv_whitening: IvWhitening = "own") -> PooledResult:
    """Identify one D = [a, b, H2, Tm] from several windows of the same bus, jointly.

    Parameters
    ----------
    windows : sequence of Window
        Windows of one bus over which the load is taken as stationary (e.g. the last k periods).
    start : array_like, optional
        First iterate (e.g. the previous pooled D); default: the component-wise median of the windows'
        own identifications (:func:`aslm_core.identify`, which also costs one fit per window).
    config : IdentifyConfig, optional
        Integrator, static model, skip, preprocessing of every window (``objective``, ``disturbance``,
        ``iv_estimator`` and ``iv_whitening`` do not apply: the pool weights each window and channel by its inverse
        noise variance; the disturbance model and the IV's options are the arguments below).
    shared_static : bool
        One static part for all windows instead of one per window.
    max_iter : int, optional
        LM iterations per reweighting pass (default ``config.max_iter``).
    xtol : float
        Relative step below which the LM stops.
    disturbance : {"gated", "none", "ar_iv"}
        ``none``: white noise per window and channel (above).  ``ar_iv``: from that optimum, the instrumental-
        variable fit of :mod:`aslm_core.instrumental` with per-window AR models of the load's own fluctuation and
        per-window instruments, one D (the windows' IV criteria summed); standard errors from the summed
        moment conditions with each window's innovation spectrum (``config.stderr_method="ar1"``: white).  Not
        with ``shared_static``.  ``gated`` (default, as ``identify``'s): the white-noise answer unless the pool's
        own-fluctuation ratio at it (:func:`pool_own_ratio`) is above
        :data:`aslm_core.identify.OWN_UNMODELLED_RATIO`, where output error is not consistent (the loop through
        the network); then the IV's, unless its instruments are rejected or it fails (the white-noise answer,
        flagged ``own_fluctuation_unmodelled``).
    iv_estimator, iv_whitening : str
        The pooled IV's criterion and AR models (as :class:`IdentifyConfig`'s fields of the same names).  Default
        LIML with the own fluctuation's AR models, not the single window's 2SLS with the residual's: they take the
        P/Q noise's bias off the IV below full P–Q coherence at the cost of a larger spread per window, which a
        pool averages down and a single window does not (docs/numerics.md, "Stop 37" and "Stop 38: the pool's
        IV options").

    Returns
    -------
    PooledResult

    Raises
    ------
    WindowError
        When a window fails its checks or the pool has no finite objective.
    ValueError
        When ``windows`` is empty.
    """
    t0 = time.perf_counter()
    if not windows:
        raise ValueError("identify_pooled needs at least one window")
    if disturbance not in ("gated", "none", "ar_iv"):
        raise ValueError(f"disturbance must be 'gated', 'none' or 'ar_iv', got {disturbance!r}")
    if iv_estimator not in get_args(IvEstimator) or iv_whitening not in get_args(IvWhitening):
        raise ValueError(f"iv_estimator must be one of {get_args(IvEstimator)} and iv_whitening one of "
                         f"{get_args(IvWhitening)}, got {iv_estimator!r}, {iv_whitening!r}")
    if disturbance == "ar_iv" and shared_static:
        raise ValueError("disturbance='ar_iv' estimates each window's static part in its instrument space: "
                         "not with shared_static")
    config = config or IdentifyConfig()
    max_iter = max_iter or config.max_iter
    preps = [prepare(w, max_gap_samples=config.max_gap_samples, min_duration_s=config.min_duration_s,
                     lowpass_hz=config.lowpass_hz, floors=True, input_smoother=config.input_smoother,
                     input_cutoff_hz=config.input_cutoff_hz, input_noise=config.input_noise) for w in windows]
    if start is None:
        start = np.median([identify(w, config=config).d for w in windows], axis=0)
    d = np.asarray(start, dtype=np.float64)
    pool = _Pool([Problem(p, w.f0, config) for p, w in zip(preps, windows, strict=True)], shared_static)
    iterations = evaluations = 0
    fit: dict = {}
    for pass_ in range(_PASSES + 1):
        if pass_ == _PASSES:
            # The slow motor's initial-state error outlives a short skip: polish on later samples.
            skips = [_transient_skip(d, p, w.f0, config) for p, w in zip(preps, windows, strict=True)]
            if all(s <= config.skip_s + 0.5 * p.dt for s, p in zip(skips, preps, strict=True)):
                break
            old = pool
            pool = _Pool([Problem(p, w.f0, replace(config, skip_s=s))
                          for p, w, s in zip(preps, windows, skips, strict=True)], shared_static)
            pool.weights = old.weights
            evaluations += old.evaluations
        blocks = pool.blocks(pool.into_feasible(d))
        if blocks is None:
            raise WindowError("no_solution", "the pooled start could not be simulated")
        pool.reweight(blocks)
        fit = _lm(pool, d, max_iter, xtol)
        if not math.isfinite(fit["cost"]):
            raise WindowError("no_solution", "no finite pooled objective")
        d, iterations = fit["d"], iterations + fit["iterations"]
    pool.reweight(fit["blocks"])
    cost, _, _ = pool.normal(fit["blocks"])
    cov = _covariance(pool, fit["blocks"])
    own_ratio = pool_own_ratio(pool, fit["blocks"])
    flags, answered = [], "none"
    wants_iv = disturbance == "ar_iv" or (disturbance == "gated" and own_ratio > OWN_UNMODELLED_RATIO)
    if wants_iv and not shared_static:
        iv = instrumental.fit_pooled(pool, pool.problems, d, max_iter=max_iter, xtol=xtol, margin=EQUILIBRIUM_MARGIN,
                                     max_order=config.ar_max_order,
                                     se_smooth_hz=SE_SMOOTH_HZ if config.stderr_method == "spectral" else None,
                                     couple=config.couple_channels, estimator=iv_estimator,
                                     whitening=iv_whitening)
        evaluations += iv["evaluations"]
        rejected = math.isfinite(iv["cost"]) and iv["overid"] > IV_OVERID_MAX
        if rejected:
            flags.append("iv_instruments_rejected")
        if math.isfinite(iv["cost"]) and (disturbance == "ar_iv" or not rejected):
            d, cost, cov, answered = iv["d"], iv["cost"], iv["cov"], "ar_iv"
            iterations += iv["iterations"]
    if wants_iv and answered == "none":
        flags.append("own_fluctuation_unmodelled")
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    flags += [f"at_bound:{n}" for i, n in enumerate(DYNAMIC_NAMES)
              if d[i] <= pool.lower[i] * (1 + 1e-9) or d[i] >= pool.upper[i] * (1 - 1e-9)]
    if (d[0] * pool.v_min**2 - 2 * d[1] * d[3]) / (d[0] * pool.v_min**2) < 0.01:
        flags.append("equilibrium_constraint_active")
    static_parts = _static_parts(pool, d)
    return PooledResult(
        dynamic={k: float(v) for k, v in zip(DYNAMIC_NAMES, d, strict=True)},
        stderr={k: float(v) for k, v in zip(DYNAMIC_NAMES, se, strict=True)},
        cov=cov.tolist(),
        static=static_parts,
        noise_std=(1.0 / np.sqrt(pool.weights)).tolist(),
        objective=float(cost),
        n_windows=len(windows),
        iterations=iterations,
        evaluations=evaluations + pool.evaluations,
        status=fit["status"],
        flags=flags,
        elapsed_s=time.perf_counter() - t0,
        own_ratio_p=own_ratio,
        disturbance=answered,
    )
