"""How much of the mismatch the named cause explains, by whether the name was right (issue 12; no diagnosis run).

    .venv/bin/python -m benchmarks.diagnosis_explained_share confirm6 confirm7 confirm8 confirm9 confirm10 confirm11 confirm12

Reads the runs of record ``docs/results/diagnosis_independent_<set>.json`` and, for every ``explained`` answer, the
named cause's ``explained_fraction`` (the share of the held-out ambient-band excess it removes; a cause is named from
``DiagnosisConfig.explained_fraction`` = 0.5 up).  Splits them by noise mode into right names, wrong names of an
inside-library effect and names of an outside-library effect, and prints the distribution and what a higher threshold
would have withheld of each.  It reads what each run of record recorded, whatever code made it: a threshold read off
this is development data, to be confirmed on a set fixed before it is run.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
THRESHOLDS = (0.6, 0.7, 0.8, 0.9)


def named_shares(sets: list[str]) -> list[tuple[str, bool, float]]:
    """(class, input noise, explained fraction) of every ``explained`` answer of the sets' runs of record; class
    ``right``, ``wrong`` (an inside-library effect given another name) or ``outside`` (an outside-library effect)."""
    out = []
    for s in sets:
        for r in json.loads((RESULTS / f"diagnosis_independent_{s}.json").read_text())["records"]:
            if r["verdict"] != "explained":
                continue
            share = next((c.get("explained_fraction") for c in r["candidates"] if c["name"] == r["cause"]), None)
            if share is None:
                continue
            # ``expected``: the cause to name, "consistent" (clean) or "outside" (an outside-library effect).
            cls = "outside" if r["expected"] == "outside" else ("right" if r["cause"] == r["expected"] else "wrong")
            out.append((cls, bool(r["input_noise"]), float(share)))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sets", nargs="+")
    args = p.parse_args(argv)
    rows = named_shares(args.sets)
    print(f"runs of record: {', '.join(args.sets)}\n")
    print("| noise | named | n | min | 5 % | 25 % | median | " + " | ".join(f"< {t:g}" for t in THRESHOLDS) + " |")
    print("|---|---|---|---|---|---|---|" + "---|" * len(THRESHOLDS))
    for mode, label in ((False, "P/Q"), (True, "V/θ too")):
        for cls in ("right", "wrong", "outside"):
            v = np.array([x for c, m, x in rows if c == cls and m == mode])
            if not v.size:
                continue
            q = np.percentile(v, [0, 5, 25, 50])
            print(f"| {label} | {cls} | {v.size} | " + " | ".join(f"{x:.2f}" for x in q) + " | "
                  + " | ".join(str(int((v < t).sum())) for t in THRESHOLDS) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
