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

import numpy as np
from scipy import signal

__all__ = ["BUS", "CASE", "F0", "FS", "MAIN_SCENARIOS", "MOTOR", "NAMES", "PQ_AT_BUS", "SCENARIOS", "STATIC_PQ",
           "ZIP_SHARES", "lowpass_noise", "resample", "simulate", "solve_power_flow"]

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
    """Unit-variance white noise through a 2nd-order Butterworth low-pass at fc [Hz] (causal, burnt in)."""
    sos = signal.butter(2, fc, fs=1.0 / dt, output="sos")
    x = signal.sosfilt(sos, rng.standard_normal(n + burn))[burn:]
    return x / x.std()


def solve_power_flow(ss) -> None:
    """ANDES power flow started from the motors' low-slip equilibrium (:func:`_init_motor_guess`).

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
    """Overwrite ANDES's generic power-flow start of Motor3 (slip 1) with the low-slip equilibrium.

    From ANDES's default start the Newton iteration diverged (KLU segfaulted on this case); starting from
    the paper's closed-form equilibrium at the initial bus voltage converges in a few iterations.
    """
    m, bus, dae = ss.Motor3, ss.Bus, ss.dae
    for i in range(m.n):
        ub = bus.idx2uid(m.bus.v[i])
        v, ang = dae.y[bus.v.a[ub]], dae.y[bus.a.a[ub]]
        va = -v * math.sin(ang) + 1j * v * math.cos(ang)
        x0, x1, t10, wb = m.x0.v[i], m.x1.v[i], m.T10.v[i], m.wb.v[i]
        a, b = (x0 / x1 - 1) / (t10 * x1), x0 / (t10 * x1)
        tm = m.c1.v[i] + m.c2.v[i] + m.c3.v[i]
        c = 2 * tm * b * b / (a * v * v + math.sqrt(a * a * v**4 - 4 * tm * tm * b * b))
        e = x1 * a / (b * b + c * c) * (b - 1j * c) * va
        cur = (va - e) / (1j * x1)
        s = va * np.conj(cur)
        for var, val in ((m.slip, c / wb), (m.e1d, e.real), (m.e1q, e.imag)):
            dae.x[var.a[i]] = val
        for var, val in ((m.vd, va.real), (m.vq, va.imag), (m.Id, cur.real), (m.Iq, cur.imag),
                         (m.p, s.real), (m.q, s.imag), (m.te, (e * np.conj(cur)).real), (m.tm, tm)):
            dae.y[var.a[i]] = val


def simulate(scenario: str, *, tf: float, tstep: float, amp: float, seed: int, tol: float = 1e-8,
             numba: bool = True) -> dict:
    """Run ANDES; return bus-9 signals on ANDES's step grid, the converted truth and run facts."""
    import andes

    andes.config_logger(stream_level=logging.ERROR)
    ss = andes.load(andes.get_case(CASE), setup=False, no_output=True, default_config=True, numba=numba)
    ss.add("Motor3", {"idx": "M1", "name": "M1", "bus": BUS, **MOTOR, **SCENARIOS[scenario]})
    ss.setup()
    ss.PQ.set("p0", PQ_AT_BUS, STATIC_PQ[0], base="device")
    ss.PQ.set("q0", PQ_AT_BUS, STATIC_PQ[1], base="device")
    for k, v in ZIP_SHARES.items():
        setattr(ss.PQ.config, k, v)
    solve_power_flow(ss)
    m, pq = ss.Motor3, ss.PQ
    x0, x1, t10, M = float(m.x0.v[0]), float(m.x1.v[0]), float(m.T10.v[0]), float(m.M.v[0])
    truth = np.array([(x0 / x1 - 1) / (t10 * x1), x0 / (t10 * x1), M, float(m.tm.v[0])])
    slip0 = float(m.slip.v[0])

    ss.TDS.config.tf = tf
    ss.TDS.config.tstep = tstep
    ss.TDS.config.no_tqdm = 1
    ss.TDS.config.tol = tol
    ss.TDS.init()
    u9 = pq.idx2uid(PQ_AT_BUS)
    others = np.array([i for i in range(pq.n) if i != u9])
    ppf0, qpf0 = pq.Ppf.v.copy(), pq.Qpf.v.copy()
    n = int(round(tf / tstep)) + 2
    rng = np.random.default_rng(seed)
    noise_p = np.stack([lowpass_noise(n, tstep, 2.0, rng) for _ in others], axis=1)
    noise_q = np.stack([lowpass_noise(n, tstep, 2.0, rng) for _ in others], axis=1)

    def pert(t, system):
        k = min(int(round(float(t) / tstep)), n - 1)
        pq.Ppf.v[others] = ppf0[others] * (1.0 + amp * noise_p[k])
        pq.Qpf.v[others] = qpf0[others] * (1.0 + amp * noise_q[k])

    ss.TDS.callpert = pert
    t_run = time.perf_counter()
    ss.TDS.run()
    t_run = time.perf_counter() - t_run
    if ss.TDS.busted or ss.dae.t < tf - 1e-6:
        raise RuntimeError(f"ANDES TDS stopped at t = {float(ss.dae.t):.3f} s")
    ts = ss.dae.ts
    t = np.asarray(ts.t, dtype=float)
    y = np.asarray(ts.y, dtype=float)
    ub = ss.Bus.idx2uid(BUS)
    V, th = y[:, ss.Bus.v.a[ub]], y[:, ss.Bus.a.a[ub]]
    pm, qm = y[:, m.p.a[0]], y[:, m.q.a[0]]
    sh = ZIP_SHARES
    # ANDES's PQ in TDS: p2p·Ppf + p2i·Ipeq·v + p2z·Req·v² (Ppf, Ipeq, Req fixed at the power flow).
    zp = np.array([sh["p2z"] * pq.Req.v[u9], sh["p2i"] * pq.Ipeq.v[u9], sh["p2p"] * pq.Ppf.v[u9]])
    zq = np.array([sh["q2z"] * pq.Xeq.v[u9], sh["q2i"] * pq.Iqeq.v[u9], sh["q2q"] * pq.Qpf.v[u9]])
    ps = zp[0] * V**2 + zp[1] * V + zp[2]
    qs = zq[0] * V**2 + zq[1] * V + zq[2]
    keep = np.concatenate(([True], np.diff(t) > 1e-9))
    return {
        "t": t[keep], "V": V[keep], "theta": th[keep], "P": (pm + ps)[keep], "Q": (qm + qs)[keep],
        "p_motor": pm[keep], "q_motor": qm[keep], "truth": truth, "x1": x1, "slip0": slip0,
        "static_truth": {"Pz": zp[0], "Pi": zp[1], "Pp": zp[2], "Qz": zq[0] + 1.0 / x1, "Qi": zq[1], "Qp": zq[2]},
        "tds_s": t_run, "andes_version": andes.__version__,
        "rs_sys": float(m.rs.v[0]), "tm_slope": float(m.bb.v[0]),
    }


def resample(sim: dict, fs: float = FS) -> dict:
    """Linear interpolation of the ANDES record onto a uniform fs grid from t = 0."""
    t = sim["t"]
    grid = np.arange(0.0, t[-1] + 1e-9, 1.0 / fs)
    return {"t": grid, **{k: np.interp(grid, t, sim[k]) for k in ("V", "theta", "P", "Q", "p_motor", "q_motor")}}
