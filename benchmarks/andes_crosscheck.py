"""Cross-check of the identifier against an independent simulator: ANDES (Motor3 + ZIP in IEEE 14-bus).

A third-order induction motor (ANDES ``Motor3``) and a ZIP static load share bus 9 of ANDES's
``ieee14/ieee14_full.xlsx`` (GENROU machines, exciters, governors).  Every *other* load's
constant-power part is driven by independent 2 Hz low-passed white noise (ambient excitation);
ANDES integrates the whole DAE (implicit trapezoid, fixed step), and bus 9's V, θ and total load
P, Q (motor + static), resampled to 100 Hz, go through :func:`aslm_core.identify` in 10 s windows.

Conversion of Motor3 (ANDES ``models/motor/motorbase.py``, ``motor3.py``; all on the system base
after ANDES's per-unit conversion of the device data, z-type parameters × (Sb/Sn)·(Vn/Vb)², Hm × Sn/Sb)::

    X   = x0  = xs + xm
    X'  = x1  = xs + xr1·xm/(xr1 + xm)
    Td0 = T10 = (xr1 + xm)/(ωb·rr1),   ωb = 2π·fn
    a = (X/X' − 1)/(Td0·X'),   b = X/(Td0·X'),   H2 = M = 2·Hm (system base),   Tm = τm at the power flow

ANDES writes ``M·dσ/dt = τm − τe`` with ``τm = (c1+c2+c3) + (−c2−2c3)·σ + c2·σ²`` (its source uses c2,
not c3, in the quadratic term) and the stator algebra ``v − e' = (rs + j·x')·i``; with rs = 0 and
c2 = c3 = 0 this is exactly the paper's eq. 1 (ANDES's vd + j·vq = j·V·e^{jθ} is a 90° rotation of the
paper's frame, to which the model is invariant).

The system and the simulation are :mod:`aslm_sim.andes.scenario`; this module checks the identifier on it.

Two scenarios: ``model`` (rs ≈ 0, constant torque: the identifier's assumptions) and
``andes_default`` (ANDES's default rs = 0.01 and torque coefficients c1 = 0.1, c2 = c3 = 0.02; the
other motor data are the same).  Run::

    .venv/bin/python -m benchmarks.andes_crosscheck [--quick]
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from aslm_core import IdentifyConfig, Window, identify, motor
from aslm_core.identify import Problem
from aslm_core.preprocess import prepare

# The scenario lives in aslm_sim.andes; these names stay importable from here (other benchmarks use them).
from aslm_sim.andes.scenario import (  # noqa: F401
    BUS,
    CASE,
    F0,
    FS,
    MAIN_SCENARIOS,
    MOTOR,
    NAMES,
    PQ_AT_BUS,
    SCENARIOS,
    STATIC_PQ,
    ZIP_SHARES,
    lowpass_noise,
    resample,
    rotor_modes,
    simulate,
    solve_power_flow,
)


def noisy_window(rec: dict, t0: float, t1: float, snr_db: float, rng: np.random.Generator) -> Window:
    """The resampled record's [t0, t1] as a Window, white noise added to P and Q at ``snr_db`` (each channel's std)."""
    sl = (rec["t"] >= t0 - 1e-9) & (rec["t"] <= t1 + 1e-9)
    P, Q = rec["P"][sl].copy(), rec["Q"][sl].copy()
    for x in (P, Q):
        x += rng.standard_normal(x.size) * np.std(x) * 10 ** (-snr_db / 20)
    return Window(rec["t"][sl], rec["V"][sl], rec["theta"][sl], P, Q, f0=F0, bus=f"andes-bus{BUS}")


def conversion_check(rec: dict, sim: dict) -> dict:
    """Drive the identifier's motor model (eq. 4–5, RK4) with truth D on ANDES's V, θ from t = 0 and compare
    with ANDES's Motor3 output: relative RMS error of the fluctuations of P and of Q − V²/X'."""
    p, q, _ = motor.simulate(rec["V"], rec["theta"], sim["truth"], 1.0 / FS, motor.omega0_of(F0))
    pa = rec["p_motor"]
    qa = rec["q_motor"] - rec["V"] ** 2 / sim["x1"]
    sl = slice(int(2 * FS), None)
    return {"p": float(np.std((p - pa)[sl]) / np.std(pa[sl])), "q": float(np.std((q - qa)[sl]) / np.std(qa[sl])),
            "p_offset": float(np.mean((p - pa)[sl]))}


def fd_at(window: Window, d: np.ndarray, config: IdentifyConfig) -> tuple[float, float, float]:
    """FD of P and Q and the eq. 7 objective of a given D on a window (truth reference)."""
    prob = Problem(prepare(window, max_gap_samples=config.max_gap_samples, min_duration_s=config.min_duration_s,
                          lowpass_hz=config.lowpass_hz), window.f0, config)
    out = prob.residuals(np.asarray(d, dtype=float), jacobian=False)
    if out is None:
        return float("nan"), float("nan"), float("nan")
    rp, rq, _, _ = out
    pc, qc = prob.p_meas - prob.p_meas.mean(), prob.q_meas - prob.q_meas.mean()
    return (1 - float(rp @ rp) / float(pc @ pc), 1 - float(rq @ rq) / float(qc @ qc),
            (math.sqrt(rp @ rp) + math.sqrt(rq @ rq)) / prob.l)


def run_scenario(scenario: str, *, tf: float, tstep: float, amp: float, seed: int, windows: list[tuple[float, float]],
                 meas_snr_db: float | None, config: IdentifyConfig) -> dict:
    sim = simulate(scenario, tf=tf, tstep=tstep, amp=amp, seed=seed)
    rec = resample(sim)
    conv = conversion_check(rec, sim)
    rng = np.random.default_rng(seed + 1)
    rows = []
    for t0, t1 in windows:
        sl = (rec["t"] >= t0 - 1e-9) & (rec["t"] <= t1 + 1e-9)
        P, Q = rec["P"][sl].copy(), rec["Q"][sl].copy()
        if meas_snr_db is not None:
            for x in (P, Q):
                x += rng.standard_normal(x.size) * np.std(x) * 10 ** (-meas_snr_db / 20)
        w = Window(rec["t"][sl], rec["V"][sl], rec["theta"][sl], P, Q, f0=F0, bus=f"andes-ieee14-bus{BUS}")
        res = identify(w, config=config)
        fdp_t, fdq_t, of_t = fd_at(w, sim["truth"], config)
        vbar, st, zt = float(np.mean(w.V)), res.static, sim["static_truth"]
        # The ZIP split is not identifiable from ±0.2 % voltage; the static power at the mean voltage is.
        static_ratio = [(st[z] * vbar**2 + st[i] * vbar + st[c]) / (zt[z] * vbar**2 + zt[i] * vbar + zt[c])
                        for z, i, c in (("Pz", "Pi", "Pp"), ("Qz", "Qi", "Qp"))]
        rows.append({
            "window": [t0, t1], "d": res.d.tolist(), "ratio": (res.d / sim["truth"]).tolist(),
            "stderr": [res.stderr[k] for k in NAMES], "fd_p": res.fit["fd_p"], "fd_q": res.fit["fd_q"],
            "objective": res.objective, "fd_p_truth": fdp_t, "fd_q_truth": fdq_t, "objective_truth": of_t,
            "static_ratio": static_ratio, "flags": res.flags, "v_std_rel": res.quality["v_std_rel"], "static": res.static, "elapsed_s": res.elapsed_s,
        })
    return {"scenario": scenario, "truth": sim["truth"].tolist(), "static_truth": sim["static_truth"],
            "slip0": sim["slip0"], "rs_sys": sim["rs_sys"], "tm_slope": sim["tm_slope"], "conversion": conv,
            "tds_s": sim["tds_s"], "andes_version": sim["andes_version"], "meas_snr_db": meas_snr_db, "rows": rows}


def print_report(results: list[dict], args) -> None:
    print(f"ANDES {results[0]['andes_version']}; case {CASE}, bus {BUS}; tstep {args.tstep} s, tf {args.tf} s, "
          f"ambient amplitude {args.amp} (relative, on the constant-power part), seed {args.seed}")
    for r in results:
        tr = r["truth"]
        c = r["conversion"]
        print(f"\n### {r['scenario']} (meas. SNR {r['meas_snr_db']} dB): truth D = "
              + ", ".join(f"{k}={v:.4g}" for k, v in zip(NAMES, tr, strict=True))
              + f"; slip0 {r['slip0']:.4f}, rs(sys) {r['rs_sys']:.3g}, dTm/dσ {r['tm_slope']:.3g}; ANDES TDS {r['tds_s']:.1f} s")
        print(f"conversion check (eq. 4–5 with truth D vs Motor3): rel. RMS error P {c['p']:.3%}, "
              f"Q−V²/X' {c['q']:.3%}, mean P offset {c['p_offset']:.2e} pu")
        print("| window [s] | a | b | H2 | Tm | a/a0 | b/b0 | H2/H20 | Tm/Tm0 | FD_P | FD_Q | FD_P,Q @truth "
              "| OF / OF@truth | Pst/Pst0, Qst/Qst0 at V̄ | V std | flags |")
        print("|---|" + "---|" * 15)
        for w in r["rows"]:
            d, q = w["d"], w["ratio"]
            print(f"| {w['window'][0]:g}–{w['window'][1]:g} | " + " | ".join(f"{x:.4g}" for x in d) + " | "
                  + " | ".join(f"{x:.3f}" for x in q)
                  + f" | {w['fd_p']:.4f} | {w['fd_q']:.4f} | {w['fd_p_truth']:.4f}, {w['fd_q_truth']:.4f} "
                  f"| {w['objective'] / w['objective_truth']:.3f} | {w['static_ratio'][0]:.3f}, {w['static_ratio'][1]:.3f} "
                  f"| {w['v_std_rel']:.2%} | "
                  f"{', '.join(w['flags']) or '–'} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="12.5 s at a 10 ms step per scenario, one window each")
    p.add_argument("--scenario", choices=[*SCENARIOS, "all"], default="all")
    p.add_argument("--tstep", type=float, default=None, help="ANDES fixed step [s] (default 0.005, quick 0.01)")
    p.add_argument("--tf", type=float, default=None, help="simulated time [s] (default 16, quick 12.5)")
    p.add_argument("--amp", type=float, default=0.15, help="relative std of the ambient load noise")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--meas-snr-db", type=float, default=None, help="add white measurement noise to P, Q")
    p.add_argument("--json", type=str, default=None, help="write the results to this JSON file")
    args = p.parse_args(argv)
    args.tf = args.tf or (12.5 if args.quick else 16.0)
    args.tstep = args.tstep or (0.01 if args.quick else 0.005)
    windows = [(args.tf - 10.0, args.tf)] if args.quick else [(2.0, 12.0), (args.tf - 10.0, args.tf)]
    scen = list(MAIN_SCENARIOS) if args.scenario == "all" else [args.scenario]
    config = IdentifyConfig()
    results = [run_scenario(s, tf=args.tf, tstep=args.tstep, amp=args.amp, seed=args.seed, windows=windows,
                            meas_snr_db=args.meas_snr_db, config=config) for s in scen]
    print_report(results, args)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
