"""Concealed effects on synthetic cases: the ground truth for the diagnosis tests and benchmark.

Each effect takes a noise-free synthetic case (:func:`aslm_core.synthetic.make_cases`: ZIP + original-form
induction motor in a small network), keeps its measured V and θ, and adds to its P and Q the effect
computed with its *own* model code — independent of the candidate that is supposed to find it:

* ``frequency_dependence``: Kpf·Δf, Kqf·Δf with Δf from the simulator's bus frequency.
* ``second_motor``: a second induction-motor group in ORIGINAL form (eq. 1–3: X, X', Td0, H2, Tm),
  integrated here with RK4 at 1 ms on spline-interpolated voltage phasors.
* ``speed_dependent_torque``: the case's motor again in original form with Tm(s) = Tm·((1−s)/(1−s0))^k,
  minus the same motor with constant torque.
* ``motor_stator_dynamics``: the case's motor as a FIFTH-order model (stator flux states, stator
  resistance Rs) minus the same motor third-order with the same Rs: the stator transients alone.
* ``measurement_skew``: P and Q delayed by τ through a band-limited (FFT, mirror-extended) shift.
* ``inverter_der``: a DER/inverter load with Q–V droop and P–V response through a first-order voltage
  transducer lag T, integrated at 1 ms.
* ``exponential_static``: the static P and Q get non-integer voltage exponents.  Not detectable against
  a re-identified ZIP (see the candidate's module); the case carries a user model (the true ZIP + IM
  with the old exponents) to be diagnosed with ``model=``.
* Outside the library: ``load_cycling`` (an exogenous periodic on/off load block) and ``hysteresis``
  (a capacitor bank switched by a voltage relay with a dead band).

The noise is the case's own realisation (``window − clean``), so the SNR is the case's.  An effect is
*concealed* when the plain ZIP + IM fit of the whole window still has FD ≥ 0.9 on P and Q; the
magnitude is reduced (×0.7 per try) until it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba as nb
import numpy as np
from scipy.interpolate import CubicSpline

import aslm_core.synthetic as syn
from aslm_core.identify import identify
from aslm_core.synthetic import LoadTruth, SyntheticCase
from aslm_core.window import Window

# Smooth forcing between samples (the 10 ms grid leaves kinks that bias fits ~1 %).
syn.MAX_FORCING_STEP_S = 0.001

LIBRARY_EFFECTS = ("frequency_dependence", "second_motor", "speed_dependent_torque", "motor_stator_dynamics",
                   "measurement_skew", "inverter_der", "exponential_static")
OUTSIDE_EFFECTS = ("load_cycling", "hysteresis")
FINE_STEP_S = 1e-3


@dataclass
class EffectCase:
    """A synthetic case with a concealed effect.

    Attributes
    ----------
    window : Window
        Noisy record with the effect.
    effect : str
        Effect name (``none`` for the clean case).
    truth : dict
        The effect's own parameters, in the candidate's units.
    base : SyntheticCase
        The case it was built on.
    model : dict or None
        The user model to diagnose against (``exponential_static`` only).
    fd_plain : dict
        FD of the plain ZIP + IM fit of the whole window (concealment check).
    scale : float
        Factor the drawn magnitude was reduced by for concealment.
    """

    window: Window
    effect: str
    truth: dict
    base: SyntheticCase
    model: dict | None = None
    fd_plain: dict = field(default_factory=dict)
    scale: float = 1.0


# --------------------------------------------------------------------------------------------------
# Independent motor models (original form) at a fine step
# --------------------------------------------------------------------------------------------------


def fine_inputs(t: np.ndarray, V: np.ndarray, theta: np.ndarray, h: float = FINE_STEP_S):
    """Vd, Vq on a fine grid of half steps (cubic splines of V and θ) and the sample stride.

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


def _equilibrium(vd: float, vq: float, X: float, Xp: float, Td0: float, Tm: float, Rs: float, w0: float):
    """Low-slip steady state [Ed, Eq, s] of the original-form motor with stator resistance Rs."""
    from scipy.optimize import brentq

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


def original_motor_power(t, V, theta, *, X, Xp, Td0, H2, Tm, k=0.0, Rs=0.0, fifth=False, f0=50.0):
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


def _truth_motor(tr: LoadTruth) -> dict:
    return {"X": tr.X, "Xp": tr.Xp, "Td0": tr.Td0, "H2": tr.H2, "Tm": tr.Tm}


# --------------------------------------------------------------------------------------------------
# Effects: each returns (dP, dQ, truth) for a noise-free case
# --------------------------------------------------------------------------------------------------


def _band_limited_shift(y: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """y(t − τ) by an FFT phase shift of the mirror-extended record (no wrap-around jump)."""
    ext = np.concatenate([y, y[::-1]])
    f = np.fft.rfftfreq(ext.size, dt)
    out = np.fft.irfft(np.fft.rfft(ext) * np.exp(-2j * np.pi * f * tau), n=ext.size)
    return out[: y.size]


def _effect(name: str, c: SyntheticCase, mag: float, rng: np.random.Generator):
    w = c.clean
    tr = c.truth
    p0 = float(np.mean(w.P))
    if name == "frequency_dependence":
        df = w.f - w.f0
        kp = mag * p0 / w.f0  # mag = per-unit sensitivity (ΔP/P0)/(Δf/f0)
        kq = 0.5 * mag * p0 / w.f0 * rng.choice([-1.0, 1.0])
        return kp * df, kq * df, {"Kpf": kp, "Kqf": kq}
    if name == "measurement_skew":
        tau = mag * rng.choice([-1.0, 1.0]) if rng.random() < 0.3 else mag
        return (_band_limited_shift(w.P, tau, w.dt) - w.P, _band_limited_shift(w.Q, tau, w.dt) - w.Q, {"tau": tau})
    if name == "second_motor":
        for _ in range(100):
            t2 = syn.random_truth(rng)
            if abs(math.log(t2.b / tr.b)) > math.log(1.8) or abs(math.log(t2.H2 / tr.H2)) > math.log(1.8):
                break
        scale = mag * tr.Tm / t2.Tm  # second motor torque = mag × first motor's
        x, xp = t2.X / scale, t2.Xp / scale  # a scaled copy of the drawn motor: same a/b ratio per unit
        p2, q2 = original_motor_power(w.t, w.V, w.theta, X=x, Xp=xp, Td0=t2.Td0, H2=t2.H2 * scale,
                                      Tm=t2.Tm * scale, f0=w.f0)
        a2 = (x / xp - 1.0) / (t2.Td0 * xp)
        b2 = x / (t2.Td0 * xp)
        return p2, q2, {"a2": a2, "b2": b2, "H22": t2.H2 * scale, "Tm2": t2.Tm * scale}
    if name == "speed_dependent_torque":
        m = _truth_motor(tr)
        pk, qk = original_motor_power(w.t, w.V, w.theta, **m, k=mag, f0=w.f0)
        p0_, q0_ = original_motor_power(w.t, w.V, w.theta, **m, k=0.0, f0=w.f0)
        return pk - p0_, qk - q0_, {"k": mag}
    if name == "motor_stator_dynamics":
        m = _truth_motor(tr)
        rs = mag * tr.Xp  # mag = Rs/X'
        p5, q5 = original_motor_power(w.t, w.V, w.theta, **m, Rs=rs, fifth=True, f0=w.f0)
        p3, q3 = original_motor_power(w.t, w.V, w.theta, **m, Rs=rs, fifth=False, f0=w.f0)
        return p5 - p3, q5 - q3, {"inv_Xp": 1.0 / tr.Xp, "Xp": tr.Xp, "Rs": rs}
    if name == "inverter_der":
        T = rng.uniform(0.3, 2.0)
        vdf, _, stride, h = fine_inputs(w.t, w.V, np.zeros_like(w.V))
        vf = _lag(vdf, stride, h, T, w.V.size)
        kq = mag * p0  # Q–V droop [pu/pu]: Q_der = −Kq·(Vf − V0)
        kp = 0.3 * mag * p0 * rng.uniform(-1.0, 1.0)
        dv = vf - vf[0]
        return -kp * dv, -kq * dv, {"T": T, "Kp": -kp, "Kq": -kq}
    if name == "exponential_static":
        # Exponents of the static part as the identifier sees it (Qz includes the motor's V²/X').
        st = tr.static_identifiable
        v0 = float(w.V[0])
        ps0 = st["Pz"] * v0**2 + st["Pi"] * v0 + st["Pp"]
        qs0 = st["Qz"] * v0**2 + st["Qi"] * v0 + st["Qp"]
        n_zip_p = (2 * st["Pz"] * v0**2 + st["Pi"] * v0) / ps0
        n_zip_q = (2 * st["Qz"] * v0**2 + st["Qi"] * v0) / qs0
        np_ = n_zip_p + mag * rng.choice([-1.0, 1.0])
        nq_ = n_zip_q + mag * rng.choice([-1.0, 1.0])
        vr = w.V / v0
        ps_zip = st["Pz"] * w.V**2 + st["Pi"] * w.V + st["Pp"]
        qs_zip = st["Qz"] * w.V**2 + st["Qi"] * w.V + st["Qp"]
        return ps0 * vr**np_ - ps_zip, qs0 * vr**nq_ - qs_zip, {"np": np_, "nq": nq_}
    if name == "load_cycling":
        fc = rng.uniform(0.2, 0.6)
        ph = rng.uniform(0, 2 * np.pi)
        sq = np.tanh(4.0 * np.sin(2 * np.pi * fc * w.t + ph))  # smooth on/off
        amp = mag * float(np.std(w.P))
        return amp * sq, 0.5 * amp * sq, {"f_cycle": fc, "amplitude": amp}
    if name == "hysteresis":
        vm, sv = float(np.mean(w.V)), float(np.std(w.V))
        on = False
        state = np.zeros(w.V.size)
        for i, v in enumerate(w.V):
            if not on and v < vm - 0.5 * sv:
                on = True
            elif on and v > vm + 0.5 * sv:
                on = False
            state[i] = 1.0 if on else 0.0
        bq = mag * float(np.std(w.Q))
        return np.zeros_like(w.P), -bq * state * w.V**2, {"B": bq}
    raise ValueError(f"unknown effect {name!r}")


@nb.njit(cache=True)
def _lag(vf, stride, h, T, n):  # pragma: no cover - numba
    """First-order lag dVf/dt = (V − Vf)/T by RK4 on the fine half-step grid, sampled at the samples."""
    out = np.empty(n)
    x = vf[0]
    for i in range(n):
        out[i] = x
        if i == n - 1:
            break
        for m in range(stride):
            j = 2 * (i * stride + m)
            k1 = (vf[j] - x) / T
            k2 = (vf[j + 1] - (x + 0.5 * h * k1)) / T
            k3 = (vf[j + 1] - (x + 0.5 * h * k2)) / T
            k4 = (vf[j + 2] - (x + h * k3)) / T
            x += h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


#: Magnitude drawn per effect (uniform range, in the effect's own unit).
MAGNITUDES: dict[str, tuple[float, float]] = {
    "frequency_dependence": (1.0, 3.0),  # (ΔP/P0)/(Δf/f0) [-]
    "measurement_skew": (0.015, 0.04),  # τ [s]
    "second_motor": (0.4, 1.0),  # Tm2/Tm1 [-]
    "speed_dependent_torque": (2.0, 5.0),  # k [-]
    "motor_stator_dynamics": (0.05, 0.2),  # Rs/X' [-]
    "inverter_der": (1.0, 4.0),  # Kq/P0 [pu/pu]
    "exponential_static": (0.7, 1.5),  # |np − n_ZIP| [-]
    "load_cycling": (0.3, 0.8),  # amplitude / std(P) [-]
    "hysteresis": (0.2, 0.5),  # switched Q / std(Q) [-]
}


def apply_effect(case: SyntheticCase, name: str, magnitude: float | None = None, *, seed: int = 0,
                 conceal: bool = True, max_tries: int = 6, conceal_case: SyntheticCase | None = None) -> EffectCase:
    """Add an effect to a synthetic case (noise: the case's own realisation).

    Parameters
    ----------
    case : SyntheticCase
        Made with ``input_noise=False`` (noise on P and Q only, the paper's protocol) or ``True`` (V, θ
        and f noisy too: the window keeps them; the effect is computed from the noise-free V and θ, as the
        load sees them).
    name : str
        An effect of :data:`LIBRARY_EFFECTS` or :data:`OUTSIDE_EFFECTS`, or ``none``.
    magnitude : float, optional
        In the effect's unit (see :data:`MAGNITUDES`); default drawn from its range.
    seed : int
        Seed of the effect's own random draws.
    conceal : bool
        Reduce the magnitude (×0.7 per try) until the plain fit has FD ≥ 0.9 on P and Q.
    max_tries : int
        Reductions tried before giving up (the last one is returned, flagged by ``fd_plain``).
    conceal_case : SyntheticCase, optional
        Conceal on this case instead — e.g. the same seed without input noise, whose plain fit is not
        degraded by noisy V and θ — and apply the magnitude found there to ``case`` (same draws);
        ``fd_plain`` and ``scale`` are then the twin's.

    Returns
    -------
    EffectCase
    """
    rng_m = np.random.default_rng([seed, 7])
    w = case.window
    if name == "none":
        r = identify(w)
        return EffectCase(w, "none", {}, case, fd_plain=dict(r.fit))
    if magnitude is None:
        magnitude = float(rng_m.uniform(*MAGNITUDES[name]))
    if conceal and conceal_case is not None:
        twin = apply_effect(conceal_case, name, magnitude, seed=seed, conceal=True, max_tries=max_tries)
        mag = magnitude if name == "speed_dependent_torque" else magnitude * twin.scale
        ec = apply_effect(case, name, mag, seed=seed, conceal=False)
        ec.fd_plain, ec.scale = twin.fd_plain, twin.scale
        return ec
    scale = 1.0
    model = None
    if name == "exponential_static":
        tr = case.truth
        model = {"dynamic": tr.dynamic, "static": tr.static_identifiable}
    for _ in range(max_tries):
        rng = np.random.default_rng([seed, 11])  # same draws at every scale
        # k of speed_dependent_torque stays physical (the effect is small anyway).
        dp, dq, truth = _effect(name, case, magnitude * scale if name != "speed_dependent_torque" else magnitude,
                                rng)
        win = Window(t=w.t, V=w.V, theta=w.theta, P=w.P + dp, Q=w.Q + dq, f=w.f, f0=w.f0, bus=w.bus,
                     meta={**w.meta, "effect": name})
        if not conceal:
            return EffectCase(win, name, truth, case, model, {}, scale)
        r = identify(win)
        if min(r.fit["fd_p"], r.fit["fd_q"]) >= 0.9 or name == "speed_dependent_torque":
            return EffectCase(win, name, truth, case, model, dict(r.fit), scale)
        scale *= 0.7
    return EffectCase(win, name, truth, case, model, dict(r.fit), scale)


def make_effect_cases(name: str, n: int, *, level: int, seed: int = 0, f0: float = 50.0) -> list[EffectCase]:
    """Concealed cases of one effect at a noise level.

    Parameters
    ----------
    name : str
        Effect (see :func:`apply_effect`).
    n : int
        Number of cases.
    level : int
        Noise level of :data:`aslm_core.synthetic.NOISE_LEVELS`.
    seed : int
        Seed of the synthetic cases (``make_cases(n, seed=seed)``) and of the effects.
    f0 : float
        Nominal frequency [Hz].

    Returns
    -------
    list of EffectCase
    """
    cases = syn.make_cases(n, level=level, seed=seed, input_noise=False, f0=f0)
    return [apply_effect(c, name, seed=seed * 100003 + i) for i, c in enumerate(cases)]
