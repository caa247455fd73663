"""The joint likelihood over latent V and θ in the time domain, by a Kalman filter (issue 11, stop 52; a candidate).

Issue 11 lists "joint likelihood over latent V and θ" among the estimators to compare. Stop 46 built it in the
frequency domain and it failed: a finite window's DFT carries the response to inputs before the window, which that
model has no term for. In the time domain a state-space model holds that response in its initial state, so the
transient needs no term of its own. This benchmark builds that form and screens it against the default on the
supplement's windows whose structural bounds ``input_noise_bound_n300.json`` holds (seed 43, the first ``--n``, the same
noise draws as every other seed-43 benchmark).

The model, per window (deviations from the window's operating point):

* latent inputs x_k = [ΔV_k, Δθ_k] (V about its mean, θ about its least-squares line), a VAR(p) process
  x_k = Σ A_i·x_{k−i} + w_k, w ~ N(0, Σ_w);
* the third-order motor (paper eq. 4–5) linearised about its steady state in the frame that turns with θ's line,
  inputs held first-order between samples (the exact discretisation of that hold);
* y_k = [V, θ, P, Q] deviations = [ΔV, Δθ, c_P·ΔV + ΔP_im, c_Q·ΔV + ΔQ_im] + white noise (variances r).

The likelihood is the Kalman filter's prediction-error decomposition over the samples after ``skip_s`` (the
identifier's skipped first second), from a wide prior on the initial state. The fit alternates EM for the VAR, Σ_w and
the four noise variances at the current D, accelerated by SQUAREM, with L-BFGS-B on D, c_P and c_Q at the current
nuisance, from the default's D and the Yule–Walker VAR with the measured floor taken off the lag-0 covariance. It is
not adopted (docs/numerics.md, "Stop 52: the joint likelihood over latent V and θ in the time domain").

    .venv/bin/python -m benchmarks.input_noise_kalman [--n 100] [--order 12] [--cycles-first 40] [--cycles 15]
        [--rounds 4] [--cells "3|0.1 % / 1e-3 rad"]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numba as nb  # noqa: E402
import numpy as np  # noqa: E402
from scipy import linalg, optimize  # noqa: E402

from aslm_core import IdentifyConfig, motor  # noqa: E402
from aslm_core.noise import channel_floors  # noqa: E402
from aslm_core.params import dynamic_bounds  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks.input_noise import CONFIRM_SEED, identified_draws, noisy_draws  # noqa: E402

LEVELS = (1, 2, 3)
DEFAULT = IdentifyConfig()


def linear_motor(d: np.ndarray, v0: float, w_off: float, omega0: float):
    """The motor (paper eq. 4–5) linearised about its steady state at V0 in the frame turning at w_off [rad/s].

    Returns A (3, 3) [1/s], B (3, 2) on [ΔV, Δθ], C (2, 3) and Dm (2, 2) for [ΔP_im, ΔQ_im]; None where no steady
    state exists (a·V0² < 2·b·Tm).
    """
    a, b, h2, tm = (float(x) for x in d)
    disc = (a * v0 * v0) ** 2 - 4.0 * tm * tm * b * b
    if disc < 0.0 or h2 <= 0.0:
        return None
    # Low-slip root of Tm = a·V0²·ω_s / (b² + ω_s²), ω_s = s·ω0 + w_off.
    ws = (a * v0 * v0 - math.sqrt(disc)) / (2.0 * tm) if tm > 1e-12 else 0.0
    den = b * b + ws * ws
    fd0 = a * v0 * b / den
    fq0 = -a * v0 * ws / den
    A = np.array([[-b, ws, omega0 * fq0], [-ws, -b, -omega0 * fd0], [0.0, v0 / h2, 0.0]])
    # On (ud, uq) = (ΔV, V0·Δθ).
    Bu = np.array([[a, 0.0], [0.0, a], [fq0 / h2, -fd0 / h2]])
    C = np.array([[0.0, -v0, 0.0], [-v0, 0.0, 0.0]])
    Du = np.array([[-fq0, fd0], [-fd0, -fq0]])
    T = np.diag([1.0, v0])
    return A, Bu @ T, C, Du @ T


def first_order_hold(A: np.ndarray, B: np.ndarray, dt: float):
    """z_{k+1} = Φ·z_k + Γ0·u_k + Γ1·u_{k+1} for ż = A·z + B·u with u linear between samples."""
    n, m = B.shape
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n] = A * dt
    M[:n, n:n + m] = B * dt
    M[n:n + m, n + m:] = np.eye(m)
    E = linalg.expm(M)
    phi, g1, g2 = E[:n, :n], E[:n, n:n + m], E[:n, n + m:]
    return phi, g1 - g2, g2


def linear_response(lin: tuple, u: np.ndarray, dt: float) -> np.ndarray:
    """Output (n, 2) of the linear system ``lin`` = (A, B, C, D) (:func:`linear_motor`: [ΔP_im, ΔQ_im] [pu]) driven by
    u (n, 2) (the input deviations [ΔV pu, Δθ rad]), linear between samples, from zero state."""
    a_m, b_m, c_m, d_m = lin
    phi, g0, g1 = first_order_hold(a_m, b_m, dt)
    z = np.zeros(a_m.shape[0])
    out = np.empty((u.shape[0], c_m.shape[0]))
    for k in range(u.shape[0]):
        out[k] = c_m @ z + d_m @ u[k]
        if k + 1 < u.shape[0]:
            z = phi @ z + g0 @ u[k] + g1 @ u[k + 1]
    return out


#: The filter's gain is frozen from this sample on: the Riccati recursion has settled by then, and a fixed step keeps
#: the likelihood smooth in the parameters (a convergence test would switch it at a step that moves with them, which
#: spoils finite-difference gradients) [samples].
FREEZE_AT = 400


@nb.njit(cache=True)
def kalman_nll(F, Gq, H, r, y, k0, p0, freeze_at):  # pragma: no cover - numba
    """Negative log-likelihood (without 2π) of y (N, 4) under x_{k+1} = F·x_k + w, y_k = H·x_k + e, from x_0 ~ N(0, p0),
    summed over k ≥ k0; the gain and the innovation covariance are held from sample ``freeze_at`` on."""
    n = F.shape[0]
    N = y.shape[0]
    x = np.zeros(n)
    P = p0.copy()
    R = np.diag(r)
    nll = 0.0
    K = np.zeros((n, 4))
    Si = np.zeros((4, 4))
    logdet = 0.0
    Ft = np.ascontiguousarray(F.T)
    for k in range(N):
        if k > 0:
            x = F @ x
            if k <= freeze_at:
                P = F @ P @ Ft + Gq
        nu = y[k] - H @ x
        if k <= freeze_at:
            PH = P @ H.T
            S = H @ PH + R
            L = np.linalg.cholesky(S)
            logdet = 2.0 * np.sum(np.log(np.diag(L)))
            Si = np.linalg.inv(S)
            K = PH @ Si
            P = P - K @ PH.T
            P = 0.5 * (P + P.T)
        if k >= k0:
            nll += 0.5 * (logdet + nu @ (Si @ nu))
        x = x + K @ nu
    return nll


@nb.njit(cache=True)
def var_moments(F, Gq, H, r, y, p0, order):  # pragma: no cover - numba
    """The Kalman–RTS smoother's sums over the window for the VAR's M-step: E[x_{k+1}·x_{k+1}ᵀ], E[x_{k+1}·X_kᵀ] and
    E[X_k·X_kᵀ] (x the inputs at state indices 3:5, X the p lags at 3:3+2p), and the count."""
    n = F.shape[0]
    N = y.shape[0]
    R = np.diag(r)
    xp = np.zeros((N, n))
    Pp = np.zeros((N, n, n))
    xf = np.zeros((N, n))
    Pf = np.zeros((N, n, n))
    x = np.zeros(n)
    P = p0.copy()
    for k in range(N):
        if k > 0:
            x = F @ x
            P = F @ P @ F.T + Gq
        xp[k] = x
        Pp[k] = P
        PH = P @ H.T
        S = H @ PH + R
        K = PH @ np.linalg.inv(S)
        x = x + K @ (y[k] - H @ x)
        P = P - K @ PH.T
        P = 0.5 * (P + P.T)
        xf[k] = x
        Pf[k] = P
    m = 2 * order
    s11 = np.zeros((2, 2))
    s10 = np.zeros((2, m))
    s00 = np.zeros((m, m))
    rs = np.zeros(4)
    xs = xf[N - 1].copy()
    Ps = Pf[N - 1].copy()
    e = y[N - 1] - H @ xs
    rs += e * e + np.diag(H @ Ps @ H.T)
    for k in range(N - 2, -1, -1):
        J = Pf[k] @ F.T @ np.linalg.pinv(Pp[k + 1])
        xs_k = xf[k] + J @ (xs - xp[k + 1])
        Ps_k = Pf[k] + J @ (Ps - Pp[k + 1]) @ J.T
        C = Ps @ J.T  # Cov(s_{k+1}, s_k | all)
        a = xs[3:5]
        b = xs_k[3:3 + m]
        s11 += np.outer(a, a) + Ps[3:5, 3:5]
        s10 += np.outer(a, b) + C[3:5, 3:3 + m]
        s00 += np.outer(b, b) + Ps_k[3:3 + m, 3:3 + m]
        xs = xs_k
        Ps = 0.5 * (Ps_k + Ps_k.T)
        e = y[k] - H @ xs
        rs += e * e + np.diag(H @ Ps @ H.T)
    return s11, s10, s00, N - 1, rs / N


class JointModel:
    """One window's joint model: the data, the operating point and the parameter vector's layout."""

    def __init__(self, V, theta, P, Q, dt: float, f0: float, order: int, skip_s: float):
        n = V.size
        t = np.arange(n) * dt
        self.dt, self.p, self.omega0 = dt, order, motor.omega0_of(f0)
        self.v0 = float(V.mean())
        slope, icpt = np.polyfit(t, theta, 1)
        self.w_off = float(slope)
        self.y = np.ascontiguousarray(np.stack([V - self.v0, theta - (slope * t + icpt), P - P.mean(),
                                                Q - Q.mean()], axis=1))
        self.k0 = int(math.ceil(skip_s / dt - 1e-9))
        fl = channel_floors(V, theta, P, Q, 1.0 / dt)
        self.r0 = np.array([fl["noise_v"], fl["noise_theta"], fl["noise_p"], fl["noise_q"]]) ** 2
        self.ns = 3 + 2 * order
        self.prior = self.p0()

    def var_start(self) -> tuple[np.ndarray, np.ndarray]:
        """VAR(p) coefficients (p, 2, 2) and innovation covariance from the Yule–Walker equations with the inputs'
        measured floor taken off the lag-0 covariance."""
        x = self.y[:, :2] - self.y[:, :2].mean(axis=0)
        n, p = x.shape[0], self.p
        g = [x[k:].T @ x[:n - k] / n for k in range(p + 1)]  # g[k] = E[x_{t+k} x_tᵀ]
        g0 = g[0] - np.diag(self.r0[:2])
        if np.any(np.linalg.eigvalsh(g0) <= 0):
            g0 = g[0].copy()
        gl = lambda k: g0 if k == 0 else (g[k] if k > 0 else g[-k].T)  # noqa: E731
        big = np.block([[gl(j - i) for j in range(p)] for i in range(p)])
        rhs = np.hstack([gl(i + 1) for i in range(p)])
        coef = np.linalg.solve(big.T, rhs.T).T  # [A1 … Ap], (2, 2p)
        sw = g0 - coef @ rhs.T
        sw = 0.5 * (sw + sw.T)
        if np.any(np.linalg.eigvalsh(sw) <= 0):
            sw = np.diag(np.maximum(np.diag(g0), 1e-16) * 1e-2)
        return coef.reshape(2, p, 2).transpose(1, 0, 2), sw

    def pack(self, d, cp, cq, A, sw, r) -> np.ndarray:
        """The parameter vector [D, c_P, c_Q, nuisance (:func:`_nuisance_vector`)]."""
        return np.r_[d, cp, cq, _nuisance_vector(A, sw, r)]

    def unpack(self, th: np.ndarray):
        return (th[:4], th[4], th[5], *_nuisance(th[6:], self.p))

    def matrices(self, th: np.ndarray):
        """F, G·Σ_w·Gᵀ, H, r of the state [z, x_k, …, x_{k−p+1}]; None without a steady state."""
        d, cp, cq, A, sw, r = self.unpack(th)
        lin = linear_motor(d, self.v0, self.w_off, self.omega0)
        if lin is None:
            return None
        Am, Bm, Cm, Dm = lin
        phi, g0, g1 = first_order_hold(Am, Bm, self.dt)
        p, ns = self.p, self.ns
        F = np.zeros((ns, ns))
        F[:3, :3] = phi
        F[:3, 3:5] += g0
        for i in range(p):
            F[:3, 3 + 2 * i:5 + 2 * i] += g1 @ A[i]
            F[3:5, 3 + 2 * i:5 + 2 * i] = A[i]
        for i in range(1, p):
            F[3 + 2 * i:5 + 2 * i, 1 + 2 * i:3 + 2 * i] = np.eye(2)
        G = np.zeros((ns, 2))
        G[:3] = g1
        G[3:5] = np.eye(2)
        H = np.zeros((4, ns))
        H[0, 3] = H[1, 4] = 1.0
        H[2:, :3] = Cm
        H[2:, 3:5] = Dm
        H[2, 3] += cp
        H[3, 3] += cq
        return F, G @ sw @ G.T, H, r

    def p0(self) -> np.ndarray:
        """A wide prior on the initial state: the motor's deviations and the inputs' lags, each 100 × the inputs'
        sample variance (the motor's in P_im's units through a)."""
        vx = np.maximum(self.y[:, :2].var(axis=0), 1e-12)
        diag = np.r_[np.full(3, 100.0 * float(vx.max())), np.tile(100.0 * vx, self.p)]
        return np.diag(diag)

    def nll(self, th: np.ndarray) -> float:
        m = self.matrices(th)
        if m is None:
            return 1e12
        F, Gq, H, r = m
        try:
            v = kalman_nll(F, Gq, H, r, self.y, self.k0, self.prior, FREEZE_AT)
        except np.linalg.LinAlgError:
            return 1e12
        return v if math.isfinite(v) else 1e12


def motor_response(jm: JointModel, d: np.ndarray) -> np.ndarray | None:
    """[ΔP_im, ΔQ_im] (n, 2) of the linear motor at d driven by the window's measured input deviations; None without
    a steady state."""
    lin = linear_motor(d, jm.v0, jm.w_off, jm.omega0)
    if lin is None:
        return None
    return linear_response(lin, jm.y[:, :2], jm.dt)


def static_slopes(jm: JointModel, d: np.ndarray) -> tuple[float, float]:
    """c_P, c_Q by least squares of P, Q minus the linear motor driven by the measured inputs, on ΔV."""
    out = motor_response(jm, d)
    if out is None:
        return 0.0, 0.0
    k0 = jm.k0
    dv = jm.y[k0:, 0]
    cp = float(np.dot(dv, jm.y[k0:, 2] - out[k0:, 0]) / np.dot(dv, dv))
    cq = float(np.dot(dv, jm.y[k0:, 3] - out[k0:, 1]) / np.dot(dv, dv))
    return cp, cq


def em_step(jm: JointModel, d, cp, cq, u: np.ndarray, fit_r: bool) -> np.ndarray:
    """One EM update of the nuisance vector u = [A (4p), log-Cholesky of Σ_w (3), log r (4)] at D, c_P, c_Q."""
    p = jm.p
    A, sw, r = _nuisance(u, p)
    m = jm.matrices(jm.pack(d, cp, cq, A, sw, r))
    if m is None:
        return u
    F, Gq, H, _r = m
    s11, s10, s00, cnt, r_new = var_moments(F, Gq, H, r, jm.y, jm.prior, p)
    coef = np.linalg.solve(s00.T, s10.T).T
    sw = (s11 - coef @ s10.T) / cnt
    sw = 0.5 * (sw + sw.T)
    A = coef.reshape(2, p, 2).transpose(1, 0, 2)
    return _nuisance_vector(A, sw, r_new if fit_r else r)


def _nuisance_vector(A, sw, r) -> np.ndarray:
    w, v = np.linalg.eigh(sw)
    c = np.linalg.cholesky((v * np.maximum(w, 1e-12 * max(float(w.max()), 1e-300))) @ v.T)
    return np.r_[A.ravel(), math.log(c[0, 0]), c[1, 0], math.log(c[1, 1]), np.log(r)]


def _nuisance(u: np.ndarray, p: int):
    A = u[:4 * p].reshape(p, 2, 2)
    l0, l1, l2 = u[4 * p:4 * p + 3]
    c = np.array([[math.exp(min(max(l0, -60.0), 10.0)), 0.0], [l1, math.exp(min(max(l2, -60.0), 10.0))]])
    return A, c @ c.T, np.exp(np.clip(u[4 * p + 3:4 * p + 7], -80.0, 10.0))


def em_fit(jm: JointModel, d, cp, cq, u: np.ndarray, cycles: int, fit_r: bool = True) -> np.ndarray:
    """The nuisance at D, c_P, c_Q by EM accelerated by SQUAREM (Varadhan & Roland 2008, scheme S3), each cycle
    kept only where it does not lower the likelihood."""
    def nll(v):
        A, sw, r = _nuisance(v, jm.p)
        return jm.nll(jm.pack(d, cp, cq, A, sw, r))
    for _ in range(cycles):
        u1 = em_step(jm, d, cp, cq, u, fit_r)
        u2 = em_step(jm, d, cp, cq, u1, fit_r)
        rr = u1 - u
        vv = u2 - u1 - rr
        nv = float(np.linalg.norm(vv))
        alpha = -max(1.0, float(np.linalg.norm(rr)) / nv) if nv > 0 else -1.0
        u3 = em_step(jm, d, cp, cq, u - 2.0 * alpha * rr + alpha * alpha * vv, fit_r)
        f3, f2 = nll(u3), nll(u2)
        u = u3 if f3 <= f2 else u2
    return u


def joint_ml(V, theta, P, Q, dt: float, f0: float, d0: np.ndarray, order: int = 12, skip_s: float = 1.0,
             rounds: int = 4, cycles_first: int = 40, cycles: int = 15,
             fit_r: bool = True) -> tuple[np.ndarray, dict]:
    """D [a, b, H2, Tm] maximising the joint likelihood over latent V and θ, from d0; and the fit's record.

    Alternates the nuisance (the VAR, Σ_w and, with ``fit_r``, the noise variances) by accelerated EM at the current D
    (:func:`em_fit`, ``cycles_first`` cycles before D first moves, ``cycles`` after) with D and c_P, c_Q by L-BFGS-B at
    the current nuisance.  The VAR starts from the Yule–Walker equations on the measured inputs with their floor taken
    off."""
    jm = JointModel(V, theta, P, Q, dt, f0, order, skip_s)
    A, sw = jm.var_start()
    d = np.asarray(d0, float).copy()
    cp, cq = static_slopes(jm, d)
    u = _nuisance_vector(A, sw, jm.r0.copy())
    lo, hi = dynamic_bounds(float(P.mean()))
    scale = np.maximum(np.abs(d0), 1e-3)
    nll0 = jm.nll(jm.pack(d, cp, cq, A, sw, jm.r0))
    hist = []
    nfev = 0
    for rnd in range(rounds):
        u = em_fit(jm, d, cp, cq, u, cycles_first if rnd == 0 else cycles, fit_r)
        A, sw, r = _nuisance(u, order)

        def f(x, A=A, sw=sw, r=r):  # the nuisance of this round
            return jm.nll(jm.pack(x[:4] * scale, x[4], x[5], A, sw, r))
        bounds = [(lo[i] / scale[i], hi[i] / scale[i]) for i in range(4)]
        bounds += [(None, None)] * 2
        res = optimize.minimize(f, np.r_[d / scale, cp, cq], method="L-BFGS-B", bounds=bounds,
                                options={"maxiter": 200})
        nfev += res.nfev
        d, cp, cq = res.x[:4] * scale, float(res.x[4]), float(res.x[5])
        hist.append(float(res.fun))
    A, sw, r = _nuisance(u, order)
    return d, {"nll0": float(nll0), "nll": float(hist[-1]), "nll_rounds": hist, "nfev": nfev,
               "theta": jm.pack(d, cp, cq, A, sw, r).tolist(), "r": r.tolist(), "r0": jm.r0.tolist()}


def summarise(rows: list[dict], key: str) -> dict:
    r = np.array([row[key] for row in rows], float)
    var = np.array([row["bound_var"] for row in rows], float)
    ok = np.all(np.isfinite(r), axis=1)
    z = (r[ok] - 1.0) / np.sqrt(var[ok])
    return {"n": int(ok.sum()), "mu": r[ok].mean(axis=0).tolist(), "sigma": r[ok].std(axis=0, ddof=1).tolist(),
            "sigma_over_bound": (r[ok].std(axis=0, ddof=1) / np.sqrt(var[ok].mean(axis=0))).tolist(),
            "z_mad": (1.4826 * np.median(np.abs(z - np.median(z, axis=0)), axis=0)).tolist(),
            "n_far_3": int(np.sum(np.max(np.abs(z), axis=1) > 3.0))}


def main(argv=None) -> dict:
    ap = common.parser(__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--order", type=int, default=12)
    ap.add_argument("--cycles-first", type=int, default=40, help="accelerated EM cycles before D first moves")
    ap.add_argument("--cycles", type=int, default=15, help="accelerated EM cycles in each later round")
    ap.add_argument("--rounds", type=int, default=4, help="rounds of EM cycles and a D step")
    ap.add_argument("--cells", nargs="*", default=None, help="'level|class' keys (default: every noisy cell)")
    ap.add_argument("--out", default="input_noise_kalman")
    args = ap.parse_args(argv)
    stored = json.loads((common.RESULTS / "input_noise_bound_n300.json").read_text())
    bounds = stored["per_window_relative_variance"]
    cases = {level: common.cases(args.first + args.n, level=level, seed=CONFIRM_SEED) for level in LEVELS}
    t0 = time.perf_counter()
    cells: dict[str, list] = {}
    draws = noisy_draws(cases, CONFIRM_SEED, args.first + args.n, LEVELS)
    for i, level, cls, key, c, w, r in identified_draws(draws, args.first, args.cells, DEFAULT):
        dt = float(np.median(np.diff(w.t)))
        t1 = time.perf_counter()
        d, rec = joint_ml(w.V, w.theta, w.P, w.Q, dt, w.f0, r.d, order=args.order, rounds=args.rounds,
                          cycles_first=args.cycles_first, cycles=args.cycles)
        rec["s"] = time.perf_counter() - t1
        cells.setdefault(key, []).append({"i": i, "default": (r.d / c.truth.d).tolist(),
                                          "kalman": (d / c.truth.d).tolist(),
                                          "bound_var": bounds[i][str(level)][f"{cls}|structural"], **rec})
        print(f"{i} {key} default {np.round(r.d / c.truth.d, 3)} kalman {np.round(d / c.truth.d, 3)} "
              f"({rec['s']:.1f} s, {rec['nfev']} evaluations, nll {rec['nll0']:.1f} -> {rec['nll']:.1f})", flush=True)
    summ = {key: {name: summarise(rows, name) for name in ("default", "kalman")} for key, rows in cells.items()}
    for key, per in summ.items():
        for name, row in per.items():
            print(f"{key:24s} {name:8s} n {row['n']} μ {np.round(row['mu'], 3)} σ/bound "
                  f"{np.round(row['sigma_over_bound'], 2)} z_mad {np.round(row['z_mad'], 2)} far {row['n_far_3']}")
    out = {"machine": common.machine(), "n": args.n, "first": args.first, "order": args.order,
           "cycles_first": args.cycles_first, "cycles": args.cycles, "rounds": args.rounds, "seed": CONFIRM_SEED,
           "summary": summ, "cells": cells, "total_s": time.perf_counter() - t0}
    if not args.no_write:
        common.write_json(args.out, out)
    return out


if __name__ == "__main__":
    main()
