"""The IEEE 14-bus scenario of the ANDES benchmarks: a load bus driven by ambient noise on the other loads.

A third-order induction motor (ANDES ``Motor3``) and a ZIP static load share bus 9 of ANDES's
``ieee14/ieee14_full.xlsx`` (GENROU machines, exciters, governors).  Every *other* load's constant-power
part is driven by independent 2 Hz low-passed white noise (ambient excitation); ANDES integrates the whole
DAE (implicit trapezoid, fixed step), and bus 9's V, θ and total load P, Q (motor + static) are returned on
ANDES's step grid (:func:`simulate`) and resampled to a uniform grid (:func:`resample`).  The motor
conversion to the paper's D is in docs/andes_crosscheck.md.

``andes`` is optional: it is imported only when a simulation runs.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import signal

__all__ = ["BUS", "CASE", "F0", "FS", "MAIN_SCENARIOS", "MOTOR", "NAMES", "PQ_AT_BUS", "SCENARIOS", "STATIC_PQ",
           "ZIP_SHARES", "BusLoad", "lowpass_noise", "motor_equilibrium", "resample", "rotor_modes", "simulate",
           "simulate_load", "solve_power_flow", "transformed_d"]

CASE = "ieee14/ieee14_full.xlsx"
BUS = 9
PQ_AT_BUS = "PQ_6"  # the case's load at bus 9 (29.5 MW, 16.6 Mvar); reduced to make room for the motor
STATIC_PQ = (0.15, 0.10)  # p0, q0 [pu on 100 MVA] kept as static load at bus 9
ZIP_SHARES = {"p2p": 0.3, "p2i": 0.3, "p2z": 0.4, "q2q": 0.3, "q2i": 0.3, "q2z": 0.4}
# Motor data on its own base (Sn = 25 MVA, 138 kV): chosen so that D falls inside the paper's box.
MOTOR = {"Sn": 25.0, "Vn": 138.0, "fn": 60.0, "xs": 0.1, "xr1": 0.1, "xm": 3.0, "rr1": 0.01, "Hm": 2.0}
SCENARIOS = {
    "model": {"rs": 1e-5, "c1": 0.2, "c2": 0.0, "c3": 0.0},
    "andes_default": {"rs": 0.01, "c1": 0.1, "c2": 0.02, "c3": 0.02},
    # The two departures of andes_default one at a time (not in the default run).
    "rs_only": {"rs": 0.01, "c1": 0.14, "c2": 0.0, "c3": 0.0},
    "torque_only": {"rs": 1e-5, "c1": 0.1, "c2": 0.02, "c3": 0.02},
}
MAIN_SCENARIOS = ("model", "andes_default")
F0 = 60.0
FS = 100.0
NAMES = ("a", "b", "H2", "Tm")


def lowpass_noise(n: int, dt: float, fc: float, rng: np.random.Generator, burn: int = 2000) -> np.ndarray:
    """Unit-variance white noise through a 2nd-order Butterworth low-pass at fc [Hz] (causal, burnt in).

    Parameters
    ----------
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    fc : float
        Cut-off frequency [Hz].
    rng : numpy.random.Generator
        Source of the white noise.
    burn : int
        Samples drawn and dropped first, so that the filter's start-up transient is gone.
    """
    sos = signal.butter(2, fc, fs=1.0 / dt, output="sos")
    x = signal.sosfilt(sos, rng.standard_normal(n + burn))[burn:]
    return x / x.std()


def solve_power_flow(ss) -> None:
    """ANDES power flow started from the motors' low-slip equilibrium (:func:`_init_motor_guess`).

    Parameters
    ----------
    ss : andes.System
        The set-up system (its motors' start is overwritten after ANDES's own initialisation).

    Raises
    ------
    RuntimeError
        The power flow did not converge.
    """
    orig_init = ss.PFlow.init

    def pf_init():
        out = orig_init()
        _init_motor_guess(ss)
        return out

    ss.PFlow.init = pf_init
    if not ss.PFlow.run():
        raise RuntimeError("ANDES power flow did not converge")


def _init_motor_guess(ss) -> None:
    """Overwrite ANDES's generic power-flow start of the motors (slip 1) with their low-slip equilibrium.

    From ANDES's default start the Newton iteration diverged (KLU segfaulted on this case); starting from
    the equilibrium at the initial bus voltage converges in a few iterations.  It is found from the
    model's own equations (:func:`motor_equilibrium`), so rs, the torque law and Motor5's second cage count.
    """
    bus, dae = ss.Bus, ss.dae
    for m in (ss.Motor3, ss.Motor5):
        for i in range(m.n):
            ub = bus.idx2uid(m.bus.v[i])
            v, ang = dae.y[bus.v.a[ub]], dae.y[bus.a.a[ub]]
            va = -v * math.sin(ang) + 1j * v * math.cos(ang)
            sl, e1, e2, cur, tm = motor_equilibrium(m, i, va)
            s = va * np.conj(cur)
            states = [(m.slip, sl), (m.e1d, e1.real), (m.e1q, e1.imag)]
            if e2 is not None:
                states += [(m.e2d, e2.real), (m.e2q, e2.imag)]
            for var, val in states:
                dae.x[var.a[i]] = val
            te = ((e1 if e2 is None else e2) * np.conj(cur)).real
            for var, val in ((m.vd, va.real), (m.vq, va.imag), (m.Id, cur.real), (m.Iq, cur.imag),
                             (m.p, s.real), (m.q, s.imag), (m.te, te), (m.tm, tm)):
                dae.y[var.a[i]] = val


def motor_equilibrium(m, i: int, va: complex) -> tuple[float, complex, complex | None, complex, float]:
    """Low-slip equilibrium of ANDES Motor3/Motor5 device ``i`` at the terminal voltage ``va`` (ANDES frame).

    For a slip σ the rotor equations at rest are linear in E', (E'') and I; the slip is the smallest root of
    τe(σ) = τm(σ) (scan, then bisection).

    Parameters
    ----------
    m : andes model
        ``ss.Motor3`` or ``ss.Motor5`` after setup (its parameters on the system base).
    i : int
        Index of the device within the model.
    va : complex
        Terminal voltage phasor in ANDES's frame [pu].

    Returns
    -------
    tuple
        σ [-], E' [pu], E'' [pu] (None for Motor3), I [pu] and τm [pu], all on the system base.
    """
    x0, x1, t10, wb, rs = (float(getattr(m, k).v[i]) for k in ("x0", "x1", "T10", "wb", "rs"))
    five = hasattr(m, "x2")
    x2, t20 = (float(m.x2.v[i]), float(m.T20.v[i])) if five else (x1, 1.0)
    aa, bb, c2 = float(m.aa.v[i]), float(m.bb.v[i]), float(m.c2.v[i])

    def solve(sig: float):
        # Unknowns [E1, E2, I]; Motor3 has E2 = E1.
        w = 1j * wb * sig
        a = np.zeros((3, 3), complex)
        rhs = np.zeros(3, complex)
        a[0] = [-w - 1 / t10, 0, 1j * (x0 - x1) / t10]
        if five:
            a[1] = [-1 / t10 + 1 / t20, -w - 1 / t20, 1j * (x0 - x1) / t10 + 1j * (x1 - x2) / t20]
        else:
            a[1] = [1, -1, 0]
        a[2] = [0, 1, rs + 1j * x2]
        rhs[2] = va
        e1, e2, cur = np.linalg.solve(a, rhs)
        return e1, e2, cur, (e2 * np.conj(cur)).real - (aa + bb * sig + c2 * sig * sig)

    lo = 0.0
    for hi in np.geomspace(1e-7, 0.5, 400):
        if solve(hi)[3] > 0:
            break
        lo = hi
    else:
        raise RuntimeError("no motor equilibrium below slip 0.5")
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if solve(mid)[3] > 0 else (mid, hi)
    sig = 0.5 * (lo + hi)
    e1, e2, cur, _ = solve(sig)
    return sig, e1, (e2 if five else None), cur, aa + bb * sig + c2 * sig * sig


def rotor_modes(m, i: int = 0) -> np.ndarray:
    """The rotor circuits of ANDES Motor5 device ``i`` as the transformed model's modes [[a1, b1], [a2, b2]].

    With rs = 0 the stator current is (V − E'')/(jX''); the rotor equations are then linear in (E', E'')
    with the same −jωs rotation on both, and F = E''/X'' (the paper's transformed state) is the sum of
    two modes dF_k/dt = −b_k·F_k + a_k·V − jsω0·F_k: b_k the eigenvalues' negatives, a_k the residues of
    the transfer function V → F.

    Parameters
    ----------
    m : andes model
        ``ss.Motor5`` after setup (its parameters on the system base).
    i : int
        Index of the device within the model.

    Returns
    -------
    numpy.ndarray
        [[a1, b1], [a2, b2]] [1/s], the slower mode first.
    """
    x0, x1, x2, t10, t20 = (float(getattr(m, k).v[i]) for k in ("x0", "x1", "x2", "T10", "T20"))
    g = (x0 - x1) / (x2 * t10)  # j(X − X')·I/T10 = g·(V − E'')
    h = (x1 - x2) / (x2 * t20)  # j(X' − X'')·I/T20 = h·(V − E'')
    amat = np.array([[-1 / t10, -g], [-1 / t10 + 1 / t20, -g - 1 / t20 - h]])
    bvec = np.array([g, g + h])
    lam, vec = np.linalg.eig(amat)
    cvec = np.array([0.0, 1.0 / x2]) @ vec
    res = cvec * np.linalg.solve(vec, bvec)
    out = sorted(zip(-lam.real, res.real, strict=True))
    return np.array([[r, b] for b, r in out])


@dataclass(frozen=True)
class BusLoad:
    """What sits at the load bus, beyond the network: motors, the static load and its departures.

    Attributes
    ----------
    motors : tuple of (str, dict)
        ANDES model (``"Motor3"`` or ``"Motor5"``) and its data (device base: ``Sn`` [MVA], ``Vn`` [kV],
        reactances and resistances [pu], ``Hm`` [s], torque coefficients ``c1..c3`` [pu, system base]).
    static_pq : (float, float)
        p0, q0 of the static load kept at the bus [pu on 100 MVA] (ZIP with :data:`ZIP_SHARES`).
    fload : dict or None
        ANDES ``FLoad`` data replacing the static load in the simulation (``ap``, ``aq`` voltage and ``bp``,
        ``bq`` frequency exponents [-], ``Tf`` [s]); its frequency is ANDES's ``BusFreq`` at the bus.
    own : dict or None
        Exogenous change of the static load's constant-power part, relative [-]: ``{"kind": "noise", "amp",
        "fc"}`` (its own low-passed noise, cut-off fc [Hz]), ``{"kind": "sine", "amp", "hz", "phase"}`` or
        ``{"kind": "cycle", "amp", "on_s", "off_s"}`` (thermostatic cycling: a share ``amp`` of the part switched
        on and off, each period drawn uniformly from the ``(lo, hi)`` ranges ``on_s``/``off_s`` [s], P and Q together).
    relay : dict or None
        A capacitor bank ``b`` [pu on 100 MVA] switched by a voltage relay: in below V0 − ``dv``, out above
        V0 + ``dv`` [pu] (V0 the power-flow voltage), each after ``delay`` [s] beyond the threshold.
    toggles : tuple of (int, float)
        (index into ``motors``, time [s]): ANDES's ``Toggle`` flips that motor's status ``u`` at that time,
        a load change at a known time.  A motor given ``"u": 0`` in its data is off until its toggle;
        while off, ANDES freezes its states at the power-flow start (its low-slip equilibrium at the
        initial bus voltage, :func:`solve_power_flow`), so it connects running, not from standstill.
    """

    motors: tuple = ()
    static_pq: tuple = STATIC_PQ
    fload: dict | None = None
    own: dict | None = None
    relay: dict | None = None
    toggles: tuple = ()


def simulate(scenario: str, *, tf: float, tstep: float, amp: float, seed: int, tol: float = 1e-8,
             numba: bool = True, model: str = "Motor3", motor_data: dict | None = None) -> dict:
    """Run one of :data:`SCENARIOS` (one motor with :data:`MOTOR` data and a ZIP load at bus 9).

    Parameters
    ----------
    scenario : str
        A key of :data:`SCENARIOS`.
    tf, tstep, amp, seed, tol, numba :
        As in :func:`simulate_load`.
    model : str
        The ANDES motor model, ``"Motor3"`` or ``"Motor5"``.
    motor_data : dict, optional
        Overrides of :data:`MOTOR` and the scenario (device base, e.g. ``{"rs": 0.02}`` or Motor5's ``xr2``,
        ``rr2``).

    Returns
    -------
    dict
        :func:`simulate_load`'s record; for Motor5 also ``modes``, its two rotor modes in the transformed
        model (:func:`rotor_modes`), and ``truth`` then holds the slower one's a, b.
    """
    load = BusLoad(motors=((model, {**MOTOR, **SCENARIOS[scenario], **(motor_data or {})}),))
    out = simulate_load(load, tf=tf, tstep=tstep, amp=amp, seed=seed, tol=tol, numba=numba)
    modes = out["motors"][0].get("modes")
    out["modes"] = modes
    if modes is not None:
        out["truth"][:2] = modes[0]
    return out


def simulate_load(load: BusLoad, *, tf: float, tstep: float, amp: float, seed: int, tol: float = 1e-8,
                  numba: bool = True) -> dict:
    """Run ANDES with ``load`` at bus 9; return its signals on ANDES's step grid, the motors' truth, run facts.

    Parameters
    ----------
    load : BusLoad
        The devices at bus 9.
    tf, tstep : float
        Simulated time and ANDES's fixed step [s].
    amp : float
        Relative std of the ambient noise on the other loads' constant-power part [-].
    seed : int
        Seed of the ambient noise (the load's own departures draw from a stream derived from it).
    tol : float
        ANDES's Newton tolerance.
    numba : bool
        Let ANDES use its numba-compiled equations.

    Returns
    -------
    dict
        ``t`` [s], ``V`` [pu], ``theta`` [rad], ``P``, ``Q`` (the bus's whole load) and ``p_motor``,
        ``q_motor`` (all motors) [pu, 100 MVA]; ``truth`` (D of the first motor), ``motors`` (each motor's
        converted D, slip, rs), ``static_truth``, ``tds_s`` and the ANDES version.
    """
    import andes

    andes.config_logger(stream_level=logging.ERROR)
    ss = andes.load(andes.get_case(CASE), setup=False, no_output=True, default_config=True, numba=numba)
    for k, (model, data) in enumerate(load.motors):
        ss.add(model, {"idx": f"M{k + 1}", "name": f"M{k + 1}", "bus": BUS, **data})
    if load.fload is not None:
        ss.add("FLoad", {"idx": "FL9", "name": "FL9", "pq": PQ_AT_BUS, **load.fload})
    if load.relay is not None:
        ss.add("Shunt", {"idx": "SW9", "name": "SW9", "bus": BUS, "Sn": 100.0, "Vn": 138.0, "b": 0.0, "g": 0.0})
    for j, (k, t_switch) in enumerate(load.toggles):
        ss.add("Toggle", {"idx": f"TG{j + 1}", "model": load.motors[k][0], "dev": f"M{k + 1}", "t": float(t_switch)})
    ss.setup()
    ss.PQ.set("p0", PQ_AT_BUS, load.static_pq[0], base="device")
    ss.PQ.set("q0", PQ_AT_BUS, load.static_pq[1], base="device")
    for k, v in ZIP_SHARES.items():
        setattr(ss.PQ.config, k, v)
    solve_power_flow(ss)
    motors = [_motor_facts(getattr(ss, model), model, i) for model, i in _motor_slots(load.motors)]

    ss.TDS.config.tf = tf
    ss.TDS.config.tstep = tstep
    ss.TDS.config.no_tqdm = 1
    ss.TDS.config.tol = tol
    ss.TDS.init()
    pq = ss.PQ
    u9 = pq.idx2uid(PQ_AT_BUS)
    ub = ss.Bus.idx2uid(BUS)
    others = np.array([i for i in range(pq.n) if i != u9])
    ppf0, qpf0 = pq.Ppf.v.copy(), pq.Qpf.v.copy()
    n = int(round(tf / tstep)) + 2
    rng = np.random.default_rng(seed)
    noise_p = np.stack([lowpass_noise(n, tstep, 2.0, rng) for _ in others], axis=1)
    noise_q = np.stack([lowpass_noise(n, tstep, 2.0, rng) for _ in others], axis=1)
    own_p, own_q = _own_factors(load.own, n, tstep, np.random.default_rng([seed, 1]))
    relay = _Relay(load.relay, ss, ub, tstep, n) if load.relay is not None else None

    def pert(t, system):
        k = min(int(round(float(t) / tstep)), n - 1)
        pq.Ppf.v[others] = ppf0[others] * (1.0 + amp * noise_p[k])
        pq.Qpf.v[others] = qpf0[others] * (1.0 + amp * noise_q[k])
        if own_p is not None:
            pq.Ppf.v[u9] = ppf0[u9] * (1.0 + own_p[k])
            pq.Qpf.v[u9] = qpf0[u9] * (1.0 + own_q[k])
        if relay is not None:
            relay.step(k)

    ss.TDS.callpert = pert
    t_run = time.perf_counter()
    ss.TDS.run()
    t_run = time.perf_counter() - t_run
    if ss.TDS.busted or ss.dae.t < tf - 1e-6:
        raise RuntimeError(f"ANDES TDS stopped at t = {float(ss.dae.t):.3f} s")
    t = np.asarray(ss.dae.ts.t, dtype=float)
    y = np.asarray(ss.dae.ts.y, dtype=float)
    V, th = y[:, ss.Bus.v.a[ub]], y[:, ss.Bus.a.a[ub]]
    pm = sum(y[:, getattr(ss, model).p.a[i]] for model, i in _motor_slots(load.motors))
    qm = sum(y[:, getattr(ss, model).q.a[i]] for model, i in _motor_slots(load.motors))
    # The perturbation set at a step's start acts on the values stored at its end: sample j saw index j − 1.
    k_out = np.clip(np.round(t / tstep).astype(int) - 1, 0, n - 1)
    started = t > tstep / 2
    if load.fload is None:
        ps, qs, static_truth = _zip_static(pq, u9, V, load.own and (own_p[k_out] * started, own_q[k_out] * started))
    else:
        fl = ss.FLoad
        f = y[:, fl.f.a[0]]
        ps = fl.pv0.v[0] * V ** fl.ap.v[0] * f ** fl.bp.v[0]
        qs = fl.qv0.v[0] * V ** fl.aq.v[0] * f ** fl.bq.v[0]
        static_truth = {"pv0": float(fl.pv0.v[0]), "qv0": float(fl.qv0.v[0])}
    if relay is not None:
        qs = qs - relay.b_out(k_out, started) * V**2
    keep = np.concatenate(([True], np.diff(t) > 1e-9))
    first = motors[0] if motors else None
    out = {
        "t": t[keep], "V": V[keep], "theta": th[keep], "P": (pm + ps)[keep], "Q": (qm + qs)[keep],
        "p_motor": np.asarray(pm)[keep] if motors else np.zeros(int(keep.sum())),
        "q_motor": np.asarray(qm)[keep] if motors else np.zeros(int(keep.sum())),
        "motors": motors, "static_truth": static_truth, "tds_s": t_run, "andes_version": andes.__version__,
    }
    if first is not None:
        if load.fload is None:  # the identifier's convention: Qz includes the motor's V²/X'
            static_truth["Qz"] = static_truth["Qz"] + 1.0 / first["x1"]
        out.update(truth=np.array(first["d"]), x0=first["x0"], x1=first["x1"], slip0=first["slip0"],
                   rs_sys=first["rs_sys"], tm_slope=first["tm_slope"])
    if relay is not None:
        out["switchings"] = relay.switchings
    return out


def transformed_d(x0: float, x1: float, t10: float, h2: float, tm: float) -> np.ndarray:
    """D = [a, b, H2, Tm] of a third-order motor with rs = 0 (docs/andes_crosscheck.md).

    Parameters
    ----------
    x0, x1 : float
        Open-circuit and transient reactance X = xs + xm, X' = xs + xr1·xm/(xr1 + xm) [pu, system base].
    t10 : float
        Open-circuit transient time constant T'0 = (xr1 + xm)/(ωb·rr1) [s].
    h2 : float
        2H on the system base [s].
    tm : float
        Load torque [pu, system base].

    Returns
    -------
    numpy.ndarray
        a = (X/X' − 1)/(T'0·X') [1/s], b = X/(T'0·X') [1/s], H2 [s], Tm [pu].
    """
    return np.array([(x0 / x1 - 1) / (t10 * x1), x0 / (t10 * x1), h2, tm])


def _motor_slots(motors: tuple) -> list[tuple[str, int]]:
    """(ANDES model, index within that model) of each motor, in the order they were added."""
    seen: dict[str, int] = {}
    slots = []
    for model, _ in motors:
        slots.append((model, seen.get(model, 0)))
        seen[model] = seen.get(model, 0) + 1
    return slots


def _motor_facts(m, model: str, i: int) -> dict:
    """A motor's D converted to the paper's form (docs/andes_crosscheck.md) and its power-flow facts."""
    x0, x1, t10 = float(m.x0.v[i]), float(m.x1.v[i]), float(m.T10.v[i])
    tm = float(m.tm.v[i])
    if not m.u.v[i]:  # off at the power flow (ANDES's τm is 0 there): its torque law at its start slip
        sl = float(m.slip.v[i])
        tm = float(m.aa.v[i] + m.bb.v[i] * sl + m.c2.v[i] * sl * sl)
    d = transformed_d(x0, x1, t10, float(m.M.v[i]), tm).tolist()
    return {"model": model, "d": d, "x0": x0, "x1": x1, "slip0": float(m.slip.v[i]), "rs_sys": float(m.rs.v[i]),
            "tm_slope": float(m.bb.v[i]), "modes": rotor_modes(m, i).tolist() if model == "Motor5" else None}


def _own_factors(own: dict | None, n: int, tstep: float, rng: np.random.Generator):
    """Relative change of the static load's constant-power P and Q per step (None without one)."""
    if own is None:
        return None, None
    if own["kind"] == "noise":
        return (own["amp"] * lowpass_noise(n, tstep, own["fc"], rng),
                own["amp"] * lowpass_noise(n, tstep, own["fc"], rng))
    if own["kind"] == "cycle":
        # Switched by the appliances' own thermostats, not by the bus voltage: durations drawn up front.
        state = np.zeros(n)
        k, on = 0, bool(rng.integers(2))
        while k < n:
            dur = int(round(rng.uniform(*(own["on_s"] if on else own["off_s"])) / tstep))
            state[k:k + max(dur, 1)] = float(on)
            k, on = k + max(dur, 1), not on
        return own["amp"] * state, own["amp"] * state.copy()
    t = np.arange(n) * tstep
    wave = own["amp"] * np.sin(2 * np.pi * own["hz"] * t + own["phase"])
    return wave, wave.copy()


def _zip_static(pq, u9: int, V: np.ndarray, own: tuple | None) -> tuple[np.ndarray, np.ndarray, dict]:
    """P, Q of the bus's ZIP load from V; its constant-power part scaled by (1 + own) when given."""
    sh = ZIP_SHARES
    # ANDES's PQ in TDS: p2p·Ppf + p2i·Ipeq·v + p2z·Req·v² (Ppf, Ipeq, Req fixed at the power flow).
    zp = np.array([sh["p2z"] * pq.Req.v[u9], sh["p2i"] * pq.Ipeq.v[u9], sh["p2p"] * pq.Ppf.v[u9]])
    zq = np.array([sh["q2z"] * pq.Xeq.v[u9], sh["q2i"] * pq.Iqeq.v[u9], sh["q2q"] * pq.Qpf.v[u9]])
    ps = zp[0] * V**2 + zp[1] * V + zp[2]
    qs = zq[0] * V**2 + zq[1] * V + zq[2]
    if own:
        ps = ps + zp[2] * own[0]
        qs = qs + zq[2] * own[1]
    return ps, qs, {"Pz": zp[0], "Pi": zp[1], "Pp": zp[2], "Qz": zq[0], "Qi": zq[1], "Qp": zq[2]}


class _Relay:
    """A capacitor bank switched by an undervoltage/overvoltage relay with a dead band and a delay."""

    def __init__(self, spec: dict, ss, ub: int, tstep: float, n: int) -> None:
        self.spec, self.ss, self.tstep = spec, ss, tstep
        self.addr = ss.Bus.v.a[ub]
        self.v0 = float(ss.dae.y[self.addr])
        self.uid = ss.Shunt.idx2uid("SW9")  # the case has its own shunt at bus 9 too
        self.on, self.timer = False, 0.0
        self.b_log = np.zeros(n)
        self.switchings = 0

    def step(self, k: int) -> None:
        v = float(self.ss.dae.y[self.addr])
        beyond = v > self.v0 + self.spec["dv"] if self.on else v < self.v0 - self.spec["dv"]
        self.timer = self.timer + self.tstep if beyond else 0.0
        if self.timer >= self.spec["delay"]:
            self.on, self.timer = not self.on, 0.0
            self.switchings += 1
        self.ss.Shunt.b.v[self.uid] = self.spec["b"] if self.on else 0.0
        self.b_log[k] = self.ss.Shunt.b.v[self.uid]

    def b_out(self, k_out: np.ndarray, started: np.ndarray) -> np.ndarray:
        """The susceptance in force at each stored sample [pu]."""
        return self.b_log[k_out] * started


def resample(sim: dict, fs: float = FS) -> dict:
    """Linear interpolation of the ANDES record onto a uniform fs grid from t = 0.

    Parameters
    ----------
    sim : dict
        :func:`simulate_load`'s record.
    fs : float
        Sample rate of the grid [Hz].
    """
    t = sim["t"]
    grid = np.arange(0.0, t[-1] + 1e-9, 1.0 / fs)
    return {"t": grid, **{k: np.interp(grid, t, sim[k]) for k in ("V", "theta", "P", "Q", "p_motor", "q_motor")}}
