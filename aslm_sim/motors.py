"""The induction motor in its ORIGINAL form (paper eq. 1–3), third or fifth order, driven by measured V and θ.

Independent of the identifier's transformed model (:mod:`aslm_core.motor`): the concealed effects use it
as ground truth, at a fine RK4 step on spline-interpolated voltage phasors.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from aslm_sim.truth import LoadTruth

__all__ = ["FINE_STEP_S", "fine_inputs", "original_motor_power", "truth_motor"]

#: Longest step of the fine integration grid [s].
FINE_STEP_S = 1e-3


def fine_inputs(t: np.ndarray, V: np.ndarray, theta: np.ndarray,
                h: float = FINE_STEP_S) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Vd, Vq on a fine grid of half steps (cubic splines of V and θ) and the sample stride.

    Parameters
    ----------
    t, V, theta : ndarray
        Uniform sample times [s], voltage magnitude [pu] and unwrapped angle [rad].
    h : float
        Longest fine step [s]; the step used divides the sample step.

    Returns
    -------
    vd, vq : ndarray
        Values at t0 + j·h/2 [pu].
    stride : int
        Fine steps per sample.
    h : float
        Fine step actually used [s].
    """
    dt = float(t[1] - t[0])
    stride = max(1, int(round(dt / h)))
    h = dt / stride
    tf = t[0] + 0.5 * h * np.arange(2 * stride * (t.size - 1) + 1)
    vf = CubicSpline(t, V)(tf)
    thf = CubicSpline(t, theta)(tf)
    return vf * np.cos(thf), vf * np.sin(thf), stride, h


@nb.njit(cache=True)
def _motor_rhs(x, vd, vq, X, Xp, Td0, H2, tm0, s0, k, Rs, w0, fifth):  # pragma: no cover - numba
    """Original-form motor: x = [Ed, Eq, s, psid, psiq]; returns dx and (Id, Iq)."""
    ed, eq, s = x[0], x[1], x[2]
    if fifth:
        idd = (x[3] - eq) / Xp  # I = (ψ + jE')/X'
        iq = (x[4] + ed) / Xp
    else:  # I = (V − E')/(Rs + jX')
        ur, ui = vd - ed, vq - eq
        den = Rs * Rs + Xp * Xp
        idd = (ur * Rs + ui * Xp) / den
        iq = (ui * Rs - ur * Xp) / den
    # dE'/dt = −(E' − j(X − X')I)/Td0 − j·s·ω0·E'
    xd = X - Xp
    ded = -(ed + xd * iq) / Td0 + s * w0 * eq
    deq = -(eq - xd * idd) / Td0 - s * w0 * ed
    te = ed * idd + eq * iq  # Re(E'·conj(I))
    tm = tm0 * ((1.0 - s) / (1.0 - s0)) ** k
    ds = (tm - te) / H2
    dpd = 0.0
    dpq = 0.0
    if fifth:  # dψ/dt = ω0(V − Rs·I − jψ)
        dpd = w0 * (vd - Rs * idd + x[4])
        dpq = w0 * (vq - Rs * iq - x[3])
    return ded, deq, ds, dpd, dpq, idd, iq


@nb.njit(cache=True)
def _motor_run(vdf, vqf, stride, h, x0, X, Xp, Td0, H2, tm0, s0, k, Rs, w0, fifth, n):  # pragma: no cover
    p = np.empty(n)
    q = np.empty(n)
    x = x0.copy()
    k1 = np.empty(5)
    k2 = np.empty(5)
    k3 = np.empty(5)
    k4 = np.empty(5)
    xt = np.empty(5)
    for i in range(n):
        j = 2 * i * stride
        r = _motor_rhs(x, vdf[j], vqf[j], X, Xp, Td0, H2, tm0, s0, k, Rs, w0, fifth)
        p[i] = vdf[j] * r[5] + vqf[j] * r[6]
        q[i] = vqf[j] * r[5] - vdf[j] * r[6]
        if i == n - 1:
            break
        for m in range(stride):
            jj = 2 * (i * stride + m)
            r = _motor_rhs(x, vdf[jj], vqf[jj], X, Xp, Td0, H2, tm0, s0, k, Rs, w0, fifth)
            for c in range(5):
                k1[c] = r[c]
                xt[c] = x[c] + 0.5 * h * k1[c]
            r = _motor_rhs(xt, vdf[jj + 1], vqf[jj + 1], X, Xp, Td0, H2, tm0, s0, k, Rs, w0, fifth)
            for c in range(5):
                k2[c] = r[c]
                xt[c] = x[c] + 0.5 * h * k2[c]
            r = _motor_rhs(xt, vdf[jj + 1], vqf[jj + 1], X, Xp, Td0, H2, tm0, s0, k, Rs, w0, fifth)
            for c in range(5):
                k3[c] = r[c]
                xt[c] = x[c] + h * k3[c]
            r = _motor_rhs(xt, vdf[jj + 2], vqf[jj + 2], X, Xp, Td0, H2, tm0, s0, k, Rs, w0, fifth)
            for c in range(5):
                k4[c] = r[c]
                x[c] += h / 6.0 * (k1[c] + 2.0 * k2[c] + 2.0 * k3[c] + k4[c])
    return p, q


def _equilibrium(vd: float, vq: float, X: float, Xp: float, Td0: float, Tm: float, Rs: float,
                 w0: float) -> tuple[float, float, float]:
    """Low-slip steady state [Ed, Eq, s] of the original-form motor with stator resistance Rs."""
    v = complex(vd, vq)

    def state(s):
        # E' from dE'/dt = 0 with I = (V − E')/(Rs + jX'):  E'(1 + j s ω0 Td0) = j(X − X')I
        zs = complex(Rs, Xp)
        a = 1.0 + 1j * s * w0 * Td0
        c = 1j * (X - Xp) / zs
        e = c * v / (a + c)
        i = (v - e) / zs
        return e, (e * i.conjugate()).real

    s_hi = 0.5
    grid = np.linspace(1e-7, s_hi, 4000)
    te = np.array([state(s)[1] for s in grid])
    idx = np.flatnonzero(te >= Tm)
    if idx.size == 0:
        raise ValueError("no motor equilibrium")
    j = idx[0]
    s = brentq(lambda s: state(s)[1] - Tm, grid[max(j - 1, 0)], grid[j], xtol=1e-15)
    e, _ = state(s)
    return e.real, e.imag, s


def original_motor_power(t: np.ndarray, V: np.ndarray, theta: np.ndarray, *, X: float, Xp: float, Td0: float,
                         H2: float, Tm: float, k: float = 0.0, Rs: float = 0.0, fifth: bool = False,
                         f0: float = 50.0) -> tuple[np.ndarray, np.ndarray]:
    """P, Q [pu] of an original-form induction motor (third- or fifth-order) driven by V [pu], θ [rad].

    Parameters
    ----------
    t : ndarray
        Uniform sample times [s].
    V : ndarray
        Voltage magnitude [pu].
    theta : ndarray
        Unwrapped voltage angle [rad].
    X, Xp : float
        Open-circuit and transient reactance [pu].
    Td0 : float
        Rotor open-circuit time constant [s].
    H2 : float
        2H [s].
    Tm : float
        Load torque at the initial slip [pu].
    k : float
        Torque–speed exponent: Tm(s) = Tm·((1 − s)/(1 − s0))^k [-].
    Rs : float
        Stator resistance [pu].
    fifth : bool
        Include the stator flux dynamics (dψ/dt = ω0(V − Rs·I − jψ)).
    f0 : float
        Nominal frequency [Hz].

    Notes
    -----
    Eq. 1–3 of the paper with I = (V − E')/(Rs + jX') (third order) or I = (ψ + jE')/X' with the stator
    flux ψ as two more states (fifth order); Te = Re(E'·I*), P + jQ = V·I* (Q includes V²/X').  RK4 at
    ≤ 1 ms, the voltage phasor from cubic splines of V and θ; steady-state start.
    """
    w0 = 2.0 * math.pi * f0
    vdf, vqf, stride, h = fine_inputs(t, V, theta)
    ed, eq, s0 = _equilibrium(vdf[0], vqf[0], X, Xp, Td0, Tm, Rs, w0)
    v0 = complex(vdf[0], vqf[0])
    i0 = (v0 - complex(ed, eq)) / complex(Rs, Xp)
    psi0 = -1j * (v0 - Rs * i0)  # V = Rs·I + jψ at rest
    x0 = np.array([ed, eq, s0, psi0.real, psi0.imag])
    return _motor_run(vdf, vqf, stride, h, x0, X, Xp, Td0, H2, Tm, s0, k, Rs, w0, fifth, t.size)


def truth_motor(tr: LoadTruth) -> dict[str, float]:
    """The original-form parameters X, Xp [pu], Td0, H2 [s], Tm [pu] of a truth's motor (keywords of
    :func:`original_motor_power`).

    Parameters
    ----------
    tr : LoadTruth
        The load.
    """
    return {"X": tr.X, "Xp": tr.Xp, "Td0": tr.Td0, "H2": tr.H2, "Tm": tr.Tm}

