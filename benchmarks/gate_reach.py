"""Where the gated estimator (``disturbance="gated"``) leaves output error, and what it leaves unflagged.

Two parts, each printed and written to ``docs/results/gate_reach.json``:

* ``table1``: output error's ``own_ratio_p`` (the gate's input) on Table I's windows (seed 11, exact inputs)
  and on the supplement's noisy-input windows, per disturbance level: where the gate opens, the answer
  and its time are the IV's, elsewhere output error's, unchanged.
* ``records``: from the own-fluctuation benches' per-window records (``own_fluctuation_gate*.json``), the
  windows the gate sends to the IV that carry no warning flag, split by whether they are off by more than
  20 %, and how many of each a flag at 1.96·SE > 20 % would mark (an analysis, not a tuned rule).

    .venv/bin/python -m benchmarks.gate_reach [--n 300] [--no-write]
"""

from __future__ import annotations

import json

import numpy as np

from aslm_core import WindowError, identify_many
from aslm_core.identify import IV_OVERID_MAX, OWN_UNMODELLED_RATIO
from benchmarks import common
from benchmarks.own_gate import WARNING_FLAGS

OE, IV = "output error", "AR disturbance (IV)"
RECORDS = ("own_fluctuation_gate", "own_fluctuation_gate_seed143")


def part_table1(n: int) -> list[dict]:
    """Output error's ``own_ratio_p`` per level on Table I's windows, exact and noisy inputs."""
    rows = []
    for noisy in (False, True):
        for level in (1, 2, 3):
            cs = common.cases(n, level=level, seed=11, input_noise=noisy)
            res = [r for r in identify_many([c.window for c in cs], workers=1) if not isinstance(r, WindowError)]
            ratio = np.array([r.quality["own_ratio_p"] for r in res])
            rows.append({"input_noise": noisy, "level": level, "n": int(ratio.size), "max": float(ratio.max()),
                         "p99": float(np.percentile(ratio, 99)), "gate_opens": int(np.sum(ratio > OWN_UNMODELLED_RATIO))})
            print(rows[-1], flush=True)
    return rows


def part_records() -> dict:
    """Per records file: the IV-answered windows without a warning flag, off by > 20 % or not, and 1.96·SE > 20 %."""
    out = {}
    for name in RECORDS:
        data = json.loads((common.RESULTS / f"{name}.json").read_text())
        counts = {"iv_windows": 0, "unflagged_off": 0, "unflagged_off_marked": 0, "unflagged_within": 0,
                  "unflagged_within_marked": 0}
        for run in data["runs"]:
            for i, ratio in enumerate(run["own_ratio_p"][OE]):
                q = run["quality"][IV][i]
                if ratio is None or not ratio > OWN_UNMODELLED_RATIO or q is None or not q["iv_overid"] <= IV_OVERID_MAX:
                    continue
                err, se, flags = run["errors"][IV][i], run["stderr"][IV][i], run["flags"][IV][i]
                if err is None:
                    continue
                counts["iv_windows"] += 1
                if any(f.startswith(WARNING_FLAGS) for f in flags):
                    continue
                which = "off" if np.max(np.abs(err)) > 0.2 else "within"
                counts[f"unflagged_{which}"] += 1
                counts[f"unflagged_{which}_marked"] += int(1.96 * max(se) > 0.2)
        out[name] = {"seed": data["seed"], **counts}
        print(name, out[name], flush=True)
    return out


def main() -> None:
    p = common.parser(__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=300, help="windows per level and input class (table1)")
    args = p.parse_args()
    out = {"machine": common.machine(), "records": part_records(), "table1": part_table1(20 if args.quick else args.n)}
    if not args.no_write:
        print(common.write_json("gate_reach", out))


if __name__ == "__main__":
    main()
