"""Reference implementations for the Table III comparison: the paper's method as published, and ref. [11].

(i) :func:`faithful_identify` — the paper's hierarchical method implemented the straightforward way:
    OF(D) of eq. 7 from a plain-Python, per-sample explicit-Euler integration of eq. 4 (steady state at the
    first sample, eq. 5 outputs), ZIP regression by ``np.linalg.lstsq`` over the samples after a 1 s skip,
    minimised by scipy's SLSQP with finite-difference gradients under the paper's bounds and the
    equilibrium constraint a·Vmin² − 2b·Tm > 0; 3 restarts from random feasible points, best OF wins.
    Nothing is compiled or vectorised in the integration.

(ii) :func:`de_identify` — the previous heuristic ASLM approach of the paper's ref. [11]: differential
    evolution (scipy) over Z + IM, i.e. D plus constant-impedance coefficients (P_st = Gz·V²,
    Q_st = Bz·V²), same objective form (‖r_p‖ + ‖r_q‖)/l and the same plain-Python Euler integration.

Implementation choices that do not change the optimum (stated in docs/reproduction.md):
SLSQP works on D scaled to the unit box and on OF divided by OF at the start (SLSQP's ftol is absolute,
and OF ~ 1e-4 would otherwise stop it at once); the equilibrium constraint keeps the same relative margin
(1e-3 of a·Vmin²) as ``aslm_core.identify`` so both methods search the same set.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from aslm_core import motor
from aslm_core.identify import EQUILIBRIUM_MARGIN
from aslm_core.params import dynamic_bounds
from aslm_core.preprocess import prepare
from aslm_core.window import Window

SKIP_S = 1.0
#: SLSQP's tolerance on the (normalised) objective; tight so the same-optimum check is meaningful.
SLSQP_FTOL = 1e-12
SLSQP_MAXITER = 200


# --------------------------------------------------------------------------------------------
# Plain-Python model (no numba, no vectorised integration)
# --------------------------------------------------------------------------------------------


def steady_state_py(vd0: float, vq0: float, d, w0: float):
    """Low-slip equilibrium (Fd, Fq, s) of eq. 4 at the first sample; None if none exists."""
    a, b, _, tm = (float(x) for x in d)
    v2 = vd0 * vd0 + vq0 * vq0
    disc = a * a * v2 * v2 - 4.0 * tm * tm * b * b
    if disc < 0.0 or a * v2 <= 0.0:
        return None
    c = 2.0 * tm * b * b / (a * v2 + math.sqrt(disc))  # c = s·ω0, the smaller root
    k = a / (b * b + c * c)
    return k * (b * vd0 + c * vq0), k * (-c * vd0 + b * vq0), c / w0


def euler_py(vd: list, vq: list, d, dt: float, w0: float):
    """Explicit Euler of eq. 4 at the sample step, one Python iteration per sample; eq. 5 outputs.

    Returns (P_im, Q_im) as lists, or None when no equilibrium exists or the trajectory blows up.
    """
    a, b, h2, tm = (float(x) for x in d)
    x0 = steady_state_py(vd[0], vq[0], d, w0)
    if x0 is None:
        return None
    fd, fq, s = x0
    n = len(vd)
    p = [0.0] * n
    q = [0.0] * n
    for k in range(n):
        ud = vd[k]
        uq = vq[k]
        p[k] = fd * uq - fq * ud
        q[k] = -ud * fd - uq * fq
        ws = w0 * s
        dfd = -b * fd + ws * fq + a * ud
        dfq = -b * fq - ws * fd + a * uq
        ds = (tm - (uq * fd - ud * fq)) / h2
        fd += dt * dfd
        fq += dt * dfq
        s += dt * ds
    if not (math.isfinite(fd) and math.isfinite(fq) and math.isfinite(s)) or abs(fd) > 1e12:
        return None
    return p, q


@dataclass
class PaperProblem:
    """Measured data of one window, as the paper's method sees it."""

    V: np.ndarray
    vd: list
    vq: list
    P: np.ndarray
    Q: np.ndarray
    dt: float
    w0: float
    k0: int
    lower: np.ndarray
    upper: np.ndarray
    v_min: float
    regressors: np.ndarray = field(repr=False)
    evaluations: int = 0

    @classmethod
    def from_window(cls, window: Window, skip_s: float = SKIP_S) -> PaperProblem:
        prep = prepare(window)  # uniform grid, θ unwrapped; no filter
        V, th = prep.V, prep.theta
        n = V.shape[0]
        k0 = min(int(math.ceil(skip_s / prep.dt - 1e-9)), n - 10)
        lower, upper = dynamic_bounds(float(prep.P.mean()))
        vr = V[k0:]
        return cls(
            V=V, vd=(V * np.cos(th)).tolist(), vq=(V * np.sin(th)).tolist(), P=prep.P, Q=prep.Q, dt=prep.dt,
            w0=motor.omega0_of(window.f0), k0=k0, lower=lower, upper=upper, v_min=float(V.min()),
            regressors=np.column_stack([np.ones_like(vr), vr, vr * vr]),
        )

    @property
    def l(self) -> int:  # noqa: E743 - the paper's data length
        return self.V.shape[0] - self.k0

    def feasible(self, d) -> bool:
        d = np.asarray(d, dtype=float)
        if np.any(d < self.lower) or np.any(d > self.upper):
            return False
        av = d[0] * self.v_min**2
        return av - 2.0 * d[1] * d[3] > EQUILIBRIUM_MARGIN * av

    def of(self, d) -> float:
        """OF(D), eq. 7: (‖r_p‖ + ‖r_q‖)/l of the ZIP regressions of P − P_im and Q − Q_im (inf if no solution)."""
        out = self.of_and_static(d)
        return out[0]

    def of_and_static(self, d):
        self.evaluations += 1
        sim = euler_py(self.vd, self.vq, d, self.dt, self.w0)
        if sim is None:
            return math.inf, None
        p_im, q_im = sim
        k0 = self.k0
        yp = self.P[k0:] - np.asarray(p_im[k0:])
        yq = self.Q[k0:] - np.asarray(q_im[k0:])
        phi = self.regressors
        bp = np.linalg.lstsq(phi, yp, rcond=None)[0]
        bq = np.linalg.lstsq(phi, yq, rcond=None)[0]
        rp = yp - phi @ bp
        rq = yq - phi @ bq
        of = (math.sqrt(float(rp @ rp)) + math.sqrt(float(rq @ rq))) / self.l
        static = {"Pp": bp[0], "Pi": bp[1], "Pz": bp[2], "Qp": bq[0], "Qi": bq[1], "Qz": bq[2]}
        return of, {k: float(v) for k, v in static.items()}

    def random_start(self, rng: np.random.Generator, finite: bool = False) -> np.ndarray:
        """Uniform in the box of a, b, H2, then Tm uniform below the equilibrium limit (as aslm_core).

        With ``finite``, redraw until OF is finite there (explicit Euler at 10 ms diverges in part of the
        box; an SQP such as MATLAB's fmincon refuses a start where the objective is undefined).
        """
        lo, hi = self.lower, self.upper
        while True:
            d = lo + (hi - lo) * rng.random(4)
            tm_max = min(hi[3], (1.0 - 2 * EQUILIBRIUM_MARGIN) * d[0] * self.v_min**2 / (2.0 * d[1]))
            d[3] = lo[3] + (tm_max - lo[3]) * rng.random()
            if self.feasible(d) and (not finite or math.isfinite(self.of(d))):
                return d


# --------------------------------------------------------------------------------------------
# (i) faithful baseline: SLSQP, finite differences, 3 restarts
# --------------------------------------------------------------------------------------------


def slsqp_from(problem: PaperProblem, d0, *, ftol: float = SLSQP_FTOL, maxiter: int = SLSQP_MAXITER) -> dict:
    """One SLSQP run (finite-difference gradients) from d0; D is scaled to the unit box internally."""
    lo, hi = problem.lower, problem.upper
    span = np.where(hi > lo, hi - lo, 1.0)
    d0 = np.clip(np.asarray(d0, dtype=float), lo, hi)
    f_scale = problem.of(d0)
    if not math.isfinite(f_scale) or f_scale <= 0:
        f_scale = 1.0
    vmin2 = problem.v_min**2

    def fun(x):
        f = problem.of(lo + span * x)
        return f / f_scale if math.isfinite(f) else 1e6

    def cons(x):
        d = lo + span * x
        return (1.0 - EQUILIBRIUM_MARGIN) * d[0] * vmin2 - 2.0 * d[1] * d[3]

    evals0 = problem.evaluations
    res = optimize.minimize(
        fun, (d0 - lo) / span, method="SLSQP", bounds=[(0.0, 1.0)] * 4,
        constraints=[{"type": "ineq", "fun": cons}], options={"ftol": ftol, "maxiter": maxiter},
    )
    d = lo + span * np.clip(res.x, 0.0, 1.0)
    return {"d": d, "of": problem.of(d), "iterations": int(res.nit), "evaluations": problem.evaluations - evals0,
            "success": bool(res.success), "message": str(res.message)}


@dataclass
class BaselineResult:
    d: np.ndarray
    of: float
    static: dict
    runs: list
    elapsed_s: float
    evaluations: int
    starts: list = field(default_factory=list)


def faithful_identify(window: Window, *, starts=None, n_starts: int = 3, seed: int = 0,
                      finite_starts: bool = True, ftol: float = SLSQP_FTOL) -> BaselineResult:
    """The paper's method, implemented plainly: 3 SLSQP restarts (or the given starts), best OF wins.

    Random starts (when ``starts`` is None) are redrawn until OF is finite there if ``finite_starts``;
    drawing them is part of the timed work.
    """
    t0 = time.perf_counter()
    problem = PaperProblem.from_window(window)
    if starts is None:
        rng = np.random.default_rng(seed)
        starts = [problem.random_start(rng, finite=finite_starts) for _ in range(n_starts)]
    runs = [slsqp_from(problem, s, ftol=ftol) for s in starts]
    best = min(runs, key=lambda r: r["of"])
    of, static = problem.of_and_static(best["d"])
    return BaselineResult(d=best["d"], of=of, static=static, runs=runs, elapsed_s=time.perf_counter() - t0,
                          evaluations=problem.evaluations, starts=[np.asarray(s, dtype=float) for s in starts])


# --------------------------------------------------------------------------------------------
# (ii) previous heuristic approach (ref. [11]): differential evolution over Z + IM
# --------------------------------------------------------------------------------------------


def de_objective(problem: PaperProblem, x) -> float:
    """(‖r_p‖ + ‖r_q‖)/l with the static part fixed to constant impedance: P_st = Gz·V², Q_st = Bz·V²."""
    d = x[:4]
    if not problem.feasible(d):
        return 1e3
    problem.evaluations += 1
    sim = euler_py(problem.vd, problem.vq, d, problem.dt, problem.w0)
    if sim is None:
        return 1e3
    p_im, q_im = sim
    k0 = problem.k0
    v2 = problem.V[k0:] ** 2
    rp = problem.P[k0:] - np.asarray(p_im[k0:]) - x[4] * v2
    rq = problem.Q[k0:] - np.asarray(q_im[k0:]) - x[5] * v2
    return (math.sqrt(float(rp @ rp)) + math.sqrt(float(rq @ rq))) / problem.l


def de_bounds(problem: PaperProblem) -> list[tuple[float, float]]:
    """D's box, Gz ∈ [0, mean P], Bz ∈ [mean Q − 5, mean Q + 30] (Bz absorbs −Q_im ≈ a/b·V², up to ~27 pu)."""
    qm = float(problem.Q.mean())
    pm = float(problem.P.mean())
    return [*zip(problem.lower, problem.upper, strict=True), (0.0, max(pm, 1e-6)), (qm - 5.0, qm + 30.0)]


def de_identify(window: Window, *, seed: int = 0, maxiter: int = 100, popsize: int = 15,
                tol: float = 1e-3) -> BaselineResult:
    """Differential evolution (scipy, no gradient polish) over [a, b, H2, Tm, Gz, Bz]."""
    t0 = time.perf_counter()
    problem = PaperProblem.from_window(window)
    res = optimize.differential_evolution(
        lambda x: de_objective(problem, x), de_bounds(problem), seed=seed, maxiter=maxiter, popsize=popsize,
        tol=tol, polish=False, updating="immediate",
    )
    return BaselineResult(d=np.asarray(res.x[:4]), of=float(res.fun), static={"Gz": float(res.x[4]),
                          "Bz": float(res.x[5])}, runs=[{"nit": int(res.nit), "message": str(res.message)}],
                          elapsed_s=time.perf_counter() - t0, evaluations=problem.evaluations)
