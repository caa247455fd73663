"""A disturbance model for the identifier: the load's own fluctuation as an AR process (prediction error).

The output-error fit treats what the voltage does not explain as white noise.  At a load bus much of it is
the load's own switching: coloured, and (through the network impedance) correlated with V and θ, so the
output-error estimate is biased (closed loop).  The prediction-error method with a noise model H = 1/A(q)
fitted to the window stays consistent in closed loop when H is right: the residual e = A(q)·(y − m(D) − Φβ)
is white.  A(q) is linear, so it whitens the residual and its Jacobian alike and the Levenberg–Marquardt
structure (variable projection over the static part, box and equilibrium constraints) carries over.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from aslm_core import motor, optimize
from aslm_core.params import DYNAMIC_NAMES

#: Longest AR model tried [samples]; 0.3 s at 100 frames/s covers a 2 Hz process's correlation.
AR_MAX_ORDER = 30


def autocovariance(r: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased autocovariance of r (mean removed) at lags 0 … max_lag [units of r²]."""
    x = r - r.mean()
    n = x.size
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    spec = np.fft.rfft(x, nfft)
    return np.fft.irfft(spec.real**2 + spec.imag**2, nfft)[: max_lag + 1] / n


def levinson_orders(r: np.ndarray, max_order: int) -> tuple[list[np.ndarray], np.ndarray]:
    """AR polynomials of every order up to max_order from a residual (Yule–Walker by Levinson–Durbin).

    Parameters
    ----------
    r : ndarray
        Residual [pu].
    max_order : int

    Returns
    -------
    polys : list of ndarray
        polys[p] = [1, a1, ..., ap], so that A(q)·r is the order-p prediction error.
    var : ndarray
        Prediction-error variance of each order [pu²].
    """
    return levinson(autocovariance(r, max_order))


def levinson(acf: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """AR polynomials of every order up to len(acf) − 1 from an autocovariance (Levinson–Durbin recursion).

    Parameters
    ----------
    acf : ndarray
        Autocovariance at lags 0, 1, … [pu²].

    Returns
    -------
    polys, var : as :func:`levinson_orders`.
    """
    max_order = acf.size - 1
    a = np.array([1.0])
    e = acf[0]
    polys, var = [a], [e]
    for p in range(1, max_order + 1):
        k = -(acf[p] + a[1:] @ acf[p - 1:0:-1]) / e
        a = np.concatenate([a, [0.0]])
        a = a + k * a[::-1]
        e *= 1.0 - k * k
        polys.append(a.copy())
        var.append(max(e, 1e-300))
    return polys, np.array(var)


def ar_whitener(r: np.ndarray, max_order: int = AR_MAX_ORDER) -> np.ndarray:
    """The AR polynomial A(q) that whitens r, its order chosen by the Bayesian information criterion.

    Parameters
    ----------
    r : ndarray
        Residual [pu].
    max_order : int
        Longest model tried.

    Returns
    -------
    ndarray
        [1, a1, ..., ap] (p = 0: [1.0], the residual is already white).
    """
    n = r.size
    polys, var = levinson_orders(r, min(max_order, n // 10))
    p = np.arange(var.size)
    bic = n * np.log(var) + p * math.log(n)
    return polys[int(np.argmin(bic))]


#: Largest |second / first difference| of log γ at lags 1–3 that :func:`exponential_autocovariance` reads as an
#: exponential autocovariance (0 for one).  Development windows (synthetic seed 243, ANDES own seed 1, own/total 0.9,
#: ρ = 0.7; p10–p90 of 20 per shape, ``benchmarks.own_iv_noise --shape-statistics``): switching −0.17 to +0.15, 2 Hz and
#: 1/f own processes −0.69 to −0.42.
EXPONENTIAL_CURVATURE_MAX = 0.25
#: Smallest lag-1 autocorrelation for it: a mostly white residual has no coloured part to take the noise out of.
EXPONENTIAL_LAG1_MIN = 0.5


def exponential_autocovariance(g: np.ndarray) -> bool:
    """Whether an autocovariance is exponential at lags 1–3 (an AR(1)-like process, e.g. many small loads switching)
    plus white noise, which shows at lag 0 only.

    Parameters
    ----------
    g : ndarray
        Autocovariance at lags 0 … ≥ 3.

    Returns
    -------
    bool
        |:func:`log_curvature`| ≤ :data:`EXPONENTIAL_CURVATURE_MAX` and γ(1) ≥ :data:`EXPONENTIAL_LAG1_MIN`·γ(0).
    """
    if g[1] < EXPONENTIAL_LAG1_MIN * g[0]:
        return False
    return abs(log_curvature(g)) <= EXPONENTIAL_CURVATURE_MAX


def log_curvature(g: np.ndarray) -> float:
    """(log γ(1) − 2·log γ(2) + log γ(3)) / |log γ(2) − log γ(1)| of an autocovariance [-]: 0 where it is exponential
    at lags 1–3, negative where log γ bends down (a smooth process), positive where it levels off; inf where γ(1 … 3) is not
    positive and falling."""
    if np.any(g[1:4] <= 0.0):
        return math.inf
    lg = np.log(g[1:4])
    slope = lg[1] - lg[0]
    return float((lg[0] - 2.0 * lg[1] + lg[2]) / abs(slope)) if slope < 0.0 else math.inf


def own_whitener(r: np.ndarray, max_order: int = AR_MAX_ORDER) -> np.ndarray:
    """The AR polynomial of r's coloured part alone: :func:`ar_whitener`'s, with the white noise's variance taken off
    γ(0) first where the autocovariance says how much it is.

    r is the load's own fluctuation plus the PMU's white noise on P and Q.  The instruments of the IV see the own
    fluctuation (through V) but not the noise, so they are uncorrelated with the whitened residual only if the filter
    whitens the own part; the AR model of the sum does not (its Yule–Walker equations differ at lag 0), and on a
    step-like own process, whose per-sample innovation is small, the difference biases the IV (docs/numerics.md,
    "Stop 37").  For an exponential autocovariance (:func:`exponential_autocovariance`) the white variance is
    γ(0) − γ(1)²/γ(2) (γ_own(0) = γ(1)/φ with φ = γ(2)/γ(1)); elsewhere nothing is taken off.

    Parameters
    ----------
    r : ndarray
        Residual [pu].
    max_order : int
        Longest model tried (the order is :func:`ar_whitener`'s, by BIC on r).

    Returns
    -------
    ndarray
        [1, a1, ..., ap].
    """
    chosen = ar_whitener(r, max_order)
    p = len(chosen) - 1
    g = autocovariance(r, max(p, 3))
    if p == 0 or not exponential_autocovariance(g):
        return chosen
    white = g[0] - g[1] * g[1] / g[2]
    g = g[: p + 1].copy()
    g[0] -= min(max(white, 0.0), 0.99 * g[0])
    polys, var = levinson(g)
    return polys[-1] if np.all(var > 0.0) else chosen


#: The AR noise models of the IV's passes by name (``IdentifyConfig.iv_whitening``).
WHITENERS = {"residual": "ar_whitener", "own": "own_whitener"}


def whitener(name: str):
    """The whitening function named ``name`` (:data:`WHITENERS`), looked up at call time."""
    return globals()[WHITENERS[name]]


class Whitened:
    """The identification problem with its P and Q residuals whitened by fixed AR polynomials.

    Parameters
    ----------
    problem : aslm_core.problem.Problem
        The output-error problem (inputs, regression samples, bounds, buffers).
    polys : tuple of ndarray
        A(q) of P and of Q (of Q − mix·P with ``mix``).
    mix : float
        The second channel is Q − mix·P [-] (:func:`whitened_columns`).
    """

    def __init__(self, problem, polys: tuple[np.ndarray, np.ndarray], mix: float = 0.0) -> None:
        self.pb = problem
        self.polys = polys
        self.mix = mix
        self.skip = max(len(a) for a in polys) - 1
        self.evaluations = 0

    def residuals(self, d: np.ndarray):
        """Whitened, projected residuals and Jacobians of P and Q (lists), or None when the simulation fails."""
        self.evaluations += 1
        zs = whitened_columns(self.pb, self.polys, d, self.skip, self.mix)
        if zs is None:
            return None
        es, js = [], []
        for zf in zs:
            basis, _ = np.linalg.qr(zf[:, 5:])
            zf5 = zf[:, :5]
            proj = zf5 - basis @ (basis.T @ zf5)
            es.append(proj[:, 0])
            js.append(proj[:, 1:])
        return es, js

    def cost(self, es: list[np.ndarray]) -> float:
        """The prediction-error criterion of whitened residuals."""
        return _cost(es)

    def weights(self, es: list[np.ndarray]) -> list[float]:
        """Per-channel weights of the normal equations: l/‖e_c‖² (IRLS for one unknown variance per channel)."""
        l = es[0].size
        return [l / max(float(e @ e), 1e-300) for e in es]


def whitened_columns(pb, polys: tuple[np.ndarray, np.ndarray], d: np.ndarray, skip: int,
                     mix: float = 0.0) -> list[np.ndarray] | None:
    """Per channel, the AR-filtered columns [residual, ∂residual/∂D (4), static basis] over the regression samples.

    Parameters
    ----------
    pb : aslm_core.problem.Problem
    polys : tuple of ndarray
        A(q) of P and of Q.
    d : ndarray
        D = [a, b, H2, Tm].
    skip : int
        Leading filtered samples dropped (the filter's start-up).
    mix : float
        The second channel is Q − mix·P (model and measurement alike) [-]: with mix the own fluctuation's ΔQ/ΔP
        it carries none of it (:func:`coupling`).  Its static part stays in the span of the same regressors.

    Returns
    -------
    list of two (l − skip, 5 + n_basis) arrays [pu], or None when the simulation fails.
    """
    ok = motor.simulate_kernel(pb.vd, pb.vq, pb.vdm, pb.vqm, np.asarray(d, dtype=np.float64), pb.dt, pb.omega0,
                               pb.rk4, True, pb._p, pb._q, pb._dp, pb._dq, pb._x, True, pb.k0, pb.p_meas,
                               pb.q_meas, pb._dp)
    if not ok:
        return None
    zs = []
    for c in range(2):
        meas = pb.p_meas if c == 0 else pb.q_meas
        model, grad = (pb._p, pb._dp) if c == 0 else (pb._q, pb._dq)
        zs.append(np.column_stack([meas - model[pb.k0:], -grad[pb.k0:], pb.basis]))
    if mix:
        zs[1][:, :5] -= mix * zs[0][:, :5]  # residual and gradient only: the static basis is both channels'
    return [signal.lfilter(a, [1.0], z, axis=0)[skip:] for a, z in zip(polys, zs, strict=True)]


def coupling(rp: np.ndarray, rq: np.ndarray) -> float:
    """ΔQ/ΔP of what P and Q share in their residuals (least squares of rq on rp) [-].

    The load's own fluctuation moves P and Q together (small loads switching at their power factors); with the
    second channel taken as Q − k·P it leaves that channel, whose disturbance is then the white floor, free of
    the loop through the network.  Without own fluctuation the residuals are independent floors and k ≈ 0.
    """
    den = float(rp @ rp)
    return float(rp @ rq) / den if den > 0.0 else 0.0


def _cost(es: list[np.ndarray]) -> float:
    """Gaussian likelihood with one unknown variance per channel (the prediction-error criterion)."""
    l = es[0].size
    return 0.5 * l * sum(math.log(float(e @ e) + 1e-300) for e in es)


def fit(problem, d0: np.ndarray, max_iter: int = 40, xtol: float = 1e-7, margin: float = 1e-3,
        reestimate: int = 2, max_order: int = AR_MAX_ORDER, couple: bool = False) -> dict:
    """Prediction-error fit of D from an output-error optimum d0, the AR noise models re-estimated at the end.

    The AR polynomials come from the output-error residuals at the current D; the fit then minimises the
    whitened criterion; this repeats ``reestimate`` times.

    Returns
    -------
    dict with d, cost, iterations, evaluations, status (as
    :func:`aslm_core.identify.levenberg_marquardt`), ``polys`` (the last A(q) of P and Q), ``cov``
    (4×4 covariance of D from the whitened Jacobian, inverse Fisher information) and ``resid`` (the
    whitened residuals of P and Q).
    """
    return passes(problem, d0, lambda pb, polys, d, mix: Whitened(pb, polys, mix), max_iter=max_iter, xtol=xtol,
                  margin=margin, reestimate=reestimate, max_order=max_order, couple=couple)


def passes(problem, d0: np.ndarray, make, *, max_iter: int, xtol: float, margin: float, reestimate: int,
           max_order: int, finish=None, couple: bool = False, whitening: str = "residual") -> dict:
    """``reestimate`` passes of: AR models from the output-error residual at D, then a fit of D with them.

    ``make(problem, polys, d, mix)`` builds the pass's criterion (as :class:`Whitened`; None: stop); with
    ``couple`` its second channel is Q − mix·P, mix from the pass's residuals (:func:`coupling`), else mix = 0;
    ``finish(criterion, state)`` may add entries to the pass's result; ``whitening`` names the AR models' fit
    (:data:`WHITENERS`).  Returns the last pass's result (as
    :func:`fit`) with the iterations and evaluations of all passes.
    """
    d = problem.into_feasible(d0)
    total_it = 0
    evals = 0
    state: dict = {}
    for _ in range(max(reestimate, 1)):
        r = problem.residuals(d, jacobian=False)
        evals += 1
        if r is None:
            break
        mix = coupling(r[0], r[1]) if couple else 0.0
        fit_ar = whitener(whitening)
        polys = (fit_ar(r[0], max_order), fit_ar(r[1] - mix * r[0], max_order))
        wp = make(problem, polys, d, mix)
        if wp is None:
            break
        state = constrained_lm(wp, d, max_iter, xtol, margin)
        total_it += state["iterations"]
        evals += wp.evaluations
        d = state["d"]
        state["polys"] = polys
        state["mix"] = mix
        if finish is not None:
            finish(wp, state)
    if not state:
        return {"d": d, "cost": math.inf, "iterations": 0, "evaluations": evals, "status": "failed"}
    state["iterations"], state["evaluations"] = total_it, evals
    return state


def constrained_lm(wp, d0: np.ndarray, max_iter: int, xtol: float, margin: float) -> dict:
    """Constrained Levenberg–Marquardt on a weighted least-squares criterion (the kernel's QP step).

    ``wp`` gives ``residuals(d)`` → (residuals, Jacobians) per channel or None, ``cost(residuals)`` and
    ``weights(residuals)`` (per channel, for the normal equations and the final Fisher information).
    Returns d, cost, iterations, status, ``cov`` (the inverse of Σ_c w_c·J_cᵀJ_c) and ``resid``.
    """
    pb = wp.pb
    lower, upper, vmin = pb.lower, pb.upper, pb.v_min
    d = d0.copy()
    out = wp.residuals(d)
    if out is None:
        return {"d": d, "cost": math.inf, "iterations": 0, "status": "failed", "cov": np.full((4, 4), np.inf),
                "resid": None}
    es, js = out
    cost = wp.cost(es)
    lam = 1e-3
    step = np.empty(4)
    work, vec, ivec = np.empty((4, 4)), np.empty((3, 4)), np.empty((3, 4), dtype=np.int64)
    status = "max_iter"
    it = 0
    while it < max_iter:
        it += 1
        g, A = normal_equations(wp, es, js)
        gc = np.array([vmin * vmin * (1.0 - margin), -2.0 * d[3], 0.0, -2.0 * d[1]])
        c_d = gc[0] * d[0] - 2.0 * d[1] * d[3]
        accepted = False
        for _ in range(12):
            M = A + lam * np.diag(np.maximum(np.diag(A), 1e-12 * A.diagonal().max()))
            if not optimize.qp_step(M, g, d, lower, upper, gc, c_d, step, work, vec, ivec):
                lam *= 4.0
                continue
            trial = np.minimum(np.maximum(d + step, lower), upper)
            if not pb.feasible(trial):
                tm_max = (1.0 - margin) * trial[0] * vmin * vmin / (2.0 * trial[1]) * (1.0 - 1e-9)
                trial[3] = max(min(trial[3], tm_max), lower[3])
                if not pb.feasible(trial):
                    lam *= 4.0
                    continue
            out = wp.residuals(trial)
            if out is not None and wp.cost(out[0]) < cost:
                moved = float(np.max(np.abs(trial - d) / (np.abs(d) + 1e-3)))
                d, (es, js), cost = trial, out, wp.cost(out[0])
                lam = max(lam / 3.0, 1e-9)
                accepted = True
                break
            lam *= 4.0
        if not accepted:
            status = "converged" if it > 1 else "stalled"
            break
        if moved < xtol:
            status = "converged"
            break
    fisher = sum(wc * (j.T @ j) for wc, j in zip(wp.weights(es), js, strict=True))
    try:
        cov = np.linalg.inv(fisher)
    except np.linalg.LinAlgError:
        cov = np.full((4, 4), np.inf)
    return {"d": d, "cost": cost, "iterations": it, "status": status, "cov": cov, "resid": es}


def normal_equations(wp, es: list, js: list) -> tuple[np.ndarray, np.ndarray]:
    """Gradient of ``wp``'s criterion in D and its Gauss–Newton matrix: Σ_c w_c·J_cᵀe_c and Σ_c w_c·J_cᵀJ_c, or
    the criterion's own ``normal_equations`` where it is not a weighted sum of squares."""
    own = getattr(wp, "normal_equations", None)
    if own is not None:
        return own(es, js)
    return weighted_normal_equations(wp.weights(es), es, js)


def weighted_normal_equations(w: list[float], es: list, js: list) -> tuple[np.ndarray, np.ndarray]:
    """Σ_c w_c·J_cᵀe_c and Σ_c w_c·J_cᵀJ_c: the gradient and Gauss–Newton matrix of ½ Σ_c w_c·‖e_c‖²."""
    return (sum(wc * (j.T @ e) for wc, j, e in zip(w, js, es, strict=True)),
            sum(wc * (j.T @ j) for wc, j in zip(w, js, strict=True)))


def standard_errors(cov: np.ndarray) -> dict[str, float]:
    """Standard errors of D from its covariance, by name."""
    return {k: float(math.sqrt(max(v, 0.0))) for k, v in zip(DYNAMIC_NAMES, np.diag(cov), strict=True)}
