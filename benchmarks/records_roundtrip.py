"""Round trip of the exported records through ANDES (issue 14's proof; docs/records.md).

1. ``roundtrip``: an identified model → ANDES case (Motor3 + ZIP on a PQ, two-bus system behind a
   reactance) → ANDES power flow and a fault + a voltage sag → bus P, Q compared with the identified
   model's own playback (aslm_core.diagnosis.playback.model_power) on ANDES's bus voltage: FD of P and Q.
2. ``xp_sweep``: the same for X' across its admissible interval: how much the large-disturbance
   responses differ between records that all reproduce D (the free assumption's effect).
3. ``truth``: ANDES recording with known truth (benchmarks/andes_crosscheck.py, IEEE 14-bus, bus 9) →
   identify → export → the exported load replaces the true one → the same fault in both → FD of the
   record's P, Q against the true load's.

    .venv/bin/python -m benchmarks.records_roundtrip [--quick] [--json out.json] [--figure docs/records_xp.png]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import os
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

from aslm_core.records import Assumptions, MotorRecord, admissible, invert
from aslm_core.records import andes as ra
from benchmarks.andes_crosscheck import solve_power_flow

# A fault (deep sag, cleared) then a shallow sag (a more distant fault), on the load bus [s, pu].
EVENTS = [{"tf": 1.0, "tc": 1.1, "xf": 0.02, "rf": 0.0}, {"tf": 2.0, "tc": 2.5, "xf": 0.2, "rf": 0.0}]
X_LINE = 0.05
TRIP_AT = 2.8  # [s] the motor trips in the X' sweep: what differs between records of the same D


def _load(path: str, **kw):
    import andes

    andes.config_logger(stream_level=logging.ERROR)
    ss = andes.load(path, no_output=True, default_config=True, setup=False, **kw)
    return ss




def _bus_load(ss, bus_uid: int) -> dict:
    """t, V, θ and the load P, Q (every Motor3 + ZIP on the bus, and PQs still in service) from the run."""
    ts = ss.dae.ts
    t = np.asarray(ts.t, dtype=float)
    y = np.asarray(ts.y, dtype=float)
    V, th = y[:, ss.Bus.v.a[bus_uid]], y[:, ss.Bus.a.a[bus_uid]]
    bus_idx = ss.Bus.idx.v[bus_uid]
    P, Q = np.zeros_like(V), np.zeros_like(V)
    m = ss.Motor3
    for i in range(m.n):
        if m.bus.v[i] == bus_idx:
            P += y[:, m.p.a[i]]
            Q += y[:, m.q.a[i]]
    Pm, Qm = P.copy(), Q.copy()
    z = ss.ZIP
    for i in range(z.n):
        if z.bus.v[i] == bus_idx:
            P += z.pp0.v[i] + z.pi0.v[i] * V + z.pz0.v[i] * V**2
            Q += z.qp0.v[i] + z.qi0.v[i] * V + z.qz0.v[i] * V**2
    keep = np.concatenate(([True], np.diff(t) > 1e-9))
    return {"t": t[keep], "V": V[keep], "theta": th[keep], "P": P[keep], "Q": Q[keep], "P_motor": Pm[keep],
            "Q_motor": Qm[keep]}


def _tds(ss, tf: float, tstep: float) -> None:
    ss.TDS.config.tf = tf
    ss.TDS.config.tstep = tstep
    ss.TDS.config.no_tqdm = 1
    ss.TDS.config.tol = 1e-8
    ss.TDS.init()
    ss.TDS.run()
    if ss.TDS.busted or ss.dae.t < tf - 1e-6:
        raise RuntimeError(f"ANDES TDS stopped at t = {float(ss.dae.t):.3f} s")


def uniform(rec: dict, dt: float) -> dict:
    """The record linearly interpolated onto a uniform grid of step dt [s] from its first time."""
    grid = np.arange(rec["t"][0], rec["t"][-1] + 1e-9, dt)
    return {"t": grid, **{k: np.interp(grid, rec["t"], rec[k]) for k in ("V", "theta", "P", "Q", "P_motor", "Q_motor")
                          if k in rec}}


def fd(y: np.ndarray, model: np.ndarray) -> float:
    """Fit degree (paper eq. 9)."""
    from aslm_core.diagnosis.engine import fd as fit_degree

    return fit_degree(y, model)


@contextlib.contextmanager
def _solved(case: dict):
    """The ANDES system of a JSON case, set up and its power flow solved (inside a temporary folder, where
    ANDES may also write its outputs)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "case.json")
        with open(path, "w") as fh:
            fh.write(ra.dumps(case))
        ss = _load(path)
        ss.setup()
        solve_power_flow(ss)
        yield ss


def exported_two_bus(identified: dict, asm: Assumptions, events: list[dict], iterations: int = 4) -> tuple[MotorRecord, dict]:
    """The record at the power-flow voltage of its bus: export, solve, re-export at the solved voltage."""
    v0 = asm.v0
    for _ in range(iterations):
        rec = invert(identified["dynamic"], identified["static"], replace(asm, v0=v0))
        case = ra.two_bus_case(rec, x_line=X_LINE, faults=events)
        with _solved(case) as ss:
            v_pf = float(ss.Bus.v.v[1])
        if abs(v_pf - v0) < 1e-10:
            break
        v0 = v_pf
    return rec, case


def run_case(case: dict, *, tf: float, tstep: float, bus_uid: int = 1) -> dict:
    """Load an ANDES JSON case, solve its power flow and its time domain; the load of bus ``bus_uid``."""
    with _solved(case) as ss:
        _tds(ss, tf, tstep)
        return _bus_load(ss, bus_uid)


def roundtrip(identified: dict, asm: Assumptions, *, tf: float = 3.0, tstep: float = 0.002,
              events: list[dict] | None = None, trip_at: float | None = None) -> dict:
    """FD of the exported record's P, Q in ANDES against the identified model's playback on the same V, θ.

    ``trip_at`` [s]: the motor is switched off then (an ANDES ``Toggle``), what an undervoltage relay does;
    the playback has no trip, so the FD covers the time before it.
    """
    from aslm_core.diagnosis.playback import model_power

    events = EVENTS if events is None else events
    rec, case = exported_two_bus(identified, asm, events)
    if trip_at is not None:
        motor = case["Motor3"][0]["idx"]
        case["Toggle"] = [{"idx": "TRIP", "u": 1, "name": "TRIP", "model": "Motor3", "dev": motor, "t": trip_at}]
    t0 = time.perf_counter()
    out = uniform(run_case(case, tf=tf, tstep=tstep), tstep)
    tds_s = time.perf_counter() - t0
    p_pb, q_pb = model_power(out["V"], out["theta"], identified, tstep, asm.f0)
    before = out["t"] < (trip_at if trip_at is not None else math.inf) - 1e-9
    return {"xp": rec.values["Xp"], "td0": rec.values["Td0"], "v0": rec.values["v0"],
            "q_motor": rec.values["Q_motor"], "qz_static": rec.values["Qz"], "motor_x": rec.values["X"],
            "fd_p": fd(out["P"][before], p_pb[before]), "fd_q": fd(out["Q"][before], q_pb[before]),
            "v_min": float(out["V"].min()),
            "tds_s": tds_s, "signals": out, "playback": {"P": p_pb, "Q": q_pb}}


def xp_sweep(identified: dict, asm: Assumptions, n: int = 5, **kw) -> list[dict]:
    """The round trip for X' across its admissible interval (edges excluded: they are singular), the motor
    tripping at :data:`TRIP_AT` after the fault and the sag."""
    d = np.array([identified["dynamic"][k] for k in ("a", "b", "H2", "Tm")])
    lo, hi = admissible(d, identified["static"], asm)["xp"]
    xps = np.linspace(lo, hi, n + 2)[1:-1]
    return [roundtrip(identified, replace(asm, xp=float(x), td0=None), trip_at=TRIP_AT, tf=TRIP_AT + 0.5, **kw)
            for x in xps]


def ac_x1() -> float:
    """X' of the cross-check's motor on the system base (x1 of docs/andes_crosscheck.md)."""
    from benchmarks import andes_crosscheck as ac

    m, r = ac.MOTOR, 100.0 / ac.MOTOR["Sn"]
    return (m["xs"] + m["xr1"] * m["xm"] / (m["xr1"] + m["xm"])) * r


def truth(*, tstep: float = 0.005, tf_fault: float = 3.0) -> dict:
    """ANDES recording with known truth → identify → export → fault in ieee14 with both loads at bus 9."""
    import andes

    from aslm_core import Window, identify
    from benchmarks import andes_crosscheck as ac

    sim = ac.simulate("model", tf=12.5, tstep=tstep, amp=0.15, seed=1, tol=1e-8)
    r = ac.resample(sim)
    sl = r["t"] >= 2.5 - 1e-9
    w = Window(r["t"][sl], r["V"][sl], r["theta"][sl], r["P"][sl], r["Q"][sl], f0=ac.F0, bus="andes")
    res = identify(w)
    identified = {"dynamic": res.dynamic, "static": res.static}
    v9 = float(np.mean(w.V))

    def fault_run(with_record: MotorRecord | None) -> dict:
        andes.config_logger(stream_level=logging.ERROR)
        ss = andes.load(andes.get_case(ac.CASE), setup=False, no_output=True, default_config=True)
        if with_record is None:
            ss.add("Motor3", {"idx": "M1", "name": "M1", "bus": ac.BUS, **ac.MOTOR, **ac.SCENARIOS["model"]})
        else:
            dev = ra.devices(with_record, bus=ac.BUS, kv=138.0)
            ss.add("Motor3", dev["Motor3"][0])
            ss.add("ZIP", {**dev["ZIP"][0], "pq": ac.PQ_AT_BUS})
        ss.add("Fault", {"idx": "F1", "name": "F1", "bus": ac.BUS, "tf": 1.0, "tc": 1.1, "xf": 0.05, "rf": 0.0})
        ss.setup()
        for k, v in ac.ZIP_SHARES.items():
            setattr(ss.PQ.config, k, v)
        if with_record is None:
            ss.PQ.set("p0", ac.PQ_AT_BUS, ac.STATIC_PQ[0], base="device")
            ss.PQ.set("q0", ac.PQ_AT_BUS, ac.STATIC_PQ[1], base="device")
        else:
            ss.PQ.set("p0", ac.PQ_AT_BUS, with_record.values["P_static"], base="device")
            ss.PQ.set("q0", ac.PQ_AT_BUS, with_record.values["Q_static"], base="device")
        solve_power_flow(ss)
        v_pf = float(ss.Bus.v.v[ss.Bus.idx2uid(ac.BUS)])
        _tds(ss, tf_fault, tstep)
        out = _bus_load(ss, ss.Bus.idx2uid(ac.BUS))
        if with_record is None:  # the true static load: ANDES's PQ with the global ZIP shares
            pq, u9, sh, V = ss.PQ, ss.PQ.idx2uid(ac.PQ_AT_BUS), ac.ZIP_SHARES, out["V"]
            out["P"] = out["P"] + sh["p2z"] * pq.Req.v[u9] * V**2 + sh["p2i"] * pq.Ipeq.v[u9] * V + sh["p2p"] * pq.Ppf.v[u9]
            out["Q"] = out["Q"] + sh["q2z"] * pq.Xeq.v[u9] * V**2 + sh["q2i"] * pq.Iqeq.v[u9] * V + sh["q2q"] * pq.Qpf.v[u9]
        out["v_pf"] = v_pf
        return out

    base = fault_run(None)
    rec = invert(identified["dynamic"], identified["static"], Assumptions(f0=ac.F0, v0=base["v_pf"]))
    for _ in range(3):  # the record at its own power-flow voltage
        got = fault_run(rec)
        if abs(got["v_pf"] - rec.values["v0"]) < 1e-9:
            break
        rec = invert(identified["dynamic"], identified["static"], Assumptions(f0=ac.F0, v0=got["v_pf"]))
    a, b = uniform(base, tstep), uniform(got, tstep)
    n = min(a["t"].size, b["t"].size)
    return {"identified": identified, "truth_d": sim["truth"].tolist(), "window_v_mean": v9,
            "fd_p": fd(a["P"][:n], b["P"][:n]), "fd_q": fd(a["Q"][:n], b["Q"][:n]),
            # The motor alone (its Q without V²/X': the split between motor and static is the assumption's).
            "fd_p_motor": fd(a["P_motor"][:n], b["P_motor"][:n]),
            "fd_q_motor": fd(a["Q_motor"][:n] - a["V"][:n] ** 2 / ac_x1(), b["Q_motor"][:n] - b["V"][:n] ** 2 / rec.values["Xp_sys"]),
            "static_truth": sim["static_truth"], "static_identified": res.static,
            "v_min_truth": float(a["V"].min()), "v_min_record": float(b["V"].min()),
            "xp_record": rec.values["Xp"], "xp_truth": 0.1 + 0.1 * 3.0 / 3.1}


def _figure(sweep: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for r in sweep:
        s = r["signals"]
        lab = f"X' = {r['xp']:.3f} (Td0 = {r['td0']:.3f} s)"
        ax[0].plot(s["t"], s["V"], lw=0.8, label=lab)
        ax[1].plot(s["t"], s["P"], lw=0.8)
        ax[2].plot(s["t"], s["Q"], lw=0.8)
    ax[0].set_ylabel("V [pu]")
    ax[1].set_ylabel("P [pu]")
    ax[2].set_ylabel("Q [pu]")
    ax[2].set_xlabel("t [s]")
    ax[0].legend(fontsize=7)
    ax[0].set_title(f"ANDES records across X' (motor base), same D: fault, sag, motor trip at {TRIP_AT:g} s", fontsize=9)
    for a in ax:
        a.axvline(TRIP_AT, color="k", lw=0.5, ls=":")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="skip the IEEE 14-bus truth run; 3 X' values")
    p.add_argument("--json", default=None)
    p.add_argument("--figure", default=None, help="write the X' sweep figure (PNG) here")
    p.add_argument("--truth-tstep", type=float, default=0.005, help="ANDES step of the truth runs [s]")
    args = p.parse_args(argv)
    from benchmarks import andes_crosscheck as ac

    # The converted truth of the cross-check's motor (docs/andes_crosscheck.md) with its static part.
    identified = {"dynamic": {"a": 22.796, "b": 19.159, "H2": 1.0, "Tm": 0.2},
                  "static": {"Pz": 0.06, "Pi": 0.045, "Pp": 0.045, "Qz": 0.04 + 1.2705, "Qi": 0.03, "Qp": 0.03}}
    asm = Assumptions(f0=ac.F0)
    out: dict = {"events": EVENTS, "x_line": X_LINE, "identified": identified}
    base = roundtrip(identified, asm)
    out["roundtrip"] = {k: v for k, v in base.items() if k not in ("signals", "playback")}
    print(f"round trip (X' = {base['xp']:.3f}, v0 = {base['v0']:.5f}): FD_P {base['fd_p']:.6f}, "
          f"FD_Q {base['fd_q']:.6f}, V min {base['v_min']:.3f}, ANDES TDS {base['tds_s']:.1f} s")
    sweep = xp_sweep(identified, asm, n=3 if args.quick else 5)
    ref = sweep[len(sweep) // 2]["signals"]
    rows = []
    for r in sweep:
        s = r["signals"]
        n = min(s["t"].size, ref["t"].size)
        after = s["t"][:n] > TRIP_AT + 0.3  # settled after the trip
        rows.append({"p_after_trip": float(np.mean(s["P"][:n][after])), "q_after_trip": float(np.mean(s["Q"][:n][after])),"xp": r["xp"], "td0": r["td0"], "fd_p": r["fd_p"], "fd_q": r["fd_q"], "v_min": r["v_min"],
                     "q_motor": r["q_motor"], "qz_static": r["qz_static"], "motor_x": r["motor_x"],
                     "max_dp_vs_mid": float(np.max(np.abs(s["P"][:n] - ref["P"][:n])[s["t"][:n] < TRIP_AT])),
                     "max_dq_vs_mid": float(np.max(np.abs(s["Q"][:n] - ref["Q"][:n])[s["t"][:n] < TRIP_AT]))})
        print(f"X' {r['xp']:.3f}  Td0 {r['td0']:.3f} s  FD_P {r['fd_p']:.6f}  FD_Q {r['fd_q']:.6f}  "
              f"V min {r['v_min']:.3f}  before the trip max|ΔP| {rows[-1]['max_dp_vs_mid']:.4f}  max|ΔQ| {rows[-1]['max_dq_vs_mid']:.4f}  "
              f"Q_motor(v0) {r['q_motor']:.4f}  Qz_static {r['qz_static']:.4f}  X {r['motor_x']:.3f}  "
              f"after trip P {rows[-1]['p_after_trip']:.4f} Q {rows[-1]['q_after_trip']:.4f}")
    out["xp_sweep"] = rows
    if args.figure:
        _figure(sweep, args.figure)
    if not args.quick:
        tr = truth(tstep=args.truth_tstep)
        out["truth"] = tr
        print(f"truth (IEEE 14 bus 9, fault): FD_P {tr['fd_p']:.5f}, FD_Q {tr['fd_q']:.5f}; motor alone "
              f"FD_P {tr['fd_p_motor']:.5f}, FD_Q−V²/X' {tr['fd_q_motor']:.5f}; "
              f"X' record {tr['xp_record']:.3f} vs truth {tr['xp_truth']:.4f}; identified D {tr['identified']['dynamic']}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
