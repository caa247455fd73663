"""The right candidate's test statistic per reporting rate on ANDES's development set (stop 52; a reading of stored runs).

Stop 51 found the double cage, the second motor and the speed-dependent torque that ANDES writes named at 100 frames/s
and never at 25. This reads the stored runs of ``benchmarks.diagnosis_independent --set dev`` at 100, 50 and 25
frames/s (the same noisy windows, every second or fourth sample) and prints, per effect, how often it is named and the
median and per-case z of its own candidate's paired test (P and Q noise only), so the loss can be read as a rate.

    .venv/bin/python -m benchmarks.diagnosis_rate_z [--runs 100=diagnosis_independent_dev_stop51 ...]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "results"
RUNS = {"100": "diagnosis_independent_dev_stop51", "50": "diagnosis_independent_dev_fs50",
        "25": "diagnosis_independent_dev_fs25_lag52"}
EFFECTS = ("double_cage_rotor", "second_motor", "speed_dependent_torque", "stator_resistance", "frequency_dependence")


def candidate_z(records: list[dict], effect: str) -> tuple[int, int, list[float]]:
    """(named, cases, z of the effect's own candidate per tested case) over the P/Q-noise cases of ``effect``."""
    named, n, zs = 0, 0, []
    for r in records:
        if r["expected"] != effect or r["input_noise"]:
            continue
        n += 1
        named += r["verdict"] == "explained" and r["cause"] == effect
        c = [c for c in (r["candidates"] or []) if c["name"] == effect and c.get("tested")]
        if c:
            zs.append(float(c[0]["z"]))
    return named, n, zs


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="*", default=[f"{k}={v}" for k, v in RUNS.items()],
                    help="rate=stored run name (docs/results/<name>.json)")
    args = ap.parse_args(argv)
    runs = dict(item.split("=", 1) for item in args.runs)
    recs = {fs: json.loads((RESULTS / f"{name}.json").read_text())["records"] for fs, name in runs.items()}
    out = {}
    print("| effect | frames/s | named | median z | z per case |")
    print("|---|---|---|---|---|")
    for eff in EFFECTS:
        for fs, rr in recs.items():
            named, n, zs = candidate_z(rr, eff)
            med = float(np.median(zs)) if zs else math.nan
            out[f"{eff}|{fs}"] = {"named": named, "n": n, "median_z": med, "z": zs}
            print(f"| {eff} | {fs} | {named} of {n} | {med:.2f} | {' '.join(f'{z:.1f}' for z in zs)} |")
    return out


if __name__ == "__main__":
    main()
