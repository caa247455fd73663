"""The network around a synthetic load: numba kernels, steady state and the random network draw.

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
* Ambient excitation comes from bus N (paper §VI.A) and, optionally, from the load at L itself (its
  constant-power part fluctuating, :mod:`aslm_sim.own`: rows 2–3 of the forcing), which then moves V and θ
  through the network like the identifier's unknown disturbance would.  Bus N's forcing: low-pass filtered (2 Hz, 4th-order
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

The per-case parameter row, the network states and the per-case complex constants are flat float/complex
vectors (numba kernels take arrays); their layouts are declared once, as ordered (name, length, meaning)
fields, and addressed by name: ``p[Par.ZS]`` is Re z_s, ``p[Par.ZS + 1]`` its Im.

Units: powers and impedances in per unit on the 100 MVA system base, voltages in pu, angles in rad,
times in s.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numba as nb
import numpy as np
from scipy import signal

from aslm_sim.truth import LoadTruth, low_slip_root

__all__ = [
    "FORCING_CUTOFF_HZ",
    "MAX_FORCING_STEP_S",
    "MAX_STEP_S",
    "NPAR",
    "NX",
    "PARAMETER_FIELDS",
    "STATE_FIELDS",
    "WARMUP_S",
    "Par",
    "State",
    "bus_frequency",
    "draw_network",
    "forcing_filter",
    "motor_and_static",
    "simulate",
    "solve_at",
    "static_load",
    "steady_state",
    "step_grid",
]

#: Cut-off of the low-pass filter shaping the ambient load fluctuation at bus N [Hz] (paper §VI.A).
FORCING_CUTOFF_HZ: float = 2.0
#: Longest fine integration step [s].
MAX_STEP_S: float = 1e-3
#: Longest step of the grid on which the forcing is generated (linear in between) [s].  Equal to the
#: fine step: a coarser piecewise-linear forcing puts kinks into V between the samples (the network
#: is algebraic), which biased a sample-step identifier by ~0.4 % on noise-free data.
MAX_FORCING_STEP_S: float = 1e-3
#: Warm-up simulated and discarded before a record [s].
WARMUP_S: float = 5.0
_LOW_V = 0.5  # below this the I and P parts of ZIP turn into constant impedance (as in PSAT)


def _layout(name: str, fields: tuple[tuple[str, int, str], ...]) -> tuple[type[IntEnum], int]:
    """Offsets of fields laid out one after the other, as an IntEnum, and the vector's length.

    IntEnum members index numpy arrays in Python and are folded to constants by numba.
    """
    offsets, k = {}, 0
    for field, length, _ in fields:
        offsets[field] = k
        k += length
    return IntEnum(name, offsets, module=__name__, qualname=name), k


#: The parameter row of one case, in order: (name, length, meaning [unit]).  Complex quantities take two
#: entries (re, im).
PARAMETER_FIELDS: tuple[tuple[str, int, str], ...] = (
    # Motor at L in the original form (eq. 1): dE'/dt = −BM·E' − j·s·ω0·E' + CM·V.
    ("BM", 1, "b = X/(Td0·X') [1/s]"),
    ("CM", 1, "c = (X/X' − 1)/Td0 [1/s]"),
    ("XP", 1, "transient reactance X' [pu]"),
    ("H2", 1, "2H of the slip equation [s]"),
    ("TM", 1, "mechanical torque Tm [pu]"),
    # ZIP at L (eq. 6): P = PZ·V² + PI·V + PP, Q likewise.
    ("PZ", 1, "constant-impedance P [pu]"),
    ("PI", 1, "constant-current P [pu]"),
    ("PP", 1, "constant-power P [pu]"),
    ("QZ", 1, "constant-impedance Q [pu]"),
    ("QI", 1, "constant-current Q [pu]"),
    ("QP", 1, "constant-power Q [pu]"),
    # Network (see the module docstring for the topology).
    ("VS", 2, "infinite-bus voltage (re, im) [pu]"),
    ("ZS", 2, "impedance infinite bus – H, the rest of the grid (re, im) [pu]"),
    ("ZG", 2, "generator X'd plus step-up transformer (re, im) [pu]"),
    ("ZL", 2, "feeder H – L (re, im) [pu]"),
    ("ZN", 2, "feeder H – N (re, im) [pu]"),
    ("PN", 1, "nominal load of bus N: conductance G at 1 pu [pu] (Y_N = G − jB)"),
    ("QN", 1, "nominal load of bus N: susceptance B at 1 pu [pu]"),
    ("EG", 1, "generator EMF |E'g| [pu]"),
    ("PM", 1, "generator mechanical power [pu]"),
    ("HG2", 1, "generator 2H on the system base [s]"),
    ("DG", 1, "generator damping [pu]"),
    ("W0", 1, "ω0 = 2π·f0 [rad/s]"),
    ("YF", 2, "fault shunt admittance at H (re, im) [pu], on between the fault steps"),
)
Par, NPAR = _layout("Par", PARAMETER_FIELDS)

#: The state vector of one case, in order: (name, length, meaning [unit]).
STATE_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("DELTA", 1, "generator rotor angle δ [rad]"),
    ("DOMEGA", 1, "generator speed deviation Δω [pu]"),
    ("ED", 1, "motor E'd [pu]"),
    ("EQ", 1, "motor E'q [pu]"),
    ("S", 1, "motor slip s [-]"),
)
State, NX = _layout("State", STATE_FIELDS)

# Complex constants of one case that do not change in time (computed once per case by _consts).
_CONST_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("YH0", 1, "hub self-admittance without bus N and the fault: 1/z_s + 1/z_g [pu]"),
    ("IS", 1, "infinite bus as a current source: V_s/z_s [pu]"),
    ("YG", 1, "1/z_g [pu]"),
    ("ZL", 1, "z_L [pu]"),
    ("YL", 1, "1/z_L [pu]"),
    ("ZN", 1, "z_N [pu]"),
    ("YLD", 1, "shunt at L: ZIP Z part plus the motor's 1/jX' [pu]"),
    ("YM", 1, "motor 1/jX' [pu]"),
    ("YF", 1, "fault admittance at H [pu]"),
)
_Const, _NC = _layout("_Const", _CONST_FIELDS)


@nb.njit(cache=True, error_model="numpy", inline="always")
def _inv(z):  # pragma: no cover - numba
    """1/z without numba's guarded complex division (z is never 0 here)."""
    r = 1.0 / (z.real * z.real + z.imag * z.imag)
    return complex(z.real * r, -z.imag * r)


@nb.njit(cache=True, error_model="numpy")
def _consts(p):  # pragma: no cover - numba
    """Complex constants of one case: admittances and source currents that do not change in time."""
    c = np.empty(_NC, dtype=np.complex128)
    zs = complex(p[Par.ZS], p[Par.ZS + 1])
    zg = complex(p[Par.ZG], p[Par.ZG + 1])
    zl = complex(p[Par.ZL], p[Par.ZL + 1])
    c[_Const.YH0] = 1.0 / zs + 1.0 / zg
    c[_Const.IS] = complex(p[Par.VS], p[Par.VS + 1]) / zs
    c[_Const.YG] = 1.0 / zg
    c[_Const.ZL] = zl
    c[_Const.YL] = 1.0 / zl
    c[_Const.ZN] = complex(p[Par.ZN], p[Par.ZN + 1])
    c[_Const.YM] = 1.0 / complex(0.0, p[Par.XP])  # motor: E' behind jX'
    c[_Const.YLD] = complex(p[Par.PZ], -p[Par.QZ]) + c[_Const.YM]  # ZIP Z part + motor X' as a shunt
    c[_Const.YF] = complex(p[Par.YF], p[Par.YF + 1])
    return c


@nb.njit(cache=True, error_model="numpy")
def _thevenin(p, c, dpn, dqn, fault):  # pragma: no cover - numba
    """Network seen from L at one instant, without the sources (they move with the states).

    Returns Y_H (hub self-admittance), k = Z_H/(Z_H + z_L) (source-current to Thevenin-current
    factor) and Y_th = 1/(Z_H + z_L), with the fluctuation (dpn, dqn) of bus N's admittance.
    """
    yn = complex(p[Par.PN] + dpn, -(p[Par.QN] + dqn))
    yh = c[_Const.YH0] + yn * _inv(1.0 + c[_Const.ZN] * yn)  # N: its feeder and load in series
    if fault:
        yh += c[_Const.YF]
    zhh = _inv(yh)
    yth = _inv(zhh + c[_Const.ZL])
    return yh, zhh * yth, yth


@nb.njit(cache=True, error_model="numpy")
def _network(p, c, yh, kth, yth, x, vl, dpp, dqp):  # pragma: no cover - numba
    """Algebraic network at one instant, given its Thevenin part (:func:`_thevenin`) and the states.

    ``dpp``, ``dqp``: the load's own fluctuation, added to its constant-power part [pu].

    Returns V_L, V_H, the feeder current I_line flowing from H into L (all complex, sync frame) and
    the generator EMF E'g.  The ZIP I and P parts make the L node nonlinear: Newton on V_L (a 2-D
    real problem written with dV and conj(dV)) from the guess vl, quadratically convergent, 2
    iterations from the previous stage's value.
    """
    eg = p[Par.EG] * complex(math.cos(x[State.DELTA]), math.sin(x[State.DELTA]))
    ih = c[_Const.IS] + eg * c[_Const.YG]
    num = ih * kth + complex(x[State.ED], x[State.EQ]) * c[_Const.YM]
    den = yth + c[_Const.YLD]
    v = vl
    pi, pp, qi, qp = p[Par.PI], p[Par.PP] + dpp, p[Par.QI], p[Par.QP] + dqp
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
    vh = (ih + v * c[_Const.YL]) * _inv(yh + c[_Const.YL])
    return v, vh, (vh - v) * c[_Const.YL], eg


@nb.njit(cache=True, error_model="numpy")
def _rhs(p, c, yh, kth, yth, x, vl, dx, dpp=0.0, dqp=0.0):  # pragma: no cover - numba
    """State derivatives (filled into dx); returns V_L, V_H, I_line as :func:`_network`.

    Motor in the original form, eq. 1–2; classical generator swing equation.
    """
    v, vh, il, eg = _network(p, c, yh, kth, yth, x, vl, dpp, dqp)
    w0 = p[Par.W0]
    bm = p[Par.BM]
    cm = p[Par.CM]
    ed = x[State.ED]
    eq = x[State.EQ]
    s = x[State.S]
    vd = v.real
    vq = v.imag
    dx[State.ED] = -bm * ed + s * w0 * eq + cm * vd
    dx[State.EQ] = -bm * eq - s * w0 * ed + cm * vq
    te = (ed * vq - eq * vd) / p[Par.XP]
    dx[State.S] = (p[Par.TM] - te) / p[Par.H2]
    pe = (eg * ((eg - vh) * c[_Const.YG]).conjugate()).real
    dx[State.DELTA] = w0 * x[State.DOMEGA]
    dx[State.DOMEGA] = (p[Par.PM] - pe - p[Par.DG] * x[State.DOMEGA]) / p[Par.HG2]
    return v, vh, il


@nb.njit(cache=True, error_model="numpy")
def solve_at(p: np.ndarray, x: np.ndarray, dpn: float, dqn: float, fault: bool,
             vl: complex) -> tuple:  # pragma: no cover - numba
    """One-off network solve and state derivatives, for set-up and tests.

    Parameters
    ----------
    p : ndarray
        (NPAR,) parameter row (:data:`PARAMETER_FIELDS`).
    x : ndarray
        (NX,) states (:data:`STATE_FIELDS`).
    dpn, dqn : float
        Fluctuation of bus N's conductance and susceptance [pu].
    fault : bool
        Apply the fault admittance ``p[Par.YF]`` at H.
    vl : complex
        Starting guess of V_L for the Newton iteration [pu].

    Returns
    -------
    tuple
        V_L, V_H, I_line (complex [pu]) and dx, the (NX,) state derivatives [unit/s].
    """
    c = _consts(p)
    yh, kth, yth = _thevenin(p, c, dpn, dqn, fault)
    dx = np.empty(NX)
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
    k1 = np.empty(NX)
    k2 = np.empty(NX)
    k3 = np.empty(NX)
    k4 = np.empty(NX)
    xt = np.empty(NX)
    step = 0
    on_step = fault_steps[c, 0]
    off_step = fault_steps[c, 1]
    prev_fault = False
    tb = _thevenin(p, cst, forcing[c, 0, 0], forcing[c, 1, 0], False)
    own = forcing.shape[1] >= 4  # rows 2, 3: the load's own ΔP, ΔQ of its constant-power part
    op0 = oq0 = dop = doq = 0.0
    for j in range(n_int):
        fp0 = forcing[c, 0, j]
        fq0 = forcing[c, 1, j]
        dfp = forcing[c, 0, j + 1] - fp0
        dfq = forcing[c, 1, j + 1] - fq0
        if own:
            op0 = forcing[c, 2, j]
            oq0 = forcing[c, 3, j]
            dop = forcing[c, 2, j + 1] - op0
            doq = forcing[c, 3, j + 1] - oq0
        for k in range(k_sub):
            fault = step >= on_step and step < off_step
            wa = k / k_sub
            wm = (k + 0.5) / k_sub
            wb = (k + 1.0) / k_sub
            # The forcing is continuous, so the end of a step is the start of the next one.
            if fault != prev_fault:
                ta = _thevenin(p, cst, fp0 + wa * dfp, fq0 + wa * dfq, fault)
            else:
                ta = tb
            tm_ = _thevenin(p, cst, fp0 + wm * dfp, fq0 + wm * dfq, fault)
            tb = _thevenin(p, cst, fp0 + wb * dfp, fq0 + wb * dfq, fault)
            prev_fault = fault
            vl, vh, il = _rhs(p, cst, ta[0], ta[1], ta[2], x, vl, k1, op0 + wa * dop, oq0 + wa * doq)
            if k == 0 and j % m_per_sample == 0:
                r = j // m_per_sample - n_skip
                if r >= 0:
                    out_v[c, r] = vl
                    out_s[c, r] = vl * il.conjugate()
                    for i in range(NX):
                        out_x[c, i, r] = x[i]
            for i in range(NX):
                xt[i] = x[i] + 0.5 * h * k1[i]
            v2, _, _ = _rhs(p, cst, tm_[0], tm_[1], tm_[2], xt, vl, k2, op0 + wm * dop, oq0 + wm * doq)
            for i in range(NX):
                xt[i] = x[i] + 0.5 * h * k2[i]
            v3, _, _ = _rhs(p, cst, tm_[0], tm_[1], tm_[2], xt, v2, k3, op0 + wm * dop, oq0 + wm * doq)
            for i in range(NX):
                xt[i] = x[i] + h * k3[i]
            v4, _, _ = _rhs(p, cst, tb[0], tb[1], tb[2], xt, v3, k4, op0 + wb * dop, oq0 + wb * doq)
            for i in range(NX):
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            vl = v4
            step += 1
    for i in range(NX):
        x_end[c, i] = x[i]
    vl_end[c] = vl


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _run_parallel(par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps,
                  out_v, out_s, out_x, x_end, vl_end):  # pragma: no cover - numba
    """The cases of :func:`simulate` in parallel threads (numba prange)."""
    for c in nb.prange(par.shape[0]):
        _integrate_case(c, par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps,
                        out_v, out_s, out_x, x_end, vl_end)


@nb.njit(cache=True, error_model="numpy")
def _run_serial(par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps,
                out_v, out_s, out_x, x_end, vl_end):  # pragma: no cover - numba
    """The cases of :func:`simulate` one after the other in the calling thread."""
    for c in range(par.shape[0]):
        _integrate_case(c, par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps,
                        out_v, out_s, out_x, x_end, vl_end)


def simulate(par: np.ndarray, x0: np.ndarray, vl0: np.ndarray, forcing: np.ndarray, h: float, k_sub: int,
             m_per_sample: int, n_skip: int, n_rec: int, fault_steps: np.ndarray, *,
             parallel: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integrate all cases with RK4 and record the PMU channels.

    Parameters
    ----------
    par : ndarray
        (nc, NPAR) parameter rows (:data:`PARAMETER_FIELDS`).
    x0 : ndarray
        (nc, NX) initial states (:data:`STATE_FIELDS`).
    vl0 : ndarray
        (nc,) complex V_L guess at the start [pu].
    forcing : ndarray
        (nc, 2, n_int + 1) ΔG, ΔB of bus N on the forcing grid (linear in between) [pu], with
        n_int = (n_skip + n_rec)·m_per_sample; or (nc, 4, n_int + 1) with, in rows 2 and 3, the load's
        own fluctuation ΔP, ΔQ of its constant-power part at L [pu].
    h : float
        Fine step [s].
    k_sub : int
        Fine steps per forcing interval.
    m_per_sample : int
        Forcing intervals per sample.
    n_skip : int
        Samples of warm-up not recorded.
    n_rec : int
        Samples recorded.
    fault_steps : ndarray
        (nc, 2) int, fine-step index where the fault at H starts and ends (-1: none).
    parallel : bool
        Cases in parallel threads; False: in the calling thread (the fleet: no thread hand-off per
        frame, one core at most).  The results are the same.

    Returns
    -------
    tuple
        vl, (nc, n_rec) complex V_L [pu]; sl, (nc, n_rec) complex P + jQ from the feeder current [pu];
        xs, (nc, NX, n_rec) states at the samples; x_end, (nc, NX), and vl_end, (nc,) complex: the state
        one sample period after the last record (to continue a stream).
    """
    nc = par.shape[0]
    n_int = (n_skip + n_rec) * m_per_sample
    out_v = np.empty((nc, n_rec), dtype=np.complex128)
    out_s = np.empty((nc, n_rec), dtype=np.complex128)
    out_x = np.empty((nc, NX, n_rec))
    x_end = np.empty((nc, NX))
    vl_end = np.empty(nc, dtype=np.complex128)
    run = _run_parallel if parallel else _run_serial
    run(par, x0, vl0, forcing, h, k_sub, m_per_sample, n_skip, n_int, fault_steps, out_v, out_s, out_x, x_end, vl_end)
    return out_v, out_s, out_x, x_end, vl_end


def static_load(tr: LoadTruth, v: np.ndarray) -> np.ndarray:
    """Steady-state complex power of the whole load at |V| = v (motor at its low-slip root) [pu].

    Parameters
    ----------
    tr : LoadTruth
        The load.
    v : ndarray
        Voltage magnitudes [pu].
    """
    x = np.array([low_slip_root(tr.a, tr.b, tr.Tm, float(vv)) for vv in np.atleast_1d(v)])
    qm = v * v / tr.Xp - tr.a * tr.b * v * v / (tr.b * tr.b + x * x)
    p = tr.Pz * v * v + tr.Pi * v + tr.Pp + tr.Tm
    q = tr.Qz * v * v + tr.Qi * v + tr.Qp + qm
    return p + 1j * q


def draw_network(rng: np.random.Generator, tr: LoadTruth, f0: float) -> dict:
    """Random network around the load (sizes scale with the load so every case looks alike).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draws (12 uniforms, in a fixed order).
    tr : LoadTruth
        The load at L.
    f0 : float
        Nominal frequency [Hz].

    Returns
    -------
    dict
        Scalars (see the module docstring for the topology): target V_L [pu], load P_N, Q_N of bus N
        [pu], impedances z_L, z_N, z_g, z_s (complex [pu]), generator rating S_g and output P_g [pu],
        its inertia H_g [s] and damping ratio zeta [-], the fluctuation stds sigma_P, sigma_Q (× P_N)
        and f0 [Hz].
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


def steady_state(tr: LoadTruth, net: dict) -> tuple[np.ndarray, np.ndarray, complex]:
    """Parameter row, initial state and V_L of the steady state of the whole system.

    Parameters
    ----------
    tr : LoadTruth
        The load at L.
    net : dict
        A network draw (:func:`draw_network`).

    Returns
    -------
    tuple
        p, the (NPAR,) parameter row; x0, the (NX,) states; V_L (complex [pu]).

    Notes
    -----
    |V_L| is the drawn target and fixes V_H through the feeder drop; the common angle is then set
    so that the generator delivers P_g (the infinite bus at 1∠0 supplies the rest).  Both leaves
    (L, N) have rotation-invariant loads, so the magnitude and angle problems decouple.
    """
    zl, zn, zg, zs = net["z_L"], net["z_N"], net["z_g"], net["z_s"]
    yn = net["P_N"] - 1j * net["Q_N"]
    w0 = 2.0 * math.pi * net["f0"]

    # The load is rotation-invariant: fix V_L = target∠0, get V_H from the feeder drop, rotate later.
    vl = complex(net["V_L"])
    s_l = complex(static_load(tr, np.array([net["V_L"]]))[0])
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
    x_m = low_slip_root(tr.a, tr.b, tr.Tm, abs(vl_c))
    e_m = tr.Xp * tr.a * vl_c / (tr.b + 1j * x_m)
    p = np.zeros(NPAR)
    p[Par.BM] = tr.X / (tr.Td0 * tr.Xp)
    p[Par.CM] = (tr.X / tr.Xp - 1.0) / tr.Td0
    p[Par.XP], p[Par.H2], p[Par.TM] = tr.Xp, tr.H2, tr.Tm
    p[Par.PZ], p[Par.PI], p[Par.PP], p[Par.QZ], p[Par.QI], p[Par.QP] = tr.Pz, tr.Pi, tr.Pp, tr.Qz, tr.Qi, tr.Qp
    p[Par.VS], p[Par.VS + 1] = 1.0, 0.0
    for idx, z in ((Par.ZS, zs), (Par.ZG, zg), (Par.ZL, zl), (Par.ZN, zn)):
        p[idx], p[idx + 1] = z.real, z.imag
    p[Par.PN], p[Par.QN] = net["P_N"], net["Q_N"]
    p[Par.EG], p[Par.PM], p[Par.HG2], p[Par.DG], p[Par.W0] = abs(eg), pm, hg2, dg, w0
    x0 = np.empty(NX)
    x0[State.DELTA], x0[State.DOMEGA] = np.angle(eg), 0.0
    x0[State.ED], x0[State.EQ], x0[State.S] = e_m.real, e_m.imag, x_m / w0
    return p, x0, complex(vl_c)


def forcing_filter(fs_forcing: float) -> tuple[np.ndarray, float]:
    """4th-order Butterworth low-pass at 2 Hz (sos) and the gain that makes its output unit-variance.

    Parameters
    ----------
    fs_forcing : float
        Rate of the forcing grid [Hz].
    """
    sos = signal.butter(4, FORCING_CUTOFF_HZ, fs=fs_forcing, output="sos")
    imp = np.zeros(int(40 * fs_forcing))
    imp[0] = 1.0
    gain = 1.0 / math.sqrt(float(np.sum(signal.sosfilt(sos, imp) ** 2)))
    return sos, gain


def step_grid(fs: float, max_step: float, max_forcing_step: float) -> tuple[int, int, float]:
    """Forcing intervals per sample m, fine steps per forcing interval k, and the fine step h [s].

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    max_step, max_forcing_step : float
        Longest fine step and longest forcing-grid step [s].
    """
    ts = 1.0 / fs
    m = max(1, math.ceil(ts / max_forcing_step - 1e-9))
    k = max(1, math.ceil(ts / m / max_step - 1e-9))
    return m, k, ts / m / k


def motor_and_static(tr: LoadTruth, vl: np.ndarray, xs: np.ndarray) -> dict[str, np.ndarray]:
    """Motor states, motor (eq. 3) and ZIP (eq. 6) powers [pu] from the recorded V_L and states.

    Parameters
    ----------
    tr : LoadTruth
        The load at L.
    vl : ndarray
        Complex V_L at the samples [pu].
    xs : ndarray
        (..., NX, samples) states at the samples.
    """
    vd, vq = vl.real, vl.imag
    ed, eq = xs[..., State.ED, :], xs[..., State.EQ, :]
    v = np.abs(vl)
    return {
        "Ed": ed, "Eq": eq, "s": xs[..., State.S, :],
        "P_motor": (ed * vq - eq * vd) / tr.Xp,
        "Q_motor": (v * v - vd * ed - vq * eq) / tr.Xp,
        "P_static": tr.Pz * v * v + tr.Pi * v + tr.Pp,
        "Q_static": tr.Qz * v * v + tr.Qi * v + tr.Qp,
    }


def bus_frequency(theta: np.ndarray, fs: float, f0: float) -> np.ndarray:
    """Bus frequency f0 + (dθ/dt)/2π from the sampled angle (2nd-order differences) [Hz].

    Parameters
    ----------
    theta : ndarray
        Unwrapped angle [rad], samples along the last axis.
    fs : float
        Sample rate [Hz].
    f0 : float
        Nominal frequency [Hz].
    """
    return f0 + np.gradient(theta, 1.0 / fs, axis=-1) / (2.0 * math.pi)


