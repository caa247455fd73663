"""Two runs of the synthetic self-test compared case by case: every answer that changed.

    .venv/bin/python -m benchmarks.diagnosis_selftest_diff diagnosis_stop28 diagnosis_boundrival

Reads ``docs/results/<run>.json`` (written by ``benchmarks/diagnosis.py``) for both runs, matches their records by
effect, level, case and noise mode, and prints each case whose answer (the named cause for ``explained``, else the
verdict; ``ambiguous`` with its causes) differs, with whether the plain fit's bound is in the later run's message,
then the right names of both runs and CPU per diagnosis.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "results"


def _key(r: dict) -> tuple:
    return r["effect"], r["level"], r["case"], bool(r.get("input_noise", False))


def answer(r: dict) -> str:
    """The case's answer: the cause when explained, the causes when ambiguous, else the verdict."""
    if r["verdict"] == "explained":
        return r["cause"]
    if r["verdict"] == "ambiguous":
        return "ambiguous(" + ",".join(r.get("causes") or []) + ")"
    return r["verdict"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before")
    p.add_argument("after")
    args = p.parse_args(argv)
    runs = [{_key(r): r for r in json.loads((RESULTS / f"{n}.json").read_text())["records"]}
            for n in (args.before, args.after)]
    common = sorted(set(runs[0]) & set(runs[1]), key=str)
    changed = 0
    for k in common:
        a, b = (answer(run[k]) for run in runs)
        if a != b:
            changed += 1
            print(f"{'/'.join(map(str, k[:3]))}{' V/θ' if k[3] else ''}: {a} -> {b}")
    print(f"{changed} of {len(common)} answers changed")
    for name, run in zip((args.before, args.after), runs, strict=True):
        right = sum(run[k]["verdict"] == "explained" and run[k]["cause"] == k[0] for k in common)
        cpu = np.array([run[k]["cpu_s"] for k in common if run[k].get("cpu_s") is not None])
        print(f"{name}: right names {right}; CPU per diagnosis median {np.median(cpu):.2f} s, p95 "
              f"{np.percentile(cpu, 95):.2f} s, max {cpu.max():.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
