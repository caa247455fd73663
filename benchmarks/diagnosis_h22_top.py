"""Where the second motor's fit sits on the top of its inertia box, by kind and answer (issue 12, stop 33; no diagnosis).

    .venv/bin/python -m benchmarks.diagnosis_h22_top confirm11 confirm12

Reads the runs ``docs/results/diagnosis_independent_<run>.json`` and counts, per kind, verdict and noise mode, the
cases whose ``second_motor`` fit has H22 within ``BOUND_TOL`` of its box's top (3 s, the aggregate motor's; the
``second_motor.implausible`` rule of stop 33): all of them (``tested``), those with a score z above 3, and those the
run recorded as significant.  The box's top is read from the candidate's bounds for a window's mean P, which do not
depend on it for H22.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

from aslm_core.diagnosis.candidates.base import BOUND_TOL
from aslm_core.diagnosis.candidates.second_motor import H22_MIN
from aslm_core.params import dynamic_bounds

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "results"


def on_top(runs: list[str]) -> Counter:
    """(run, kind, verdict, input noise) → [tested on the top, of them z > 3, of them significant]."""
    lo, hi = dynamic_bounds(1.0)
    edge = hi[2] - BOUND_TOL * (hi[2] - H22_MIN)  # the second motor's H22 box: [H22_MIN, the aggregate's top]
    out: Counter = Counter()
    for run in runs:
        for r in json.loads((RESULTS / f"diagnosis_independent_{run}.json").read_text())["records"]:
            for c in r["candidates"]:
                if c["name"] == "second_motor" and c.get("tested") and c["parameters"].get("H22", 0.0) >= edge:
                    key = (run, r["kind"], r["verdict"], "V/θ" if r["input_noise"] else "P/Q")
                    out[key + ("tested",)] += 1
                    out[key + ("z>3",)] += int((c.get("z") or 0.0) > 3.0)
                    out[key + ("significant",)] += int(bool(c.get("significant")))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+")
    counts = on_top(p.parse_args(argv).runs)
    rows = sorted({k[:4] for k in counts})
    print("| run | kind | verdict | noise | on the top | z > 3 | significant |\n|---|---|---|---|---|---|---|")
    for k in rows:
        print("| " + " | ".join(k) + " | " + " | ".join(str(counts[k + (f,)]) for f in ("tested", "z>3", "significant"))
              + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
