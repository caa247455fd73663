"""Reference implementations for the Table III comparison: the paper's method as published, and ref. [11].

(i) :func:`faithful_identify` — the paper's hierarchical method implemented the straightforward way:
    OF(D) of eq. 7 from a plain-Python, per-sample explicit-Euler integration of eq. 4 (steady state at the
    first sample, eq. 5 outputs), ZIP regression by ``np.linalg.lstsq`` over the samples after a 1 s skip,
    minimised by scipy's SLSQP with finite-difference gradients under the paper's bounds and the
    equilibrium constraint a·Vmin² − 2b·Tm > 0; 3 restarts from random feasible points, best OF wins.
    Nothing is compiled or vectorised in the integration.

(i') :func:`compiled_identify` — the same algorithm as a competent engineer would write it for speed: the
    same Euler integration and eq. 7 compiled with numba (one pass per evaluation, no allocation), the ZIP
    regression by projection on the regressors' QR basis factored once per window (Φ = [1, V, V²] does
    not depend on D, so this is the same least-squares residual), the forward-difference gradient of
    SLSQP's default (absolute step √eps in the unit box, reversed at the upper bound) computed in one
    compiled call from the objective value SLSQP already has, and the constraint's exact gradient.  The
    same SLSQP settings, scaling and starts as (i), hence the same optima.

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

import numba as nb
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

    def slsqp_jacobians(self, lo: np.ndarray, span: np.ndarray, f_scale: float):
        """Gradients SLSQP is given in the unit box: (objective, constraint); None = scipy's finite differences."""
        return None, None

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

    jac, cons_jac = problem.slsqp_jacobians(lo, span, f_scale)
    constraint = {"type": "ineq", "fun": cons} if cons_jac is None else {"type": "ineq", "fun": cons, "jac": cons_jac}
    evals0 = problem.evaluations
    res = optimize.minimize(
        fun, (d0 - lo) / span, jac=jac, method="SLSQP", bounds=[(0.0, 1.0)] * 4,
        constraints=[constraint], options={"ftol": ftol, "maxiter": maxiter},
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
    return _restarts(PaperProblem, window, starts, n_starts, seed, finite_starts, ftol)


def _restarts(problem_cls: type[PaperProblem], window: Window, starts, n_starts: int, seed: int,
              finite_starts: bool, ftol: float) -> BaselineResult:
    """SLSQP from each start on ``problem_cls``'s OF; the best OF wins (timed from the raw window on)."""
    t0 = time.perf_counter()
    problem = problem_cls.from_window(window)
    if starts is None:
        rng = np.random.default_rng(seed)
        starts = [problem.random_start(rng, finite=finite_starts) for _ in range(n_starts)]
    runs = [slsqp_from(problem, s, ftol=ftol) for s in starts]
    best = min(runs, key=lambda r: r["of"])
    of, static = problem.of_and_static(best["d"])
    return BaselineResult(d=best["d"], of=of, static=static, runs=runs, elapsed_s=time.perf_counter() - t0,
                          evaluations=problem.evaluations, starts=[np.asarray(s, dtype=float) for s in starts])


# --------------------------------------------------------------------------------------------
# (i') compiled baseline: the same algorithm, OF and its finite differences compiled with numba
# --------------------------------------------------------------------------------------------

#: SLSQP's default finite-difference step (absolute, in the unit box).
FD_STEP = math.sqrt(np.finfo(np.float64).eps)


# The same numba options as aslm_core's integrators: neither side is compiled with an advantage.
_JIT = {"cache": True, "nogil": True, "error_model": "numpy", "fastmath": {"contract"}}


@nb.njit(**_JIT)
def _projected_norm(y: np.ndarray, basis: np.ndarray) -> float:
    """‖y − Q1·Q1ᵀy‖: the residual norm of the least-squares fit of y on [1, V, V²] (Q1ᵀ = ``basis``, 3 × l)."""
    c0 = c1 = c2 = 0.0
    for i in range(y.size):
        c0 += basis[0, i] * y[i]
        c1 += basis[1, i] * y[i]
        c2 += basis[2, i] * y[i]
    ss = 0.0
    for i in range(y.size):
        r = y[i] - basis[0, i] * c0 - basis[1, i] * c1 - basis[2, i] * c2
        ss += r * r
    return math.sqrt(ss)


@nb.njit(**_JIT)
def euler_of(ds: np.ndarray, vd: np.ndarray, vq: np.ndarray, p_meas: np.ndarray, q_meas: np.ndarray,
             basis: np.ndarray, dt: float, w0: float, k0: int, yp: np.ndarray, yq: np.ndarray,
             out: np.ndarray) -> None:
    """OF of eq. 7 for each row D of ``ds`` by explicit Euler at the sample step: the compiled :func:`euler_py`.

    ``p_meas``, ``q_meas``: P, Q [pu] from sample k0 on; ``basis``:
    orthonormal basis of [1, V, V²] there, transposed (3 × (n − k0)); ``dt`` [s], ``w0`` [rad/s].  Rows of
    ``yp``, ``yq`` (at least len(ds) by n − k0) receive P − P_im, Q − Q_im per motor.  ``out`` receives OF, inf where there is no equilibrium
    at the first sample or the trajectory blows up (as :func:`euler_py`).
    """
    vd0, vq0 = vd[0], vq[0]
    v2 = vd0 * vd0 + vq0 * vq0
    for j in range(ds.shape[0]):
        a, b, tm = ds[j, 0], ds[j, 1], ds[j, 3]
        ih2 = 1.0 / ds[j, 2]
        disc = a * a * v2 * v2 - 4.0 * tm * tm * b * b
        if disc < 0.0 or a * v2 <= 0.0:
            out[j] = math.inf
            continue
        c = 2.0 * tm * b * b / (a * v2 + math.sqrt(disc))
        k = a / (b * b + c * c)
        fd = k * (b * vd0 + c * vq0)
        fq = k * (-c * vd0 + b * vq0)
        s = c / w0
        for i in range(vd.size):
            ud = vd[i]
            uq = vq[i]
            if i >= k0:
                yp[j, i - k0] = p_meas[i - k0] - (fd * uq - fq * ud)
                yq[j, i - k0] = q_meas[i - k0] - (-ud * fd - uq * fq)
            ws = w0 * s
            dfd = -b * fd + ws * fq + a * ud
            dfq = -b * fq - ws * fd + a * uq
            ds_ = (tm - (uq * fd - ud * fq)) * ih2
            fd += dt * dfd
            fq += dt * dfq
            s += dt * ds_
        if not (math.isfinite(fd) and math.isfinite(fq) and math.isfinite(s)) or abs(fd) > 1e12:
            out[j] = math.inf
        else:
            out[j] = (_projected_norm(yp[j], basis) + _projected_norm(yq[j], basis)) / yp.shape[1]


@nb.njit(**_JIT)
def fd_gradient(x: np.ndarray, fx: float, lo: np.ndarray, span: np.ndarray, f_scale: float, vd: np.ndarray,
                vq: np.ndarray, p_meas: np.ndarray, q_meas: np.ndarray, basis: np.ndarray, dt: float, w0: float,
                k0: int, yp: np.ndarray, yq: np.ndarray) -> np.ndarray:
    """Forward differences of OF(lo + span·x)/f_scale (1e6 where OF is infinite) at x in the unit box.

    The scheme of scipy's SLSQP without a gradient: step ``FD_STEP``, backwards where x + step leaves
    the box, divided by the step as represented ((x + h) − x); ``fx`` is the value at x.  The four
    perturbed motors are integrated in one :func:`euler_of` pass.
    """
    ds = np.empty((4, 4))
    steps = np.empty(4)
    for j in range(4):
        h = FD_STEP
        if x[j] + h > 1.0:
            h = -h
        xj = x[j] + h
        steps[j] = xj - x[j]
        for c in range(4):
            ds[j, c] = lo[c] + span[c] * x[c]
        ds[j, j] = lo[j] + span[j] * xj
    of = np.empty(4)
    euler_of(ds, vd, vq, p_meas, q_meas, basis, dt, w0, k0, yp, yq, of)
    g = np.empty(4)
    for j in range(4):
        f = of[j] / f_scale if math.isfinite(of[j]) else 1e6
        g[j] = (f - fx) / steps[j]
    return g


@dataclass
class CompiledPaperProblem(PaperProblem):
    """The paper's problem with OF and its finite differences compiled (:func:`euler_of`, :func:`fd_gradient`)."""

    # vd, vq, P and Q from k0 on, Q1ᵀ, dt, ω0, k0, and rows for P − P_im, Q − Q_im: euler_of's data arguments
    kernel_args: tuple = field(default=(), repr=False)
    _last: tuple = field(default=(b"", math.inf), repr=False)  # (D as bytes, OF) of the last evaluation
    _out: np.ndarray = field(default_factory=lambda: np.empty(1), repr=False)

    @classmethod
    def from_window(cls, window: Window, skip_s: float = SKIP_S) -> CompiledPaperProblem:
        plain = PaperProblem.from_window(window, skip_s)
        problem = cls(**{f: getattr(plain, f) for f in plain.__dataclass_fields__})
        k0 = plain.k0
        problem.kernel_args = (
            np.asarray(plain.vd, dtype=np.float64), np.asarray(plain.vq, dtype=np.float64),
            np.ascontiguousarray(plain.P[k0:]), np.ascontiguousarray(plain.Q[k0:]),
            np.ascontiguousarray(np.linalg.qr(plain.regressors)[0].T), plain.dt, plain.w0, k0,
            np.empty((4, plain.l)), np.empty((4, plain.l)),
        )
        return problem

    def of(self, d) -> float:
        """OF(D), eq. 7, compiled; the last point and value are kept for the gradient that follows."""
        self.evaluations += 1
        d = np.asarray(d, dtype=np.float64)
        euler_of(d.reshape(1, 4), *self.kernel_args, self._out)
        f = float(self._out[0])
        self._last = (d.tobytes(), f)
        return f

    def of_and_static(self, d):
        of = self.of(d)
        if not math.isfinite(of):
            return math.inf, None
        yp, yq = self.kernel_args[-2:]
        bp = np.linalg.lstsq(self.regressors, yp[0], rcond=None)[0]
        bq = np.linalg.lstsq(self.regressors, yq[0], rcond=None)[0]
        static = {"Pp": bp[0], "Pi": bp[1], "Pz": bp[2], "Qp": bq[0], "Qi": bq[1], "Qz": bq[2]}
        return of, {k: float(v) for k, v in static.items()}

    def slsqp_jacobians(self, lo: np.ndarray, span: np.ndarray, f_scale: float):
        vmin2 = self.v_min**2

        def jac(x):
            d = lo + span * x
            key, f = self._last
            if d.tobytes() != key:  # SLSQP asks for the gradient where it has just evaluated OF
                f = self.of(d)
            fx = f / f_scale if math.isfinite(f) else 1e6
            self.evaluations += 4
            return fd_gradient(np.asarray(x, dtype=np.float64), fx, lo, span, f_scale, *self.kernel_args)

        def cons_jac(x):
            d = lo + span * x
            return np.array([(1.0 - EQUILIBRIUM_MARGIN) * vmin2 * span[0], -2.0 * d[3] * span[1], 0.0,
                             -2.0 * d[1] * span[3]])

        return jac, cons_jac


class CompiledOFProblem(CompiledPaperProblem):
    """Only OF compiled; SLSQP differences it itself (scipy's default): the variant (i') improves on."""

    def slsqp_jacobians(self, lo: np.ndarray, span: np.ndarray, f_scale: float):
        return None, None


def compiled_identify(window: Window, *, starts=None, n_starts: int = 3, seed: int = 0,
                      finite_starts: bool = True, ftol: float = SLSQP_FTOL,
                      scipy_gradients: bool = False) -> BaselineResult:
    """The paper's method compiled (:class:`CompiledPaperProblem`); otherwise as :func:`faithful_identify`.

    ``scipy_gradients``: let SLSQP difference the compiled OF itself (:class:`CompiledOFProblem`).
    """
    cls = CompiledOFProblem if scipy_gradients else CompiledPaperProblem
    return _restarts(cls, window, starts, n_starts, seed, finite_starts, ftol)


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
