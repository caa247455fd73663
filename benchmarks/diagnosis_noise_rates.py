"""The diagnosis's noise model on one of ANDES's records at 100, 50 and 25 frames/s (stop 52).

One development-set record (``--kind``, its first seed and first window; P and Q noise at the level's SNR, V and θ
exact), every second or fourth sample of the same noisy window as ``benchmarks.diagnosis_independent --fs`` takes it.
Per rate and level: the input floors the noise model takes as noise, their share of P's modelled noise, P's modelled
floor over the injected noise, and the z of the effect's own candidate; with ``--quiet`` under
``DiagnosisConfig(exact_inputs_quiet=True)``.

    .venv/bin/python -m benchmarks.diagnosis_noise_rates [--kind second_motor] [--quiet]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from benchmarks.diagnosis_independent import KINDS, SETS, TF, TSTEP, WINDOWS, _window, diagnosis_config  # noqa: E402


def main(argv=None) -> list[dict]:
    from aslm_core.diagnosis import diagnose
    from aslm_sim.andes.effects import recording

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", default="second_motor", choices=[k for k in KINDS if k != "clean"])
    ap.add_argument("--quiet", action="store_true", help="DiagnosisConfig(exact_inputs_quiet=True)")
    args = ap.parse_args(argv)
    seed = SETS["dev"]["effect"][0]
    rec = recording(args.kind, seed, tf=TF, tstep=TSTEP)
    t0, t1 = WINDOWS[0]
    sl = (rec["t"] >= t0 - 1e-9) & (rec["t"] <= t1 + 1e-9)
    config = replace(diagnosis_config(), exact_inputs_quiet=args.quiet)
    expected = KINDS[args.kind].expected
    rows = []
    print("| DL | frames/s | σ_V, σ_θ taken as noise | input share of P's noise | P floor / injected | z of the effect |")
    print("|---|---|---|---|---|---|")
    for level in (2, 3):
        for step in (1, 2, 4):
            w, snr = _window(rec, t0, t1, level, False, f"{args.kind}/{seed}", step)
            injected = float(np.std(rec["P"][sl]) * 10 ** (-snr / 20))
            rep = diagnose(w, config=config)
            noise = rep.to_dict()["noise"]
            cand = [e for e in rep.missing_physics if e.name == expected]
            row = {"level": level, "fs": 100 // step, "sigma_v": noise["sigma_v"], "sigma_theta": noise["sigma_theta"],
                   "input_share_p": noise["input_share_p"], "p_floor_over_injected": noise["sigma_p"] / injected,
                   "z": cand[0].score_z if cand else None, "verdict": rep.verdict, "cause": rep.cause}
            rows.append(row)
            z = "–" if row["z"] is None else f"{row['z']:.2f}"
            print(f"| {level} | {row['fs']} | {row['sigma_v']:.2g}, {row['sigma_theta']:.2g} | "
                  f"{row['input_share_p']:.0%} | {row['p_floor_over_injected']:.2f} | {z} ({rep.verdict}) |")
    return rows


if __name__ == "__main__":
    main()
