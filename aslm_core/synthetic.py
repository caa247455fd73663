"""Synthetic composite loads with known truth: ambient PMU windows, fault events and a live fleet.

Each case is a small network simulated in the time domain::

    infinite bus ──z_s──┐
                        H (hub) ──z_L── L: ZIP + induction motor   (the identified bus)
    generator E'∠δ ─z_g─┘       └──z_N── N: impedance load with 2 Hz low-pass random fluctuation

* The motor at L is the third-order model in its ORIGINAL form (paper eq. 1–3, states Ed, Eq, s;
  parameters X, X', Td0, H2, Tm), seen by the network as E' behind jX'.
* The static load at L is ZIP (eq. 6): the Z part is a shunt admittance, the I and P parts a
  current injection, solved by Newton on V_L at every RK4 stage (below 0.5 pu the I and P parts
  turn into constant impedance, as in PSAT; irrelevant to ambient data).
* The generator is classical (E' behind X'd, swing equation with inertia and damping), so the angle
  and frequency of the hub move; the infinite bus holds the average frequency at f0.
* Ambient excitation comes ONLY from bus N (paper §VI.A): low-pass filtered (2 Hz, 4th-order
  Butterworth) white noise in its conductance and susceptance, generated on the fine-step grid
  (1 kHz) so that V, θ, P, Q are smooth between the PMU samples, as band-limited real signals are.
* RK4 with a fine step (≤ 1 ms by default), started from the steady state of the whole system;
  a warm-up of 5 s is discarded so the record is ambient.  All cases run in one numba kernel
  (parallel over cases).  Network sizes scale with the load, so every case looks alike in relative
  terms: ambient V fluctuation ~0.1–0.45 % (std/mean, 5–95 %), P ~0.1–0.8 %, Q ~0.5–2.5 %, bus
  frequency std ~4–18 mHz, around an electromechanical mode near 1 Hz.
* PMU channels at L: V, θ in the synchronously rotating frame of the infinite bus (ω0 = 2π·f0),
  P + jQ = V_L·conj(I_line) from the current of the feeder z_L (i.e. computed by the network, not
  by the load model, so that output consistency is a real check), f from dθ/dt.

Measurement noise follows the paper's eq. 10 with y the ambient part of the noise-free signal.

Units: powers and impedances in per unit on the 100 MVA system base, voltages in pu, angles in rad,
times in s.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numba as nb
import numpy as np
from scipy import signal

from aslm_core.window import Window

__all__ = [
    "NOISE_LEVELS",
    "LoadTruth",
    "SyntheticCase",
    "SyntheticFleet",
    "disturbance_inputs",
    "large_disturbance",
    "make_case",
    "make_cases",
    "random_truth",
]

#: Mean SNR [dB] (paper eq. 10, mean of P and Q) of the three disturbance levels of Table I.
NOISE_LEVELS: dict[int, float] = {1: 14.0, 2: 22.0, 3: 28.0}
#: Half-width of the uniform spread of the per-case SNR around the level's mean [dB].
SNR_SPREAD_DB: float = 2.0
#: System base [MVA].
SYSTEM_BASE_MVA: float = 100.0
#: Cut-off of the low-pass filter shaping the ambient load fluctuation at bus N [Hz] (paper §VI.A).
FORCING_CUTOFF_HZ: float = 2.0
#: Longest fine integration step [s].
MAX_STEP_S: float = 1e-3
#: Longest step of the grid on which the forcing is generated (linear in between) [s].  Equal to the
#: fine step: a coarser piecewise-linear forcing puts kinks into V between the samples (the network
#: is algebraic), which biased a sample-step identifier by ~0.4 % on noise-free data.
MAX_FORCING_STEP_S: float = 1e-3
#: Cases simulated together in make_cases (bounds the memory of the forcing arrays).
_CHUNK = 64
#: Warm-up simulated and discarded before a record [s].
WARMUP_S: float = 5.0

# Truth sampling ranges: the identification box of params.py with a margin.
_A_RANGE = (15.0, 75.0)
_B_RANGE = (4.0, 28.0)
_H2_RANGE = (0.6, 2.8)
_TM_FRACTION = (0.3, 0.55)  # Tm / breakdown torque a·V²/(2b) at V = 1: < 0.64 keeps one at 0.8 pu
_MOTOR_SHARE = (0.3, 0.7)  # motor share of the total P at V = 1
_XRATIO = (4.0, 12.0)  # X/X' of the motor
_POWER_FACTOR = (0.9, 0.98)
# Sag every truth must ride through (motor alone, rigid voltage, f0 = 60 Hz as the harsher case).
_CHECK_SAG_V = 0.75
_CHECK_SAG_S = 0.15
_PARALLEL_MIN_CASES = 8  # make_cases runs its cases in threads from this many on
_LOW_V = 0.5  # below this the I and P parts of ZIP turn into constant impedance (as in PSAT)


# --------------------------------------------------------------------------------------------
# Truth
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LoadTruth:
    """True composite load of one synthetic bus.

    Attributes
    ----------
    a, b : float
        Transformed motor parameters [1/s] (paper eq. 4): a = (X/X' − 1)/(Td0·X'), b = X/(Td0·X').
    H2 : float
        Inertia constant 2H of the slip equation [s] (on the system base).
    Tm : float
        Mechanical torque [pu on the system base]; equals the motor P in steady state.
    X, Xp, Td0 : float
        Original motor parameters (eq. 1): open-circuit reactance X [pu], transient reactance X' [pu],
        rotor open-circuit time constant Td0 [s].
    Pz, Pi, Pp, Qz, Qi, Qp : float
        True ZIP coefficients of the static part (eq. 6) [pu]; P = Pz·V² + Pi·V + Pp.

    Notes
    -----
    a/b = 1/X' − 1/X and Td0 = (X/X')/b.  The identifier sees the motor through eq. 4–5, which moves
    V²/X' from the motor's Q into the static part (§II.B.2): see :attr:`static_identifiable`.
    """

    a: float
    b: float
    H2: float
    Tm: float
    X: float
    Xp: float
    Td0: float
    Pz: float
    Pi: float
    Pp: float
    Qz: float
    Qi: float
    Qp: float

    @property
    def d(self) -> np.ndarray:
        """D = [a, b, H2, Tm] as identified (paper §V.A)."""
        return np.array([self.a, self.b, self.H2, self.Tm])

    @property
    def dynamic(self) -> dict[str, float]:
        """Motor parameters {a, b, H2, Tm}."""
        return {"a": self.a, "b": self.b, "H2": self.H2, "Tm": self.Tm}

    @property
    def static(self) -> dict[str, float]:
        """True ZIP coefficients {Pz, Pi, Pp, Qz, Qi, Qp} [pu]."""
        return {"Pz": self.Pz, "Pi": self.Pi, "Pp": self.Pp, "Qz": self.Qz, "Qi": self.Qi, "Qp": self.Qp}

    @property
    def static_identifiable(self) -> dict[str, float]:
        """ZIP coefficients an identifier using eq. 4–5 should find: Qz + 1/X' [pu]."""
        st = self.static
        st["Qz"] = self.Qz + 1.0 / self.Xp
        return st

    def slip0(self, V: float = 1.0, f0: float = 50.0) -> float:
        """Steady-state (low) slip at voltage V [pu] and nominal frequency f0 [Hz]."""
        x = _low_root(self.a, self.b, self.Tm, V)
        return float(x / (2.0 * math.pi * f0))

    def power(self, V: float = 1.0) -> tuple[float, float]:
        """Steady-state total P, Q [pu] at voltage V [pu] (motor eq. 3 plus ZIP)."""
        x = _low_root(self.a, self.b, self.Tm, V)
        qm = V * V / self.Xp - self.a * self.b * V * V / (self.b * self.b + x * x)
        p = self.Pz * V * V + self.Pi * V + self.Pp + self.Tm
        q = self.Qz * V * V + self.Qi * V + self.Qp + qm
        return float(p), float(q)

    def to_dict(self) -> dict:
        """Plain dict (JSON-able): physical parameters plus the dynamic/static groupings."""
        out = {k: float(v) for k, v in asdict(self).items()}
        out["dynamic"] = self.dynamic
        out["static"] = self.static
        out["static_identifiable"] = self.static_identifiable
        return out


def _low_root(a: float, b: float, tm: float, v: float) -> float:
    """Low-slip equilibrium x = s·ω0 [rad/s] of eq. 4 at |V| = v (Te(x) = a·V²·x/(b² + x²) = Tm)."""
    av2 = a * v * v
    disc = av2 * av2 - 4.0 * tm * tm * b * b
    if disc < 0.0:
        raise ValueError("no motor equilibrium: a·V² <= 2b·Tm")
    return 2.0 * tm * b * b / (av2 + math.sqrt(disc))  # stable form of (aV² − √disc)/(2Tm)


@nb.njit(cache=True, error_model="numpy")
def _motor_sag_rhs(a, b, h2, tm, w0, v, fd, fq, s):  # pragma: no cover - numba
    """Eq. 4 on a rigid bus V = v∠0 (Vd = v, Vq = 0): Te = −v·Fq."""
    return -b * fd + s * w0 * fq + a * v, -b * fq - s * w0 * fd, (tm + v * fq) / h2


@nb.njit(cache=True, error_model="numpy")
def _motor_sag_response(a, b, h2, tm, w0, v_sag, t_sag, t_end, h):  # pragma: no cover - numba
    """Motor alone (eq. 4) on a rigid bus: 1 pu, sag to v_sag from 0.1 s for t_sag, back to 1 pu.

    Returns (max slip, slip at t_end, steady slip).
    """
    disc = a * a - 4.0 * tm * tm * b * b
    x0 = 2.0 * tm * b * b / (a + math.sqrt(disc))
    fd = a * b / (b * b + x0 * x0)
    fq = -a * x0 / (b * b + x0 * x0)
    s = x0 / w0
    s0 = s
    smax = s
    n = int(t_end / h + 0.5)
    i_on = int(0.1 / h + 0.5)
    i_off = i_on + int(t_sag / h + 0.5)
    for i in range(n):
        v = v_sag if (i >= i_on and i < i_off) else 1.0  # constant over the step
        k1d, k1q, k1s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd, fq, s)
        k2d, k2q, k2s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd + 0.5 * h * k1d, fq + 0.5 * h * k1q,
                                       s + 0.5 * h * k1s)
        k3d, k3q, k3s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd + 0.5 * h * k2d, fq + 0.5 * h * k2q,
                                       s + 0.5 * h * k2s)
        k4d, k4q, k4s = _motor_sag_rhs(a, b, h2, tm, w0, v, fd + h * k3d, fq + h * k3q, s + h * k3s)
        fd += h / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d)
        fq += h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        s += h / 6.0 * (k1s + 2.0 * k2s + 2.0 * k3s + k4s)
        smax = max(smax, s)
        if s > 1.0:
            break
    return smax, s, s0


def random_truth(rng: np.random.Generator) -> LoadTruth:
    """Draw a stable composite load inside the identification box (with a margin).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness (the result is a deterministic function of its state).

    Returns
    -------
    LoadTruth

    Notes
    -----
    a ~ U[15, 75], b ~ U[4, 28], H2 ~ U[0.6, 2.8] [s]; Tm = k·a/(2b) with k ~ U[0.3, 0.55], i.e. a
    fraction of the breakdown torque a·V²/(2b) at 1 pu that still leaves an equilibrium at 0.8 pu
    (k < 0.64).  A draw is rejected unless the motor, alone on a rigid bus, rides through a sag to
    0.75 pu for 150 ms at 60 Hz (slip back to its steady value, max slip < 0.15).  This guard
    against a stalling truth practically never fires with these ranges (the steep torque–slip
    curve below breakdown recovers the motor: max slip ~0.04), so a, b, H2, k are in effect
    independent uniforms.  X/X' ~ U[4, 12] then gives X = (X/X' − 1)·b/a, X' = X/(X/X'), Td0 = (X/X')/b.
    The static P at 1 pu makes the motor share of P ~ U[0.3, 0.7]; the total Q at 1 pu gives a
    power factor ~ U[0.9, 0.98] (lagging), so the static Q is often capacitive (negative).
    ZIP shares are uniform on the simplex.  Because Tm ≤ 0.55·a/(2b) [pu] (physics of eq. 4:
    the breakdown torque is a·V²/(2b)), Tm spans ~0.1–3.6 pu and the total P at 1 pu ~0.2–10 pu
    (median ~1.2 pu); the paper's printed examples (e.g. Tm = 7.33 with a/b = 2.25) are not on
    this scale and would violate a·V² > 2b·Tm.
    """
    w0_check = 2.0 * math.pi * 60.0
    for _ in range(1000):
        a = rng.uniform(*_A_RANGE)
        b = rng.uniform(*_B_RANGE)
        h2 = rng.uniform(*_H2_RANGE)
        k = rng.uniform(*_TM_FRACTION)
        tm = k * a / (2.0 * b)
        smax, s_end, s0 = _motor_sag_response(a, b, h2, tm, w0_check, _CHECK_SAG_V, _CHECK_SAG_S, 2.5, 1e-3)
        if smax < 0.15 and abs(s_end - s0) < 0.05 * s0 + 1e-4:
            break
    else:  # pragma: no cover - practically unreachable
        raise RuntimeError("random_truth: no stable draw in 1000 tries")
    r = rng.uniform(*_XRATIO)
    x = (r - 1.0) * b / a
    xp = x / r
    td0 = r / b
    share = rng.uniform(*_MOTOR_SHARE)
    p_static = tm * (1.0 - share) / share
    zp = rng.dirichlet(np.ones(3))
    pf = rng.uniform(*_POWER_FACTOR)
    p_tot = p_static + tm
    x0 = _low_root(a, b, tm, 1.0)
    q_motor = 1.0 / xp - a * b / (b * b + x0 * x0)
    q_static = p_tot * math.tan(math.acos(pf)) - q_motor
    zq = rng.dirichlet(np.ones(3))
    return LoadTruth(
        a=float(a), b=float(b), H2=float(h2), Tm=float(tm), X=float(x), Xp=float(xp), Td0=float(td0),
        Pz=float(p_static * zp[0]), Pi=float(p_static * zp[1]), Pp=float(p_static * zp[2]),
        Qz=float(q_static * zq[0]), Qi=float(q_static * zq[1]), Qp=float(q_static * zq[2]),
    )


# --------------------------------------------------------------------------------------------
# Network parameter vector (one row per case) and the numba kernels
# --------------------------------------------------------------------------------------------

# Motor (original form, eq. 1) and ZIP
_BM, _CM, _XP, _H2, _TM = 0, 1, 2, 3, 4  # b = X/(Td0 X'), c = (X/X' - 1)/Td0
_PZ, _PI, _PP, _QZ, _QI, _QP = 5, 6, 7, 8, 9, 10
# Network: complex quantities as (re, im)
_VS, _ZS, _ZG, _ZL, _ZN = 11, 13, 15, 17, 19
_PN, _QN = 21, 22  # nominal load of bus N as admittance G - jB at 1 pu [pu]
_EG, _PM, _HG2, _DG, _W0 = 23, 24, 25, 26, 27  # |E'g|, mech. power, 2H and damping (system base), ω0
_YF = 28  # fault admittance at H (re, im)
_NPAR = 30
_NX = 5  # states: δ [rad], Δω [pu], Ed, Eq [pu], s [-]


# Per-case complex constants of the network (computed once per case by _consts)
_C_YH0, _C_IS, _C_YG, _C_ZL, _C_YL, _C_ZN, _C_YLD, _C_YM, _C_YF = range(9)
_NC = 9


@nb.njit(cache=True, error_model="numpy", inline="always")
def _inv(z):  # pragma: no cover - numba
    """1/z without numba's guarded complex division (z is never 0 here)."""
    r = 1.0 / (z.real * z.real + z.imag * z.imag)
    return complex(z.real * r, -z.imag * r)


@nb.njit(cache=True, error_model="numpy")
def _consts(p):  # pragma: no cover - numba
    """Complex constants of one case: admittances and source currents that do not change in time."""
    c = np.empty(_NC, dtype=np.complex128)
    zs = complex(p[_ZS], p[_ZS + 1])
    zg = complex(p[_ZG], p[_ZG + 1])
    zl = complex(p[_ZL], p[_ZL + 1])
    c[_C_YH0] = 1.0 / zs + 1.0 / zg
    c[_C_IS] = complex(p[_VS], p[_VS + 1]) / zs
    c[_C_YG] = 1.0 / zg
    c[_C_ZL] = zl
    c[_C_YL] = 1.0 / zl
    c[_C_ZN] = complex(p[_ZN], p[_ZN + 1])
    c[_C_YM] = 1.0 / complex(0.0, p[_XP])  # motor: E' behind jX'
    c[_C_YLD] = complex(p[_PZ], -p[_QZ]) + c[_C_YM]  # ZIP Z part + motor X' as a shunt
    c[_C_YF] = complex(p[_YF], p[_YF + 1])
    return c


@nb.njit(cache=True, error_model="numpy")
def _thevenin(p, c, dpn, dqn, fault):  # pragma: no cover - numba
    """Network seen from L at one instant, without the sources (they move with the states).

    Returns Y_H (hub self-admittance), k = Z_H/(Z_H + z_L) (source-current to Thevenin-current
    factor) and Y_th = 1/(Z_H + z_L), with the fluctuation (dpn, dqn) of bus N's admittance.
    """
    yn = complex(p[_PN] + dpn, -(p[_QN] + dqn))
    yh = c[_C_YH0] + yn * _inv(1.0 + c[_C_ZN] * yn)  # N: its feeder and load in series
    if fault:
        yh += c[_C_YF]
    zhh = _inv(yh)
    yth = _inv(zhh + c[_C_ZL])
    return yh, zhh * yth, yth


@nb.njit(cache=True, error_model="numpy")
def _network(p, c, yh, kth, yth, x, vl):  # pragma: no cover - numba
    """Algebraic network at one instant, given its Thevenin part (:func:`_thevenin`) and the states.

    Returns V_L, V_H, the feeder current I_line flowing from H into L (all complex, sync frame) and
    the generator EMF E'g.  The ZIP I and P parts make the L node nonlinear: Newton on V_L (a 2-D
    real problem written with dV and conj(dV)) from the guess vl, quadratically convergent, 2
    iterations from the previous stage's value.
    """
    eg = p[_EG] * complex(math.cos(x[0]), math.sin(x[0]))
    ih = c[_C_IS] + eg * c[_C_YG]
    num = ih * kth + complex(x[2], x[3]) * c[_C_YM]
    den = yth + c[_C_YLD]
    v = vl
    pi, pp, qi, qp = p[_PI], p[_PP], p[_QI], p[_QP]
    for _ in range(30):
        m = abs(v)
        if m >= _LOW_V:
            s = complex(pi * m + pp, qi * m + qp)
            ds = complex(pi, qi)
        else:  # constant impedance below _LOW_V, continuous at _LOW_V
            s0 = complex(pi * _LOW_V + pp, qi * _LOW_V + qp)
            s = s0 * (m / _LOW_V) ** 2
            ds = s0 * (2.0 * m / (_LOW_V * _LOW_V))
        w = _inv(v.conjugate())
        f = den * v - num + s.conjugate() * w
        # dI = al·dV + be·conj(dV), from d|V| = Re(conj(V)·dV)/|V|
        al = den + ds.conjugate() / (2.0 * m)
        be = ds.conjugate() * v * w / (2.0 * m) - s.conjugate() * w * w
        dv = (-f * al.conjugate() + be * f.conjugate()) / (al.real * al.real + al.imag * al.imag
                                                           - be.real * be.real - be.imag * be.imag)
        v += dv
        if abs(dv) < 1e-9:  # quadratic convergence: the error left is ~|dv|² < 1e-17
            break
    vh = (ih + v * c[_C_YL]) * _inv(yh + c[_C_YL])
    return v, vh, (vh - v) * c[_C_YL], eg


@nb.njit(cache=True, error_model="numpy")
def _rhs(p, c, yh, kth, yth, x, vl, dx):  # pragma: no cover - numba
    """State derivatives (filled into dx); returns V_L, V_H, I_line as :func:`_network`.

    Motor in the original form, eq. 1–2; classical generator swing equation.
    """
    v, vh, il, eg = _network(p, c, yh, kth, yth, x, vl)
    w0 = p[_W0]
    bm = p[_BM]
    cm = p[_CM]
    ed = x[2]
    eq = x[3]
    s = x[4]
    vd = v.real
    vq = v.imag
    dx[2] = -bm * ed + s * w0 * eq + cm * vd
    dx[3] = -bm * eq - s * w0 * ed + cm * vq
    te = (ed * vq - eq * vd) / p[_XP]
    dx[4] = (p[_TM] - te) / p[_H2]
    pe = (eg * ((eg - vh) * c[_C_YG]).conjugate()).real
    dx[0] = w0 * x[1]
    dx[1] = (p[_PM] - pe - p[_DG] * x[1]) / p[_HG2]
    return v, vh, il


@nb.njit(cache=True, error_model="numpy")
def _solve_at(p, x, dpn, dqn, fault, vl):  # pragma: no cover - numba
    """One-off network solve and derivatives (for set-up and tests): (V_L, V_H, I_line, dx)."""
    c = _consts(p)
    yh, kth, yth = _thevenin(p, c, dpn, dqn, fault)
    dx = np.empty(_NX)
    v, vh, il = _rhs(p, c, yh, kth, yth, x, vl, dx)
    return v, vh, il, dx


@nb.njit(cache=True, error_model="numpy")
def _integrate_case(c, par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps,
                    out_v, out_s, out_x, x_end, vl_end):  # pragma: no cover - numba
    """RK4 integration of case c over n_int forcing intervals; fills row c of the outputs."""
    p = par[c]
    cst = _consts(p)
    x = x0[c].copy()
    vl = vl0[c]
    k1 = np.empty(_NX)
    k2 = np.empty(_NX)
    k3 = np.empty(_NX)
    k4 = np.empty(_NX)
    xt = np.empty(_NX)
    step = 0
    on_step = fault_steps[c, 0]
    off_step = fault_steps[c, 1]
    prev_fault = False
    tb = _thevenin(p, cst, forcing[c, 0, 0], forcing[c, 1, 0], False)
    for j in range(n_int):
        fp0 = forcing[c, 0, j]
        fq0 = forcing[c, 1, j]
        dfp = forcing[c, 0, j + 1] - fp0
        dfq = forcing[c, 1, j + 1] - fq0
        for k in range(k_sub):
            fault = step >= on_step and step < off_step
            wm = (k + 0.5) / k_sub
            wb = (k + 1.0) / k_sub
            # The forcing is continuous, so the end of a step is the start of the next one.
            if fault != prev_fault:
                wa = k / k_sub
                ta = _thevenin(p, cst, fp0 + wa * dfp, fq0 + wa * dfq, fault)
            else:
                ta = tb
            tm_ = _thevenin(p, cst, fp0 + wm * dfp, fq0 + wm * dfq, fault)
            tb = _thevenin(p, cst, fp0 + wb * dfp, fq0 + wb * dfq, fault)
            prev_fault = fault
            vl, vh, il = _rhs(p, cst, ta[0], ta[1], ta[2], x, vl, k1)
            if k == 0 and j % m_per_sample == 0:
                r = j // m_per_sample - n_skip
                if r >= 0:
                    out_v[c, r] = vl
                    out_s[c, r] = vl * il.conjugate()
                    for i in range(_NX):
                        out_x[c, i, r] = x[i]
            for i in range(_NX):
                xt[i] = x[i] + 0.5 * h * k1[i]
            v2, _, _ = _rhs(p, cst, tm_[0], tm_[1], tm_[2], xt, vl, k2)
            for i in range(_NX):
                xt[i] = x[i] + 0.5 * h * k2[i]
            v3, _, _ = _rhs(p, cst, tm_[0], tm_[1], tm_[2], xt, v2, k3)
            for i in range(_NX):
                xt[i] = x[i] + h * k3[i]
            v4, _, _ = _rhs(p, cst, tb[0], tb[1], tb[2], xt, v3, k4)
            for i in range(_NX):
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            vl = v4
            step += 1
    for i in range(_NX):
        x_end[c, i] = x[i]
    vl_end[c] = vl


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _simulate(par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_rec, fault_steps):  # pragma: no cover
    """Integrate all cases with RK4 and record the PMU channels.

    Cases run in parallel threads (numba prange).

    Parameters
    ----------
    par : (nc, _NPAR) case parameters;  x0 : (nc, 5) initial states;  vl0 : (nc,) complex V_L guess.
    forcing : (nc, 2, n_int + 1) ΔG, ΔB of bus N on the forcing grid (linear in between) [pu].
    h : fine step [s];  k_sub : fine steps per forcing interval;  m_per_sample : forcing intervals
    per sample;  n_skip : samples of warm-up not recorded;  n_rec : samples recorded.
    fault_steps : (nc, 2) int, fine-step index where the fault at H starts and ends (-1: none).

    Returns
    -------
    vl : (nc, n_rec) complex V_L;  sl : (nc, n_rec) complex P + jQ from the feeder current;
    xs : (nc, 5, n_rec) states at the samples;  x_end : (nc, 5);  vl_end : (nc,) complex —
    the state one sample period after the last record (to continue a stream).
    """
    nc = par.shape[0]
    n_int = (n_skip + n_rec) * m_per_sample
    out_v = np.empty((nc, n_rec), dtype=np.complex128)
    out_s = np.empty((nc, n_rec), dtype=np.complex128)
    out_x = np.empty((nc, _NX, n_rec))
    x_end = np.empty((nc, _NX))
    vl_end = np.empty(nc, dtype=np.complex128)
    for c in nb.prange(nc):
        _integrate_case(c, par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps,
                        out_v, out_s, out_x, x_end, vl_end)
    return out_v, out_s, out_x, x_end, vl_end


@nb.njit(cache=True, error_model="numpy")
def _simulate_serial(par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_rec, fault_steps):  # pragma: no cover
    """:func:`_simulate` in the calling thread (the fleet: no thread hand-off per frame, one core at most)."""
    nc = par.shape[0]
    n_int = (n_skip + n_rec) * m_per_sample
    out_v = np.empty((nc, n_rec), dtype=np.complex128)
    out_s = np.empty((nc, n_rec), dtype=np.complex128)
    out_x = np.empty((nc, _NX, n_rec))
    x_end = np.empty((nc, _NX))
    vl_end = np.empty(nc, dtype=np.complex128)
    for c in range(nc):
        _integrate_case(c, par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps,
                        out_v, out_s, out_x, x_end, vl_end)
    return out_v, out_s, out_x, x_end, vl_end


# --------------------------------------------------------------------------------------------
# Case set-up: network draw and steady state of the whole system
# --------------------------------------------------------------------------------------------


def _static_load(tr: LoadTruth, v: np.ndarray) -> np.ndarray:
    """Steady-state complex power of the whole load at |V| = v (motor at its low-slip root) [pu]."""
    x = np.array([_low_root(tr.a, tr.b, tr.Tm, float(vv)) for vv in np.atleast_1d(v)])
    qm = v * v / tr.Xp - tr.a * tr.b * v * v / (tr.b * tr.b + x * x)
    p = tr.Pz * v * v + tr.Pi * v + tr.Pp + tr.Tm
    q = tr.Qz * v * v + tr.Qi * v + tr.Qp + qm
    return p + 1j * q


def _draw_network(rng: np.random.Generator, tr: LoadTruth, f0: float) -> dict:
    """Random network around the load (sizes scale with the load so every case looks alike).

    Returns a dict of scalars (see the module docstring for the topology).
    """
    p_l, q_l = tr.power(1.0)
    p_n = p_l * rng.uniform(0.5, 2.0)
    q_n = p_n * math.tan(math.acos(rng.uniform(0.9, 0.98)))
    s_tot = p_l + p_n
    s_g = s_tot * rng.uniform(0.8, 1.5)  # generator rating [pu]
    zl = (rng.uniform(0.1, 0.3) + 1j) * rng.uniform(0.02, 0.05) / p_l
    zn = (rng.uniform(0.1, 0.3) + 1j) * rng.uniform(0.02, 0.05) / p_n
    zg = 1j * (rng.uniform(0.25, 0.35) + 0.12) / s_g  # X'd + step-up transformer
    zs = (0.1 + 1j) / (rng.uniform(3.0, 8.0) * s_tot)  # rest of the grid: short-circuit ratio 3–8
    return {
        "V_L": rng.uniform(0.97, 1.03),  # target operating voltage at L [pu]
        "P_N": p_n, "Q_N": q_n,
        "z_L": zl, "z_N": zn, "z_g": zg, "z_s": zs,
        "S_g": s_g, "P_g": s_tot * rng.uniform(0.4, 0.7),
        "H_g": rng.uniform(3.0, 7.0),  # [s] on the generator rating
        "zeta": rng.uniform(0.05, 0.15),  # damping ratio of the electromechanical mode
        "sigma_P": rng.uniform(0.04, 0.12),  # std of the conductance fluctuation at N, × P_N
        "sigma_Q": rng.uniform(0.02, 0.06),  # std of the susceptance fluctuation at N, × P_N
        "f0": f0,
    }


def _steady_state(tr: LoadTruth, net: dict) -> tuple[np.ndarray, np.ndarray, complex]:
    """Parameter row, initial state and V_L of the steady state of the whole system.

    |V_L| is the drawn target and fixes V_H through the feeder drop; the common angle is then set
    so that the generator delivers P_g (the infinite bus at 1∠0 supplies the rest).  Both leaves
    (L, N) have rotation-invariant loads, so the magnitude and angle problems decouple.
    """
    zl, zn, zg, zs = net["z_L"], net["z_N"], net["z_g"], net["z_s"]
    yn = net["P_N"] - 1j * net["Q_N"]
    w0 = 2.0 * math.pi * net["f0"]

    # The load is rotation-invariant: fix V_L = target∠0, get V_H from the feeder drop, rotate later.
    vl = complex(net["V_L"])
    s_l = complex(_static_load(tr, np.array([net["V_L"]]))[0])
    vh = vl + zl * (s_l / vl).conjugate()
    i_out = (vh - vl) / zl + vh / (zn + 1.0 / yn)
    p_out = (vh * np.conj(i_out)).real
    p_s_target = p_out - net["P_g"]  # from the infinite bus into H

    def p_s(phi: float) -> float:
        v = vh * np.exp(1j * phi)
        return float((v * np.conj((1.0 - v) / zs)).real)

    phi = 0.0
    for _ in range(100):  # Newton with a numerical derivative; smooth and monotonic near 0
        f = p_s(phi) - p_s_target
        dfd = (p_s(phi + 1e-7) - p_s(phi - 1e-7)) / 2e-7
        step = f / dfd
        phi -= step
        if abs(step) < 1e-14:
            break
    rot = np.exp(1j * phi)
    vh_c, vl_c = vh * rot, vl * rot
    i_s = (1.0 - vh_c) / zs
    i_g = i_out * rot - i_s
    eg = vh_c + zg * i_g
    pm = float((eg * np.conj(i_g)).real)
    # Damping giving the drawn damping ratio on the mode of the machine against the infinite bus.
    hg2 = 2.0 * net["H_g"] * net["S_g"]
    k_sync = abs(eg) * 1.0 * math.cos(np.angle(eg)) / abs(zg + zs)
    wn = math.sqrt(w0 * k_sync / hg2)
    dg = 2.0 * net["zeta"] * wn * hg2
    # Motor at its low-slip root (eq. 1 with d/dt = 0): E = X'·a·V/(b + j·x), x = s·ω0.
    x_m = _low_root(tr.a, tr.b, tr.Tm, abs(vl_c))
    e_m = tr.Xp * tr.a * vl_c / (tr.b + 1j * x_m)
    p = np.zeros(_NPAR)
    p[_BM] = tr.X / (tr.Td0 * tr.Xp)
    p[_CM] = (tr.X / tr.Xp - 1.0) / tr.Td0
    p[_XP], p[_H2], p[_TM] = tr.Xp, tr.H2, tr.Tm
    p[_PZ], p[_PI], p[_PP], p[_QZ], p[_QI], p[_QP] = tr.Pz, tr.Pi, tr.Pp, tr.Qz, tr.Qi, tr.Qp
    p[_VS], p[_VS + 1] = 1.0, 0.0
    for idx, z in ((_ZS, zs), (_ZG, zg), (_ZL, zl), (_ZN, zn)):
        p[idx], p[idx + 1] = z.real, z.imag
    p[_PN], p[_QN] = net["P_N"], net["Q_N"]
    p[_EG], p[_PM], p[_HG2], p[_DG], p[_W0] = abs(eg), pm, hg2, dg, w0
    x0 = np.array([np.angle(eg), 0.0, e_m.real, e_m.imag, x_m / w0])
    return p, x0, complex(vl_c)


def _plain(net: dict) -> dict:
    """JSON-friendly copy of a network draw: complex impedances as [re, im]."""
    return {k: ([v.real, v.imag] if isinstance(v, complex) else float(v)) for k, v in net.items()}


def _forcing_filter(fs_forcing: float) -> tuple[np.ndarray, float]:
    """4th-order Butterworth low-pass at 2 Hz and the gain that makes its output unit-variance."""
    sos = signal.butter(4, FORCING_CUTOFF_HZ, fs=fs_forcing, output="sos")
    imp = np.zeros(int(40 * fs_forcing))
    imp[0] = 1.0
    gain = 1.0 / math.sqrt(float(np.sum(signal.sosfilt(sos, imp) ** 2)))
    return sos, gain


def _grid(fs: float, max_step: float, max_forcing_step: float) -> tuple[int, int, float]:
    """Forcing intervals per sample m, fine steps per forcing interval k, and the fine step h [s]."""
    ts = 1.0 / fs
    m = max(1, math.ceil(ts / max_forcing_step - 1e-9))
    k = max(1, math.ceil(ts / m / max_step - 1e-9))
    return m, k, ts / m / k


# --------------------------------------------------------------------------------------------
# Measurement noise (eq. 10)
# --------------------------------------------------------------------------------------------


def _ambient(y: np.ndarray, detrend: bool = False) -> np.ndarray:
    """Ambient part of a record: minus its mean (and linear trend for θ)."""
    if detrend:
        t = np.arange(y.shape[-1], dtype=float)
        coef = np.polyfit(t, y, 1)
        return y - np.polyval(coef, t)
    return y - y.mean()


def channel_snr_db(clean: np.ndarray, noisy: np.ndarray, *, detrend: bool = False) -> float:
    """SNR of a channel per eq. 10 [dB], y = ambient part of the clean signal, e = noisy − clean."""
    y = _ambient(np.asarray(clean, float), detrend)
    e = np.asarray(noisy, float) - np.asarray(clean, float)
    return float(10.0 * np.log10(np.sum(y * y) / np.sum(e * e)))


def _sigma_for(y_amb_rms: float, snr: float) -> float:
    """Noise std giving an expected SNR of snr [dB] for an ambient part of rms y_amb_rms."""
    return float(y_amb_rms * 10.0 ** (-snr / 20.0))


# --------------------------------------------------------------------------------------------
# Public: cases
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SyntheticCase:
    """One synthetic load-modelling case.

    Attributes
    ----------
    window : Window
        What a PMU gives: V [pu], θ [rad], P, Q [pu], f [Hz] with measurement noise (== clean when
        noise-free).
    clean : Window
        The same without noise.  ``clean.meta`` holds the network draw and the case's SNR target.
    truth : LoadTruth
        The load that produced the record.
    snr_db : float
        Achieved SNR of the case (mean of the SNR of P and of Q, eq. 10) [dB]; inf when noise-free.
    level : int or None
        Disturbance level of NOISE_LEVELS, if the case was made by level.
    states : dict
        Noise-free internals at the samples: ``Ed``, ``Eq`` [pu], ``s`` [-] (eq. 1 states),
        ``P_motor``, ``Q_motor`` (eq. 3), ``P_static``, ``Q_static`` (eq. 6) [pu], and ``snr``:
        the achieved SNR per channel [dB].
    """

    window: Window
    clean: Window
    truth: LoadTruth
    snr_db: float
    level: int | None
    states: dict = field(default_factory=dict, compare=False, repr=False)


def _motor_and_static(tr: LoadTruth, vl: np.ndarray, xs: np.ndarray) -> dict[str, np.ndarray]:
    """Motor (eq. 3) and ZIP (eq. 6) powers from the recorded V_L and states."""
    vd, vq = vl.real, vl.imag
    ed, eq = xs[..., 2, :], xs[..., 3, :]
    v = np.abs(vl)
    return {
        "Ed": ed, "Eq": eq, "s": xs[..., 4, :],
        "P_motor": (ed * vq - eq * vd) / tr.Xp,
        "Q_motor": (v * v - vd * ed - vq * eq) / tr.Xp,
        "P_static": tr.Pz * v * v + tr.Pi * v + tr.Pp,
        "Q_static": tr.Qz * v * v + tr.Qi * v + tr.Qp,
    }


def _bus_frequency(theta: np.ndarray, fs: float, f0: float) -> np.ndarray:
    """Bus frequency f0 + (dθ/dt)/2π from the sampled angle (2nd-order differences) [Hz]."""
    return f0 + np.gradient(theta, 1.0 / fs, axis=-1) / (2.0 * math.pi)


def _target_snr(rng: np.random.Generator, level: int | None, snr: float | None) -> float | None:
    if level is not None and snr is not None:
        raise ValueError("give level or snr_db, not both")
    if level is not None:
        if level not in NOISE_LEVELS:
            raise ValueError(f"level must be one of {sorted(NOISE_LEVELS)}")
        return NOISE_LEVELS[level] + rng.uniform(-SNR_SPREAD_DB, SNR_SPREAD_DB)
    return snr


def make_cases(
    n: int,
    *,
    level: int | None = None,
    snr_db: float | None = None,
    seed: int = 0,
    duration_s: float = 10.0,
    fs: float = 100.0,
    f0: float = 50.0,
    input_noise: bool = True,
) -> list[SyntheticCase]:
    """Simulate n ambient cases with known truth.

    Parameters
    ----------
    n : int
        Number of cases.
    level : int, optional
        Disturbance level (key of NOISE_LEVELS): per-case SNR target ~ U[mean ± 2 dB].
    snr_db : float, optional
        Fixed SNR target [dB] for every case (instead of level).  Neither: noise-free.
    seed : int
        Case i depends only on (seed, i): the truth, the network and the ambient excitation come from
        streams independent of the noise, so the same seed at different levels gives the same clean
        records.
    duration_s : float
        Length of the record after the warm-up [s]; n_samples = round(duration_s·fs).
    fs : float
        Sample rate [Hz].
    f0 : float
        Nominal frequency [Hz] (ω0 = 2π·f0).
    input_noise : bool
        Add noise to V, θ and f too (same SNR rule per channel); False: noise on P and Q only.

    Returns
    -------
    list of SyntheticCase
        Windows start at t = 0 [s].

    Notes
    -----
    SNR per eq. 10 with y the ambient part (minus the mean; θ also minus a linear trend) of the
    noise-free channel; the noise std of each channel is set so that the expected SNR equals the
    target, so the achieved value scatters by ~±0.3 dB around it.
    """
    n_samp = int(round(duration_s * fs))
    n_skip = int(round(WARMUP_S * fs))
    m, k, h = _grid(fs, MAX_STEP_S, MAX_FORCING_STEP_S)
    sos, gain = _forcing_filter(fs * m)
    n_int = (n_skip + n_samp) * m

    cases: list[SyntheticCase] = []
    children = np.random.SeedSequence(seed).spawn(n)
    for c0 in range(0, n, _CHUNK):
        cases.extend(_make_chunk(children[c0:c0 + _CHUNK], c0, sos, gain, m, k, h, n_skip, n_samp, n_int,
                                 level, snr_db, seed, fs, f0, input_noise))
    return cases


def _make_chunk(children: list, c0: int, sos: np.ndarray, gain: float, m: int, k: int, h: float,
                n_skip: int, n_samp: int, n_int: int, level: int | None, snr_db: float | None, seed: int,
                fs: float, f0: float, input_noise: bool) -> list[SyntheticCase]:
    """Simulate and post-process one chunk of :func:`make_cases` (cases c0, c0 + 1, ...)."""
    n = len(children)
    truths, nets, rows, x0s, vl0s, noise_rngs = [], [], [], [], [], []
    forcing = np.zeros((n, 2, n_int + 1))
    for i, ss in enumerate(children):
        s_truth, s_net, s_noise = ss.spawn(3)
        tr = random_truth(np.random.default_rng(s_truth))
        rng_net = np.random.default_rng(s_net)
        net = _draw_network(rng_net, tr, f0)
        p, x0, vl0 = _steady_state(tr, net)
        w = rng_net.standard_normal((2, n_int))
        # Zero first value: the system starts at its steady state with no fluctuation.
        forcing[i, 0, 1:] = net["sigma_P"] * net["P_N"] * gain * signal.sosfilt(sos, w[0])
        forcing[i, 1, 1:] = net["sigma_Q"] * net["P_N"] * gain * signal.sosfilt(sos, w[1])
        truths.append(tr)
        nets.append(net)
        rows.append(p)
        x0s.append(x0)
        vl0s.append(vl0)
        noise_rngs.append(np.random.default_rng(s_noise))
    par = np.array(rows).reshape(n, _NPAR)
    faults = -np.ones((n, 2), dtype=np.int64)
    # Threads only pay off for a batch (and the parallel kernel costs its own compilation).
    kernel = _simulate if n >= _PARALLEL_MIN_CASES else _simulate_serial
    out_v, out_s, out_x, _, _ = kernel(
        par, np.array(x0s).reshape(n, _NX), np.array(vl0s, dtype=complex), forcing,
        h, k, m, n_skip, n_samp, faults,
    )
    del forcing
    t = np.arange(n_samp) / fs
    cases = []
    for i in range(n):
        tr, net = truths[i], nets[i]
        v = np.abs(out_v[i])
        th = np.unwrap(np.angle(out_v[i]))
        fr = _bus_frequency(th, fs, f0)
        pc, qc = out_s[i].real, out_s[i].imag
        rng = noise_rngs[i]
        target = _target_snr(rng, level, snr_db)
        meta = {
            "source": "synthetic", "seed": seed, "case": c0 + i, "snr_target_db": target,
            "network": _plain(net),
            "step_s": h,
        }
        clean = Window(t=t, V=v, theta=th, P=pc, Q=qc, f=fr, f0=f0, bus=f"syn{c0 + i:04d}", meta=meta)
        states = _motor_and_static(tr, out_v[i], out_x[i])
        if target is None:
            noisy, achieved, per = clean, float("inf"), {}
        else:
            chans = {"P": (pc, False), "Q": (qc, False)}
            if input_noise:
                chans.update({"V": (v, False), "theta": (th, True), "f": (fr, False)})
            noisy_ch = {"V": v, "theta": th, "P": pc, "Q": qc, "f": fr}
            per = {}
            for name in ("P", "Q", "V", "theta", "f"):  # fixed order: deterministic draws
                if name not in chans:
                    continue
                y, detr = chans[name]
                amb = _ambient(y, detr)
                sig = _sigma_for(float(np.sqrt(np.mean(amb * amb))), target)
                noisy_ch[name] = y + sig * rng.standard_normal(y.shape)
                per[name] = channel_snr_db(y, noisy_ch[name], detrend=detr)
            achieved = 0.5 * (per["P"] + per["Q"])
            noisy = Window(
                t=t, V=noisy_ch["V"], theta=noisy_ch["theta"], P=noisy_ch["P"], Q=noisy_ch["Q"],
                f=noisy_ch["f"], f0=f0, bus=clean.bus, meta=meta,
            )
        states["snr"] = per
        cases.append(SyntheticCase(window=noisy, clean=clean, truth=tr, snr_db=achieved, level=level,
                                   states=states))
    return cases


def make_case(seed: int, **kw) -> SyntheticCase:
    """One case: ``make_cases(1, seed=seed, **kw)[0]``."""
    return make_cases(1, seed=seed, **kw)[0]


# --------------------------------------------------------------------------------------------
# Public: large disturbance
# --------------------------------------------------------------------------------------------


def _fault_admittance(p: np.ndarray, x0: np.ndarray, vl0: complex, sag_depth: float) -> complex:
    """Shunt admittance at H that makes |V_L| drop to (1 − sag_depth)·|V_L0| at fault inception."""
    zs, zg, zn = _cplx_py(p, _ZS), _cplx_py(p, _ZG), _cplx_py(p, _ZN)
    yn = p[_PN] - 1j * p[_QN]
    z_th = 1.0 / (1.0 / zs + 1.0 / zg + 1.0 / (zn + 1.0 / yn))
    y_unit = 1.0 / z_th  # same angle as the Thevenin admittance: a real voltage ratio on no load
    target = (1.0 - sag_depth) * abs(vl0)

    def v_at(kappa: float) -> float:
        q = p.copy()
        yf = kappa * y_unit
        q[_YF], q[_YF + 1] = yf.real, yf.imag
        v, _, _, _ = _solve_at(q, x0, 0.0, 0.0, True, vl0)
        return abs(v)

    k_lo, k_hi = 0.0, sag_depth / (1.0 - sag_depth)
    while v_at(k_hi) > target:
        k_hi *= 2.0
    for _ in range(60):  # bisection: |V_L| decreases monotonically with the fault admittance
        k_mid = 0.5 * (k_lo + k_hi)
        if v_at(k_mid) > target:
            k_lo = k_mid
        else:
            k_hi = k_mid
    return complex(0.5 * (k_lo + k_hi) * y_unit)


def _cplx_py(p: np.ndarray, i: int) -> complex:
    return complex(p[i], p[i + 1])


def large_disturbance(
    truth: LoadTruth,
    *,
    seed: int = 0,
    fs: float = 100.0,
    f0: float = 50.0,
    sag_depth: float = 0.2,
    duration_s: float = 5.0,
    fault_start_s: float = 1.0,
    fault_duration_s: float = 0.1,
) -> Window:
    """Noise-free response of the TRUE load to a temporary fault (paper §VI.B.1.b, Table II).

    Parameters
    ----------
    truth : LoadTruth
        The load at bus L.
    seed : int
        Seed of the network draw around the load.
    fs : float
        Sample rate [Hz].
    f0 : float
        Nominal frequency [Hz].
    sag_depth : float
        Voltage drop at L at fault inception, as a fraction of the pre-fault |V_L| [-].
    duration_s : float
        Record length [s], starting from the pre-fault steady state.
    fault_start_s, fault_duration_s : float
        Fault application time and duration [s] (rounded to the fine step).

    Returns
    -------
    Window
        V [pu], θ [rad], P, Q [pu] (from the feeder current), f [Hz] at L; ``meta`` has the fault
        admittance, the times and the states (``Ed``, ``Eq``, ``s``, ``P_motor``...).

    Notes
    -----
    The fault is a shunt admittance at the hub H with the angle of the hub's Thevenin admittance,
    scaled by bisection so |V_L| drops by sag_depth at inception (the motor's E' is frozen then).
    No ambient fluctuation is applied.  Play an identified model back on (V, θ) and compare P, Q by
    the fitting degree FD, eq. 9.
    """
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x1D]))
    net = _draw_network(rng, truth, f0)
    p, x0, vl0 = _steady_state(truth, net)
    yf = _fault_admittance(p, x0, vl0, sag_depth)
    p[_YF], p[_YF + 1] = yf.real, yf.imag
    n_samp = int(round(duration_s * fs))
    m, k, h = _grid(fs, MAX_STEP_S, MAX_STEP_S)
    on = int(round(fault_start_s / h))
    off = on + max(1, int(round(fault_duration_s / h)))
    forcing = np.zeros((1, 2, n_samp * m + 1))
    out_v, out_s, out_x, _, _ = _simulate_serial(
        p[None, :], x0[None, :], np.array([vl0]), forcing, h, k, m, 0, n_samp,
        np.array([[on, off]], dtype=np.int64),
    )
    vl = out_v[0]
    th = np.unwrap(np.angle(vl))
    states = _motor_and_static(truth, vl, out_x[0])
    meta = {
        "source": "synthetic-fault", "seed": seed, "sag_depth": sag_depth,
        "fault_admittance": [yf.real, yf.imag], "fault_start_s": on * h, "fault_end_s": off * h, "states": states,
    }
    return Window(
        t=np.arange(n_samp) / fs, V=np.abs(vl), theta=th, P=out_s[0].real, Q=out_s[0].imag,
        f=_bus_frequency(th, fs, f0), f0=f0, bus="fault", meta=meta,
    )


def disturbance_inputs(truth: LoadTruth, **kw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], V [pu], θ [rad]) of :func:`large_disturbance` — the inputs for a model playback."""
    w = large_disturbance(truth, **kw)
    return w.t, w.V, w.theta


# --------------------------------------------------------------------------------------------
# Public: streaming fleet
# --------------------------------------------------------------------------------------------


class SyntheticFleet:
    """A live synthetic PMU fleet: n independent load buses, continuous in time.

    Parameters
    ----------
    n_buses : int
        Number of buses.
    fs : float
        Frame rate [Hz].
    f0 : float
        Nominal frequency [Hz].
    level : int or None
        Disturbance level (NOISE_LEVELS) of the measurement noise; None: noise-free.
    seed : int
        Everything (truths, networks, excitation, noise) is deterministic for a seed.
    t0 : float or None
        Time of the first sample [s] (e.g. seconds since epoch, given by the caller); None: 0.0.
    step_s : float
        Longest internal RK4 step [s] (default 10 ms, see Notes).

    Attributes
    ----------
    truths : list of LoadTruth
    bus_names : list of str
        ``bus0001``, ``bus0002``, …
    snr_db : ndarray
        SNR target per bus [dB] (nan when noise-free).

    Notes
    -----
    Same model as :func:`make_cases` (one independent small network per bus) but integrated with a
    coarser step, 10 ms instead of 1 ms, with the forcing on the same 10 ms grid (piecewise linear),
    in the calling thread (no thread pool: the fleet must leave the cores to the identification
    workers).  With the fastest motor pole at b ≤ 28 1/s and the
    electromechanical mode near 1 Hz, RK4 at 10 ms differs from 1 ms by < 1e-7 pu in V and < 5e-7
    pu in P, ~1e-4 of the ambient fluctuation and far below the noise of any level.  The construction
    runs a 5 s warm-up and a 20 s calibration (not emitted) whose ambient rms per channel fixes each
    bus's noise std (eq. 10), so the SNR of a live 10 s window scatters around the bus's target
    (within ~±3 dB).  Noise is on V, θ, P, Q and f.  Random draws are time-major, so the stream
    does not depend on how it is chunked into :meth:`advance` calls.
    """

    _CAL_S = 20.0

    def __init__(
        self,
        n_buses: int,
        *,
        fs: float = 50.0,
        f0: float = 50.0,
        level: int | None = 2,
        seed: int = 0,
        t0: float | None = None,
        step_s: float = 1e-2,
    ) -> None:
        self.n_buses = int(n_buses)
        self.fs = float(fs)
        self.f0 = float(f0)
        self.level = level
        self.t0 = 0.0 if t0 is None else float(t0)
        self._k = 0  # index of the next sample
        root = np.random.SeedSequence([seed, 0xF1EE7])
        children = root.spawn(self.n_buses + 1)
        self._rng_stream = np.random.default_rng(children[-1])
        self.truths: list[LoadTruth] = []
        self.bus_names = [f"bus{i + 1:04d}" for i in range(self.n_buses)]
        rows, x0s, vl0s, sp, sq, tgt = [], [], [], [], [], []
        for ss in children[:-1]:
            s_truth, s_net, s_noise = ss.spawn(3)
            tr = random_truth(np.random.default_rng(s_truth))
            rng_net = np.random.default_rng(s_net)
            net = _draw_network(rng_net, tr, self.f0)
            p, x0, vl0 = _steady_state(tr, net)
            self.truths.append(tr)
            rows.append(p)
            x0s.append(x0)
            vl0s.append(vl0)
            sp.append(net["sigma_P"] * net["P_N"])
            sq.append(net["sigma_Q"] * net["P_N"])
            t_ = _target_snr(np.random.default_rng(s_noise), level, None)
            tgt.append(np.nan if t_ is None else t_)
        self._par = np.array(rows).reshape(self.n_buses, _NPAR)
        self._x = np.array(x0s).reshape(self.n_buses, _NX)
        self._vl = np.array(vl0s, dtype=complex)
        self._amp = np.stack([np.array(sp), np.array(sq)], axis=1)  # (n, 2)
        self.snr_db = np.array(tgt)
        self._m, self._ksub, self._h = _grid(self.fs, step_s, step_s)
        self._sos, self._gain = _forcing_filter(self.fs * self._m)
        self._zi = np.zeros((self._sos.shape[0], self.n_buses, 2, 2))
        self._f_last = np.zeros((self.n_buses, 2))
        self._theta_last: np.ndarray | None = None
        self._sigma = np.zeros((self.n_buses, 5))
        # Warm-up + calibration, not emitted: continue the stream from where they end.
        self._run(int(round(WARMUP_S * self.fs)))
        cal = self._run(int(round(self._CAL_S * self.fs)) + 1)
        if level is not None:
            for ci, name in enumerate(("V", "theta", "P", "Q", "f")):
                amb = _ambient_rows(cal[name], detrend=(name == "theta"))
                rms = np.sqrt(np.mean(amb * amb, axis=1))
                self._sigma[:, ci] = rms * 10.0 ** (-self.snr_db / 20.0)
        self._noise_rng = np.random.default_rng(root.spawn(1)[0])

    def _run(self, n: int) -> dict[str, np.ndarray]:
        """Simulate n samples (noise-free), carrying the state and the forcing filter over."""
        m = self._m
        # Time-major draws: the stream does not depend on how it is chunked into advance() calls.
        w = self._rng_stream.standard_normal((n * m, self.n_buses, 2)).transpose(1, 2, 0)
        y, self._zi = signal.sosfilt(self._sos, w, axis=-1, zi=self._zi)
        new = y * self._gain * self._amp[:, :, None]
        forcing = np.concatenate([self._f_last[:, :, None], new], axis=-1)
        self._f_last = new[:, :, -1].copy()
        out_v, out_s, _, self._x, self._vl = _simulate_serial(
            self._par, self._x, self._vl, forcing, self._h, self._ksub, m, 0, n,
            -np.ones((self.n_buses, 2), dtype=np.int64),
        )
        th = np.angle(out_v)
        # Unwrap continuously across calls.
        if self._theta_last is not None:
            th = np.concatenate([self._theta_last[:, None], th], axis=1)
            th = np.unwrap(th, axis=1)[:, 1:]
        else:
            th = np.unwrap(th, axis=1)
        prev = self._theta_last
        self._theta_last = th[:, -1].copy()
        # Frequency by backward differences so a sample never depends on the future.
        if prev is None:
            prev = th[:, 0]
        dth = np.diff(np.concatenate([prev[:, None], th], axis=1), axis=1)
        fr = self.f0 + dth * self.fs / (2.0 * math.pi)
        return {"V": np.abs(out_v), "theta": th, "P": out_s.real, "Q": out_s.imag, "f": fr}

    def advance(self, n_samples: int) -> dict[str, np.ndarray]:
        """Next n_samples frames of every bus.

        Returns
        -------
        dict
            ``t`` (n,) [s]; ``V`` [pu], ``theta`` [rad], ``P``, ``Q`` [pu], ``f`` [Hz], each
            (n_buses, n); noisy at the fleet's level; continuous with the previous call.
        """
        n = int(n_samples)
        t = self.t0 + (self._k + np.arange(n)) / self.fs
        self._k += n
        if n == 0:
            z = np.zeros((self.n_buses, 0))
            return {"t": t, "V": z, "theta": z.copy(), "P": z.copy(), "Q": z.copy(), "f": z.copy()}
        out = self._run(n)
        if self.level is not None:
            e = self._noise_rng.standard_normal((n, 5, self.n_buses))  # time-major, as above
            for ci, name in enumerate(("V", "theta", "P", "Q", "f")):
                out[name] = out[name] + self._sigma[:, ci, None] * e[:, ci, :].T
        out["t"] = t
        return out


def _ambient_rows(y: np.ndarray, detrend: bool) -> np.ndarray:
    """Row-wise ambient part (minus mean, optionally minus a linear trend)."""
    if not detrend:
        return y - y.mean(axis=1, keepdims=True)
    t = np.arange(y.shape[1], dtype=float)
    tc = t - t.mean()
    slope = (y - y.mean(axis=1, keepdims=True)) @ tc / (tc @ tc)
    return y - y.mean(axis=1, keepdims=True) - slope[:, None] * tc[None, :]
