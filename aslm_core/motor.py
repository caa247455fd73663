"""Transformed third-order induction motor (paper eq. 4–5) and its exact discrete sensitivities.

States x = [Fd, Fq, s] with Fd = Ed/X', Fq = Eq/X'; parameters D = [a, b, H2, Tm]::

    dFd/dt = -b·Fd + s·ω0·Fq + a·Vd
    dFq/dt = -b·Fq - s·ω0·Fd + a·Vq
    ds/dt  = (Tm - Vq·Fd + Vd·Fq) / H2
    P_im = Fd·Vq - Fq·Vd,   Q_im = -Vd·Fd - Vq·Fq

The kernels integrate either by RK4 at the sample step, split into sub-steps of at most
``MAX_STEP_S`` at low reporting rates, with V and θ inside the step from cubics through the samples (the spline where
the step is split), or by the paper's explicit Euler at the sample step, and propagate dx/dD through the
*discrete* map so the gradient is exact for the objective actually minimised.

Initial state: the low-slip steady state at the first sample.  Ambient windows start off nominal
frequency; a steady state at ω0 then carries a slip error of Δω/ω0 whose transient outlasts the skipped
first second (noise-free recovery errors up to 1.4 %).  The RK4 mode therefore starts from the steady
state that turns with the voltage phasor (dθ/dt over the first 0.05 s); the paper's Euler mode keeps ω0.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aslm_core.errors import NoEquilibriumError

# The initial steady state turns with the bus frequency, estimated over this first stretch [s].
START_SLOPE_S = 0.05
#: Longest RK4 step [s]: a sample step above it is split into sub-steps (inputs from the spline, :func:`dq_inputs`).
#: The fastest stator mode in the box decays at b ≤ 100 /s and turns at ~s·ω0, so |λ|·h reaches ~1–4 at the
#: 33–40 ms of 25–30 frames/s: there RK4 at the sample step was off by up to 0.6–0.95 of P_im's ambient
#: std and noise-free D by up to 5–9 % (H2); at 10 ms by ≤ 0.5 % of the std and ≤ 0.07 % (docs/numerics.md).
MAX_STEP_S = 0.0101


def substeps(dt: float) -> int:
    """RK4 sub-steps per sample step dt [s]: the fewest that keep each within :data:`MAX_STEP_S`."""
    return max(1, int(math.ceil(dt / MAX_STEP_S - 1e-9)))


def omega0_of(f0: float) -> float:
    """Synchronous angular speed [rad/s].

    Parameters
    ----------
    f0 : float
        Nominal system frequency [Hz].
    """
    return 2.0 * math.pi * f0


def dq_inputs(V: np.ndarray, theta: np.ndarray, m: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Voltage components at the samples and at the points inside each step RK4 with m sub-steps needs.

    Parameters
    ----------
    V : ndarray
        Voltage magnitude [pu].
    theta : ndarray
        Unwrapped voltage angle [rad].
    m : int
        RK4 sub-steps per sample step (:func:`substeps`).

    Returns
    -------
    vd, vq : ndarray, shape (n,)
        Vd + jVq = V·e^{jθ} at the samples [pu].
    vdm, vqm : ndarray, shape ((n-1)·(2m-1),)
        The same at the fractions 1/(2m) … (2m-1)/(2m) of each step, step-major (m = 1: the half steps),
        from V and θ interpolated by the cubic spline where m > 1 (:data:`SPLINE_INPUTS`), else by 4-point cubics
        [pu].  :func:`simulate_kernel` infers m from the length.
    """
    vd = V * np.cos(theta)
    vq = V * np.sin(theta)
    fr = np.arange(1, 2 * m) / (2.0 * m)
    if _spline(m, V.size):
        vm, thm = _spline_interior(V, fr), _spline_interior(theta, fr)
    elif m == 1:
        vm, thm = _midpoints(V), _midpoints(theta)
    else:
        vm = np.stack([_interior(V, f) for f in fr], axis=1).ravel()
        thm = np.stack([_interior(theta, f) for f in fr], axis=1).ravel()
    return vd, vq, vm * np.cos(thm), vm * np.sin(thm)


#: Inputs inside a split sample step (m > 1, below ~99 frames/s) from the not-a-knot cubic spline through V and θ
#: (True), or from 4-point Lagrange cubics with linear end steps (False, before stop 50; always at m = 1, where the
#: step is RK4's own and the cubic midpoint is O(dt⁴)).  The spline follows the inputs' content to a far larger share
#: of the Nyquist band: at 25 frames/s the Lagrange cubics biased noise-free a, H2 and Tm by +0.6 %, +0.7 %, −0.7 %.
#: Not at m = 1 too: the spline reads every later sample, which the IV's lag-2 instruments must not see (its criterion at
#: the true D rose from 1.63 to 1.70 median at 100 frames/s), and there it changed D by under 1e-4 (docs/numerics.md,
#: "Stop 50").
SPLINE_INPUTS = True
#: The spline's reach back: an input sample moves the interpolated inputs of steps that end more than this many samples
#: before it by under 0.05 % of its weight in its own step (the cardinal spline decays by 2 − √3 ≈ 0.27 a sample)
#: [samples].
SPLINE_REACH = 6


def _spline(m: int, n: int) -> bool:
    """Whether :func:`dq_inputs` interpolates n samples with m sub-steps by the spline."""
    return SPLINE_INPUTS and m > 1 and n >= 6


def input_reach(m: int) -> int:
    """Samples back from an input sample over which it moves the interpolated inputs (:func:`dq_inputs` with m
    sub-steps): 1 for the 4-point cubics, :data:`SPLINE_REACH` for the spline."""
    return SPLINE_REACH if _spline(m, 6) else 1


@nb.njit(cache=True, nogil=True)
def _spline_curvatures(x):  # pragma: no cover - numba
    """Second differences M of the not-a-knot cubic spline through x on a unit grid (n ≥ 6).

    Not-a-knot at knot 1 (M0 − 2·M1 + M2 = 0) turns the first interior row into 6·M1 = 6·δ²x1, so M1 and M(n−2) are
    known and rows 2 … n−3 form a tridiagonal system (1, 4, 1), solved by elimination."""
    n = x.shape[0]
    r = np.empty(n)
    for i in range(1, n - 1):
        r[i] = 6.0 * (x[i - 1] - 2.0 * x[i] + x[i + 1])
    M = np.empty(n)
    M[1] = r[1] / 6.0
    M[n - 2] = r[n - 2] / 6.0
    lo, hi = 2, n - 3
    c = np.empty(n)
    d = np.empty(n)
    d[lo] = r[lo] - M[1]
    c[lo] = 1.0 / 4.0
    d[lo] = d[lo] / 4.0
    for i in range(lo + 1, hi + 1):
        rhs = r[i] - (M[n - 2] if i == hi else 0.0)
        den = 4.0 - c[i - 1]
        c[i] = 1.0 / den
        d[i] = (rhs - d[i - 1]) / den
    M[hi] = d[hi]
    for i in range(hi - 1, lo - 1, -1):
        M[i] = d[i] - c[i] * M[i + 1]
    M[0] = 2.0 * M[1] - M[2]
    M[n - 1] = 2.0 * M[n - 2] - M[n - 3]
    return M


def _spline_interior(x: np.ndarray, fr: np.ndarray) -> np.ndarray:
    """Values of the not-a-knot cubic spline through x at the fractions fr of each step, step-major."""
    M = _spline_curvatures(np.ascontiguousarray(x, dtype=np.float64))
    f = fr[None, :]
    x0, x1 = x[:-1, None], x[1:, None]
    m0, m1 = M[:-1, None], M[1:, None]
    return ((1.0 - f) * x0 + f * x1 - f * (1.0 - f) / 6.0 * ((2.0 - f) * m0 + (1.0 + f) * m1)).ravel()


def _interior(x: np.ndarray, f: float) -> np.ndarray:
    """Values at the fraction f of each step: 4-point (cubic) Lagrange inside, linear at the two end steps."""
    out = x[:-1] + f * (x[1:] - x[:-1])
    if x.size >= 4:
        w = (-f * (f - 1) * (f - 2) / 6, (f + 1) * (f - 1) * (f - 2) / 2, -(f + 1) * f * (f - 2) / 2,
             (f + 1) * f * (f - 1) / 6)
        out[1:-1] = w[0] * x[:-3] + w[1] * x[1:-2] + w[2] * x[2:-1] + w[3] * x[3:]
    return out


def _midpoints(x: np.ndarray) -> np.ndarray:
    """Values half-way between samples: cubic (4-point) inside, linear at the two end intervals.

    Linear midpoints cost RK4 its order on sampled inputs and biased weakly excited parameters
    by ~1–2 % on noise-free data; the cubic midpoint is O(dt⁴).
    """
    m = 0.5 * (x[1:] + x[:-1])
    if x.size >= 4:
        m[1:-1] = (9.0 * (x[1:-2] + x[2:-1]) - (x[:-3] + x[3:])) / 16.0
    return m


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def _steady_state(vd0, vq0, a, b, h2, tm, w0, x0, s0, dw=0.0):
    """Low-slip equilibrium x0 and its sensitivity s0 = dx0/dD (filled in place); False if none.

    With the voltage phasor turning at dw [rad/s] (bus frequency off nominal), the steady state turns
    with it: F = a·V/(b + j·c) with c = s·ω0 + dw the same low root, so only the slip moves, by −dw/ω0.
    """
    v2 = vd0 * vd0 + vq0 * vq0
    disc = a * a * v2 * v2 - 4.0 * tm * tm * b * b
    if disc < 0.0 or a * v2 <= 0.0:
        return False
    # c = s·ω0, the smaller root of Tm·c² − a·V²·c + Tm·b² = 0, in the cancellation-free form.
    c = 2.0 * tm * b * b / (a * v2 + math.sqrt(disc))
    k = a / (b * b + c * c)
    fd = k * (b * vd0 + c * vq0)
    fq = k * (-c * vd0 + b * vq0)
    x0[0] = fd
    x0[1] = fq
    x0[2] = (c - dw) / w0
    # dx0/dD = -fx^{-1} fp at the equilibrium (implicit function theorem).
    fx = np.empty((3, 3))
    fx[0, 0] = -b
    fx[0, 1] = c
    fx[0, 2] = w0 * fq
    fx[1, 0] = -c
    fx[1, 1] = -b
    fx[1, 2] = -w0 * fd
    fx[2, 0] = -vq0 / h2
    fx[2, 1] = vd0 / h2
    fx[2, 2] = 0.0
    fp = np.zeros((3, 4))
    fp[0, 0] = vd0
    fp[1, 0] = vq0
    fp[0, 1] = -fd
    fp[1, 1] = -fq
    fp[2, 2] = 0.0  # Tm − Te = 0 at equilibrium
    fp[2, 3] = 1.0 / h2
    sol = np.linalg.solve(fx, fp)
    for i in range(3):
        for j in range(4):
            s0[i, j] = -sol[i, j]
    return True


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _start_angular_speed(vd, vq, dt):
    """dθ/dt at the first sample [rad/s]: least-squares slope of the angle over the first 0.05 s."""
    m = min(max(int(round(START_SLOPE_S / dt)) + 1, 2), vd.shape[0])
    th0 = math.atan2(vq[0], vd[0])
    st = 0.0
    sth = 0.0
    stt = 0.0
    sthh = 0.0
    prev = 0.0
    for k in range(m):
        th = math.atan2(vq[k], vd[k]) - th0
        th -= 2.0 * math.pi * round((th - prev) / (2.0 * math.pi))  # unwrap
        prev = th
        t = k * dt
        st += t
        stt += t * t
        sth += th
        sthh += t * th
    den = m * stt - st * st
    return (m * sthh - st * sth) / den if den > 0.0 else 0.0


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy", fastmath={"contract"})
def _f(fd, fq, s, vd, vq, a, b, ih2, tm, w0):
    ws = w0 * s
    return (
        -b * fd + ws * fq + a * vd,
        -b * fq - ws * fd + a * vq,
        (tm - (vq * fd - vd * fq)) * ih2,
    )


@nb.njit(cache=True, nogil=True, inline="always", error_model="numpy", fastmath={"contract"})
def _sens_rate(W, c, fd, fq, s, vd, vq, dsdt, b, w0, ih2, t, k):
    """Rows k..k+2 of W = fx·(S + c·T) + fp: the sensitivity rate at a stage state.

    W holds the sensitivity columns row-wise (rows 0–2: S = dx/dD, one column per parameter), T is
    rows t..t+2; 4-wide rows keep the loops over parameters short and contiguous.
    """
    ws = w0 * s
    wfq = w0 * fq
    wfd = w0 * fd
    for j in range(4):
        s0 = W[0, j] + c * W[t, j]
        s1 = W[1, j] + c * W[t + 1, j]
        s2 = W[2, j] + c * W[t + 2, j]
        W[k, j] = -b * s0 + ws * s1 + wfq * s2
        W[k + 1, j] = -ws * s0 - b * s1 - wfd * s2
        W[k + 2, j] = (vd * s1 - vq * s0) * ih2
    # fp = ∂f/∂D: columns a, b, H2 (−(ds/dt)/H2), Tm.
    W[k, 0] += vd
    W[k + 1, 0] += vq
    W[k, 1] -= fd
    W[k + 1, 1] -= fq
    W[k + 2, 2] -= dsdt * ih2
    W[k + 2, 3] += ih2


@nb.njit(cache=True, nogil=True, inline="always")
def substep_layout(n, nm):  # pragma: no cover - numba
    """Interior inputs per sample step and RK4 sub-steps m, from n samples and nm interior inputs (:func:`dq_inputs`'
    layout: 2m − 1 per step)."""
    per = nm // (n - 1) if n > 1 else 1
    return per, (per + 1) // 2


@nb.njit(cache=True, nogil=True, inline="always")
def substep_inputs(vd, vq, vdm, vqm, k, j, per, m):  # pragma: no cover - numba
    """Vd, Vq at the start, the middle and the end of RK4 sub-step j of sample step k (:func:`dq_inputs`' layout)."""
    base = k * per + 2 * j
    if j > 0:
        ud = vdm[base - 1]
        uq = vqm[base - 1]
    else:
        ud = vd[k]
        uq = vq[k]
    if j == m - 1:
        nd = vd[k + 1]
        nq = vq[k + 1]
    else:
        nd = vdm[base + 1]
        nq = vqm[base + 1]
    return ud, uq, vdm[base], vqm[base], nd, nq


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def simulate_kernel(vd, vq, vdm, vqm, d, dt, w0, rk4, with_sens, p_out, q_out, dp_out, dq_out, x_out,
                    store, k0, p_meas, q_meas, X):
    """Integrate from the steady state at sample 0, with forward sensitivities dx/dD.

    With ``store`` it fills P_im, Q_im, their D-gradients and the states per sample.  Otherwise it
    fills, for samples k0.., the rows of X (l×10) with [yp, ∂P_im/∂D, yq, ∂Q_im/∂D] where
    y = measured − model, each shifted by its value at sample k0 (see :func:`normal_equations`).

    Returns False when no equilibrium exists at the first sample, or when the trajectory
    leaves the finite numbers.
    """
    a = d[0]
    b = d[1]
    h2 = d[2]
    tm = d[3]
    ih2 = 1.0 / h2
    n = vd.shape[0]
    x = np.empty(3)
    # Rows 0–2: S = dx/dD; rows 3–14: the four RK4 stage rates of S.
    W = np.zeros((15, 4))
    # The paper's mode (explicit Euler) keeps its steady state at the nominal frequency.
    dw = _start_angular_speed(vd, vq, dt) if rk4 else 0.0
    if not _steady_state(vd[0], vq[0], a, b, h2, tm, w0, x, W[0:3], dw):
        return False
    fd = x[0]
    fq = x[1]
    s = x[2]
    # RK4 sub-steps per sample step, from the interior inputs given (see dq_inputs).
    per, m = substep_layout(n, vdm.shape[0])
    if not rk4:
        m = 1
    h = dt / m
    h6 = h / 6.0
    for k in range(n):
        ud = vd[k]
        uq = vq[k]
        if store:
            p_out[k] = fd * uq - fq * ud
            q_out[k] = -ud * fd - uq * fq
            x_out[k, 0] = fd
            x_out[k, 1] = fq
            x_out[k, 2] = s
            if with_sens:
                for j in range(4):
                    dp_out[k, j] = uq * W[0, j] - ud * W[1, j]
                    dq_out[k, j] = -ud * W[0, j] - uq * W[1, j]
        elif k >= k0:
            i = k - k0
            X[i, 0] = p_meas[i] - (fd * uq - fq * ud)
            X[i, 5] = q_meas[i] - (-ud * fd - uq * fq)
            for j in range(4):
                X[i, 1 + j] = uq * W[0, j] - ud * W[1, j]
                X[i, 6 + j] = -ud * W[0, j] - uq * W[1, j]
            if i > 0:
                for j in range(10):
                    X[i, j] -= X[0, j]
        if k == n - 1:
            break
        for j in range(m if rk4 else 0):
            ud, uq, md, mq, nd, nq = substep_inputs(vd, vq, vdm, vqm, k, j, per, m)
            k1 = _f(fd, fq, s, ud, uq, a, b, ih2, tm, w0)
            x2d = fd + 0.5 * h * k1[0]
            x2q = fq + 0.5 * h * k1[1]
            x2s = s + 0.5 * h * k1[2]
            k2 = _f(x2d, x2q, x2s, md, mq, a, b, ih2, tm, w0)
            x3d = fd + 0.5 * h * k2[0]
            x3q = fq + 0.5 * h * k2[1]
            x3s = s + 0.5 * h * k2[2]
            k3 = _f(x3d, x3q, x3s, md, mq, a, b, ih2, tm, w0)
            x4d = fd + h * k3[0]
            x4q = fq + h * k3[1]
            x4s = s + h * k3[2]
            k4 = _f(x4d, x4q, x4s, nd, nq, a, b, ih2, tm, w0)
            if with_sens:
                _sens_rate(W, 0.0, fd, fq, s, ud, uq, k1[2], b, w0, ih2, 0, 3)
                _sens_rate(W, 0.5 * h, x2d, x2q, x2s, md, mq, k2[2], b, w0, ih2, 3, 6)
                _sens_rate(W, 0.5 * h, x3d, x3q, x3s, md, mq, k3[2], b, w0, ih2, 6, 9)
                _sens_rate(W, h, x4d, x4q, x4s, nd, nq, k4[2], b, w0, ih2, 9, 12)
                for i in range(3):
                    for j in range(4):
                        W[i, j] += h6 * (W[3 + i, j] + 2.0 * W[6 + i, j] + 2.0 * W[9 + i, j] + W[12 + i, j])
            fd += h6 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            fq += h6 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
            s += h6 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        if not rk4:
            k1 = _f(fd, fq, s, ud, uq, a, b, ih2, tm, w0)
            if with_sens:
                _sens_rate(W, 0.0, fd, fq, s, ud, uq, k1[2], b, w0, ih2, 0, 3)
                for i in range(3):
                    for j in range(4):
                        W[i, j] += h * W[3 + i, j]
            fd += h * k1[0]
            fq += h * k1[1]
            s += h * k1[2]
        if not (math.isfinite(fd) and math.isfinite(fq) and math.isfinite(s)) or abs(fd) > 1e12:
            return False
    if not store:
        for j in range(10):
            X[0, j] = 0.0
    return True


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def normal_equations(X, basis2, G):
    """Projected residual norms and normal equations of both channels from the rows of X.

    X rows are [yp, mp(4), yq, mq(4)] shifted by the first row (so that centring loses few digits);
    the projection P⊥ removes the constant regressor (centring) and the orthonormal ``basis2``.
    Fills G (10×10) = centred XᵀX − (B2ᵀX)ᵀ(B2ᵀX); the blocks give ‖r‖², Jᵀr and JᵀJ with J = −P⊥m.
    """
    l = X.shape[0]
    gram = X.T @ X
    colsum = np.zeros(10)
    for i in range(l):
        for j in range(10):
            colsum[j] += X[i, j]
    bx = basis2.T @ X
    for u in range(10):
        for v in range(10):
            G[u, v] = gram[u, v] - colsum[u] * colsum[v] / l - bx[0, u] * bx[0, v] - bx[1, u] * bx[1, v]


def steady_state(V0: float, theta0: float, d: np.ndarray, omega0: float) -> np.ndarray:
    """Low-slip equilibrium [Fd, Fq, s] of eq. 4 at the voltage V0∠θ0.

    Parameters
    ----------
    V0 : float
        Voltage magnitude [pu].
    theta0 : float
        Voltage angle [rad].
    d : array_like
        D = [a [1/s], b [1/s], H2 [s], Tm [pu]].
    omega0 : float
        Synchronous speed [rad/s].

    Returns
    -------
    ndarray
        [Fd [pu], Fq [pu], s [-]].

    Raises
    ------
    NoEquilibriumError
        When a·V0² <= 2b·Tm: the load torque exceeds the motor's maximum torque.

    Notes
    -----
    With ds/dt = 0 and dF/dt = 0, Te = a·V²·c/(b² + c²) with c = s·ω0; Te = Tm has the roots
    c = (a·V² ± sqrt(a²V⁴ − 4Tm²b²))/(2Tm); the smaller one is the stable, low-slip operating point.
    """
    d = np.asarray(d, dtype=np.float64)
    x0 = np.empty(3)
    s0 = np.empty((3, 4))
    ok = _steady_state(V0 * math.cos(theta0), V0 * math.sin(theta0), d[0], d[1], d[2], d[3], omega0, x0, s0)
    if not ok:
        raise NoEquilibriumError(
            f"no motor equilibrium at V={V0:.4f} pu for D={d.tolist()}: "
            f"a·V² = {d[0] * V0 * V0:.4g} must exceed 2b·Tm = {2 * d[1] * d[3]:.4g}"
        )
    return x0


def slowest_time_constant(V0: float, theta0: float, d: np.ndarray, omega0: float) -> float:
    """Time constant of the slowest mode of eq. 4 linearised at its steady state [s].

    Parameters
    ----------
    V0, theta0 : float
        Voltage magnitude [pu] and angle [rad] of the operating point.
    d : array_like
        D = [a [1/s], b [1/s], H2 [s], Tm [pu]].
    omega0 : float
        Synchronous speed [rad/s].

    Returns
    -------
    float
        1/min|Re λ| over the eigenvalues λ of the state Jacobian [s] (inf if a mode does not decay).
        The initial state's error decays at this rate: the slip mode, ≈ H2·b²/(ω0·a·V²) for small
        slip, or the flux mode, ≈ 1/b.

    Raises
    ------
    NoEquilibriumError
        When D has no equilibrium at V0.
    """
    a, b, h2, _ = (float(x) for x in d)
    fd, fq, s = steady_state(V0, theta0, d, omega0)
    vd, vq = V0 * math.cos(theta0), V0 * math.sin(theta0)
    jac = np.array([[-b, s * omega0, omega0 * fq],
                    [-s * omega0, -b, -omega0 * fd],
                    [-vq / h2, vd / h2, 0.0]])
    rate = -float(np.linalg.eigvals(jac).real.max())
    return 1.0 / rate if rate > 0.0 else math.inf


def simulate(
    V: np.ndarray,
    theta: np.ndarray,
    d: np.ndarray,
    dt: float,
    omega0: float,
    integrator: str = "rk4",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Motor power driven by measured voltage phasors, starting from steady state.

    Parameters
    ----------
    V : ndarray
        Voltage magnitude [pu] on a uniform grid.
    theta : ndarray
        Unwrapped voltage angle [rad].
    d : array_like
        D = [a [1/s], b [1/s], H2 [s], Tm [pu]].
    dt : float
        Sample step [s].
    omega0 : float
        Synchronous speed [rad/s].
    integrator : {"rk4", "euler"}
        RK4 with the inputs inside the step from cubics through the samples (:func:`dq_inputs`), or the paper's
        explicit Euler (§IV.A).

    Returns
    -------
    P_im, Q_im : ndarray
        Motor active power and the reactive power of eq. 5 [pu] (V²/X' belongs to the static part).
    x : ndarray, shape (n, 3)
        States [Fd, Fq, s].

    Raises
    ------
    NoEquilibriumError
        When D has no steady state at the first sample.
    """
    V = np.ascontiguousarray(V, dtype=np.float64)
    theta = np.ascontiguousarray(theta, dtype=np.float64)
    d = np.ascontiguousarray(d, dtype=np.float64)
    steady_state(float(V[0]), float(theta[0]), d, omega0)
    vd, vq, vdm, vqm = dq_inputs(V, theta, substeps(dt) if integrator == "rk4" else 1)
    n = V.shape[0]
    p = np.empty(n)
    q = np.empty(n)
    x = np.empty((n, 3))
    dummy = np.empty((1, 4))
    ok = simulate_kernel(vd, vq, vdm, vqm, d, float(dt), float(omega0), integrator == "rk4", False, p, q, dummy,
                         dummy, x, True, 0, p, q, dummy)
    if not ok:
        p[:] = np.nan
        q[:] = np.nan
    return p, q, x
