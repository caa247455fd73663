"""Diagnosis on recordings from an independent simulator: ANDES (Motor3 + ZIP at bus 9 of IEEE 14-bus).

Reuses the set-up of :mod:`benchmarks.andes_crosscheck` (ambient load noise on every other load, ANDES's
own DAE integration, bus-9 V, θ, P, Q resampled to 100 Hz) and diagnoses 10 s windows of four scenarios:

* ``model``: rs ≈ 0, constant torque — the identifier's assumptions: the right answer is ``consistent``;
* ``torque_only``: ANDES's default torque–speed coefficients (c2 = c3 = 0.02): a speed-dependent torque;
* ``rs_only``: stator resistance rs = 0.01 (a static stator loss, not stator *dynamics*; no library
  candidate models it exactly);
* ``andes_default``: both.

White measurement noise is added to P and Q at the given SNR (relative to each channel's std).  Run::

    .venv/bin/python -m benchmarks.diagnosis_andes [--quick] [--snr-db 28]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from aslm_core import warmup
from aslm_core.diagnosis import diagnose
from benchmarks.andes_crosscheck import noisy_window, resample, simulate

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "results" / "diagnosis_andes.json"
SCENARIOS = ("model", "torque_only", "rs_only", "andes_default")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="one 10 s window per scenario at a 10 ms ANDES step")
    p.add_argument("--snr-db", type=float, nargs="+", default=[28.0, 22.0])
    p.add_argument("--seeds", type=int, default=2, help="independent ambient realisations per scenario")
    p.add_argument("--no-write", action="store_true")
    args = p.parse_args(argv)
    warmup()
    tf, tstep = (12.5, 0.01) if args.quick else (22.0, 0.005)
    windows = [(tf - 10.0, tf)] if args.quick else [(2.0, 12.0), (12.0, 22.0)]
    seeds = range(1, 2 if args.quick else args.seeds + 1)
    rows = []
    for scen in SCENARIOS:
        for seed in seeds:
            sim = simulate(scen, tf=tf, tstep=tstep, amp=0.15, seed=seed)
            rec = resample(sim)
            for snr in args.snr_db:
                rng = np.random.default_rng([seed, int(snr * 10)])
                for t0, t1 in windows:
                    w = noisy_window(rec, t0, t1, snr, rng)
                    t_ = time.perf_counter()
                    rep = diagnose(w)
                    top = rep.missing_physics[0]
                    rows.append({"scenario": scen, "seed": seed, "snr_db": snr, "window": [t0, t1],
                                 "verdict": rep.verdict, "cause": rep.cause, "top": top.name,
                                 "top_z": top.score_z, "top_parameters": top.parameters,
                                 "located": rep.located.channels, "fit_before": rep.fit_before.to_dict(),
                                 "fit_after": rep.fit_after.to_dict(), "elapsed_s": time.perf_counter() - t_})
                    r = rows[-1]
                    print(f"{scen:14s} seed {seed} SNR {snr:4.1f} dB [{t0:4.1f},{t1:4.1f}] s: {r['verdict']:11s} "
                          f"{r['cause'] or '-':24s} top {r['top']} z={r['top_z']:.1f} "
                          f"{ {k: round(v, 4) for k, v in r['top_parameters'].items() if not k.startswith('D.')} }")
    if not args.no_write:
        RESULTS.write_text(json.dumps({"tf": tf, "tstep": tstep, "rows": rows}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
