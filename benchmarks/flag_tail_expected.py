"""How many windows off by more than 20 % a standard-error flag lets through by chance alone (issue 20).

Issue 20 asks that no window off by more than 20 % leave without a warning flag.  The flag that catches a wide answer
is a rule on its standard errors (``error_may_exceed_20pct``: some SE above ``IV_SE_MAX`` = 6 % of its parameter).
An answer whose SEs are all below a threshold c can still be off by more than 20 %: a draw beyond 0.2 / c SEs.
With calibrated Gaussian errors the number of such windows in a bench is a sum of tail probabilities, which this
reads from the benches' per-window records (no identification), for the flag's threshold and tighter ones:

* ``observed``: windows off by more than 20 % with no warning flag when the SE rule is set at c;
* ``expected``: Σ over those unflagged windows of P(max_k |N(0, se_k)| > 0.2), the SEs as recorded (independent
  parameters: an approximation; the SEs of a and Tm are correlated, which lowers it);
* ``within10_warned``: the price, the share of answers within 10 % that carry a warning flag at c;
* ``beyond_3se``: among the unflagged answers' parameters, errors beyond 3 SEs, against the Gaussian count.

    .venv/bin/python -m benchmarks.flag_tail_expected docs/results/own_fluctuation_flags_seed245.json [...]
        [--thresholds 0.06 0.05 0.04 0.03] [--json NAME]
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from benchmarks import common
from benchmarks.flag_tail import cells, warned

SE_FLAGS = ("error_may_exceed_20pct", "iv_error_may_exceed_20pct")
OFF = 0.2


def tail_probability(se: np.ndarray, off: float = OFF) -> float:
    """P(max_k |e_k| > off) for independent e_k ~ N(0, se_k²) (se and off as fractions of the parameters)."""
    p_each = [math.erfc(off / (s * math.sqrt(2.0))) if s > 0 else 0.0 for s in se]
    return 1.0 - float(np.prod([1.0 - p for p in p_each]))


def row(recorded: dict, threshold: float) -> dict:
    """Observed and expected unflagged misses, and the price, with the SE rule at ``threshold``."""
    n = off = observed = within10 = within10_warned = draws = beyond3 = 0
    expected = 0.0
    for _, rec in cells(recorded):
        for e, s, f in zip(rec["errors"], rec["stderr"], rec["flags"], strict=True):
            if e is None:
                continue
            e, s = np.array(e, float), np.abs(np.array(s, float))
            # The records' SEs are fractions of the true D; the rule divides by the estimate, D·(1 + e).
            s_rule = s / np.maximum(np.abs(1.0 + e), 1e-12)
            e = np.abs(e)
            flagged = warned(f, SE_FLAGS) or bool(np.any(~np.isfinite(s)) or np.any(s_rule > threshold))
            n += 1
            off += e.max() > OFF
            if not flagged:
                observed += e.max() > OFF
                expected += tail_probability(s)
                z = e / s
                draws += len(z)
                beyond3 += int(np.sum(z > 3.0))
            if e.max() <= 0.1:
                within10 += 1
                within10_warned += flagged
    return {"threshold": threshold, "answers": n, "off_20pct": off, "observed": observed, "expected": expected,
            "within10": within10, "within10_warned": within10_warned, "unflagged_draws": draws,
            "beyond_3se": beyond3, "beyond_3se_gaussian": draws * math.erfc(3.0 / math.sqrt(2.0))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("records", nargs="+", help="own-fluctuation or rates results with per-window records")
    ap.add_argument("--thresholds", type=float, nargs="+", default=[0.06, 0.05, 0.04, 0.03])
    ap.add_argument("--json", help="write docs/results/<NAME>.json")
    args = ap.parse_args()
    out = {}
    for path in args.records:
        with open(path) as fh:
            recorded = json.load(fh)
        rows = [row(recorded, c) for c in args.thresholds]
        out[path] = rows
        print(path)
        for r in rows:
            print(f"  SE rule at {100 * r['threshold']:.0f} %: {r['answers']} answers, {r['off_20pct']} off > 20 %; "
                  f"unflagged observed {r['observed']}, expected {r['expected']:.2f}; within 10 % warned "
                  f"{r['within10_warned']} of {r['within10']} ({100 * r['within10_warned'] / max(r['within10'], 1):.0f} %); "
                  f"beyond 3 SE {r['beyond_3se']} of {r['unflagged_draws']} (Gaussian {r['beyond_3se_gaussian']:.1f})")
    if args.json:
        common.write_json(args.json, {"records": out})


if __name__ == "__main__":
    main()
