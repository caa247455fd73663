"""Can the held-out data separate the frequency dependence from the speed-dependent torque? An oracle (issue 12).

    .venv/bin/python -m benchmarks.diagnosis_separability --sets dev,confirm,confirm2,dev3,confirm3,confirm4

On the *noise-free* cached ANDES recordings of the two kinds (:mod:`benchmarks.diagnosis_independent`'s
windows), the plain ZIP + IM, the ``frequency_dependence`` and the ``speed_dependent_torque`` candidates are
fitted on the training samples exactly as the diagnosis fits them (ambient band, P and Q weighted by white
noise ∝ each channel's std: a fixed SNR).  With r_X the held-out ambient-band residual left by candidate X
(DCT coefficients over σ_ch) and D = r_B − r_A the held-out difference of the two corrections, the paired
statistic of the verdict (A the best, B the rival) has on noisy data the expectation

    z(A over B) = Dᵀ·r_B / ‖D‖

at unit SNR, scaled by 10^(SNR/20) at a level's SNR (the nominal 14 / 22 / 28 dB).  The true member
separates from the other at a level when z(true over other) ≥ 1.645 (one-sided 5 %, the verdict's Holm
level for one rival) and the reverse z(other over true) < 1.645 (else the reverse comparison makes the pair
``ambiguous``).  Also per window: each candidate's held-out residual ‖r_X‖ against the plain model's ‖r_0‖
(the oracle z of :mod:`benchmarks.diagnosis_detectability`), its parameters.  What the oracle leaves out: the
estimation error of fits on noisy training data (the real statistics scatter about these values with sd ≈ 1).
Raw output: ``docs/results/diagnosis_separability<tag>.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from aslm_sim.noise import NOISE_LEVELS  # noqa: E402
from benchmarks.diagnosis_independent import SETS, jobs  # noqa: E402

RESULTS = ROOT / "docs" / "results"
PAIR = ("frequency_dependence", "speed_dependent_torque")
TRUTH = {"frequency_dependence": "frequency_dependence", "speed_dependent_torque": "speed_dependent_torque"}
Z_ONE = 1.6448536269514722  # one-sided 5 %, one comparison


def window_pair(kind: str, seed: int) -> list[dict]:
    """Unit-SNR held-out residuals and paired statistics of the pair on each window of one cached scenario."""
    from aslm_core.diagnosis import engine
    from aslm_core.diagnosis.candidates import LIBRARY
    from aslm_core.diagnosis.pipeline import DiagnosisConfig
    from aslm_sim.andes.effects import cache_dir, recording
    from benchmarks.diagnosis_detectability import noise_free_plain
    from benchmarks.diagnosis_independent import TF, TSTEP, WINDOWS

    if not any(cache_dir().glob(f"v*-{kind}-{seed}-*.npz")):
        return []
    rec = recording(kind, seed, tf=TF, tstep=TSTEP)
    config = DiagnosisConfig()
    out = []
    for t0, t1 in WINDOWS:
        seg, ctx, noise, plain, (sp, sq) = noise_free_plain(rec, t0, t1, config)
        scale = np.array([sp, sq])
        r0 = _held_out_coefficients(seg, plain, config.band_hz) / scale
        fits = {m: engine.fit_candidate(LIBRARY[m], seg, ctx, noise, d_start=plain.d) for m in PAIR}
        res = {m: _held_out_coefficients(seg, f, config.band_hz) / scale for m, f in fits.items()}
        row = {"kind": kind, "seed": seed, "window": [t0, t1], "truth": TRUTH[kind],
               "z_plain_unit": float(np.linalg.norm(r0)),
               "left_unit": {m: float(np.linalg.norm(res[m])) for m in PAIR},
               "params": {m: {k: float(v) for k, v in f.params.items() if not k.startswith("D.")}
                          for m, f in fits.items()},
               "paired_unit": {}}
        for a, b in (PAIR, PAIR[::-1]):
            d = res[b] - res[a]
            nd = float(np.linalg.norm(d))
            row["paired_unit"][f"{a}>{b}"] = float(np.sum(d * res[b]) / nd) if nd > 0 else 0.0
        out.append(row)
    return out


def _held_out_coefficients(seg, fit, band_hz: float) -> np.ndarray:
    """Ambient-band DCT coefficients of a fit's held-out residual, columns P and Q [pu]."""
    from aslm_core.diagnosis.noise import dct_band

    te = seg.test
    return dct_band(np.column_stack([(seg.P - fit.model_p)[te], (seg.Q - fit.model_q)[te]]), seg.fs, band_hz)


def per_level(rows: list[dict]) -> dict:
    """Per kind and nominal level: windows where the true member separates rightly, and both ways."""
    out: dict = {}
    for r in rows:
        x = r["truth"]
        y = PAIR[1] if x == PAIR[0] else PAIR[0]
        for lvl, snr in NOISE_LEVELS.items():
            s = 10 ** (snr / 20)
            zx, zy = r["paired_unit"][f"{x}>{y}"] * s, r["paired_unit"][f"{y}>{x}"] * s
            cell = out.setdefault(r["kind"], {}).setdefault(f"L{lvl}", {"windows": 0, "separable": 0, "both_ways": 0,
                                                                          "true_loses": 0, "neither": 0})
            cell["windows"] += 1
            if zx >= Z_ONE and zy < Z_ONE:
                cell["separable"] += 1
            elif zx >= Z_ONE:
                cell["both_ways"] += 1
            elif zy >= Z_ONE:
                cell["true_loses"] += 1
            else:
                cell["neither"] += 1
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", default="dev,confirm,confirm2,dev3,confirm3,confirm4")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--tag", default="", help="written as diagnosis_separability_<tag>.json")
    args = p.parse_args(argv)
    sets = [s for s in args.sets.split(",") if s]
    if "confirm5" in sets:
        raise SystemExit("confirm5 is fixed for a later confirmation: not for development")
    unknown = [s for s in sets if s not in SETS]
    if unknown:
        raise SystemExit(f"unknown sets {unknown}")
    todo = sorted({j for st in sets for j in jobs(st, list(PAIR))})
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = [w for ws in pool.map(window_pair, *zip(*todo, strict=True)) for w in ws]
    summary = per_level(rows)
    print(f"{'kind':24s} level  windows  separable  both-ways  true-loses  neither")
    for kind, lv in summary.items():
        for lvl, c in lv.items():
            print(f"{kind:24s} {lvl:5s}  {c['windows']:7d}  {c['separable']:9d}  {c['both_ways']:9d}  "
                  f"{c['true_loses']:10d}  {c['neither']:7d}")
    print(f"{len(rows)} windows, {time.perf_counter() - t0:.0f} s, load {os.getloadavg()}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    name = "diagnosis_separability" + (f"_{args.tag}" if args.tag else "")
    (RESULTS / f"{name}.json").write_text(json.dumps({
        "sets": sets, "levels_db": NOISE_LEVELS, "z_one": Z_ONE, "summary": summary, "windows": rows,
        "load_avg": os.getloadavg(), "wall_s": time.perf_counter() - t0,
        "command": "benchmarks/diagnosis_separability.py " + " ".join(argv if argv is not None else sys.argv[1:])},
        indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
