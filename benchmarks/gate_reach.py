"""Where the gated estimator (``disturbance="gated"``) leaves output error, and what it leaves unflagged.

Two parts, each printed and written to ``docs/results/gate_reach.json``:

* ``table1``: output error's ``own_ratio_p`` (the gate's input) on Table I's windows (seed 11, exact inputs)
  and on the supplement's noisy-input windows, per disturbance level: where the gate opens, the answer
  and its time are the IV's, elsewhere output error's, unchanged.
* ``records``: from the own-fluctuation benches' per-window records (``own_fluctuation_gate*.json``), the
  windows the gate sends to the IV that carry no warning flag, split by whether they are off by more than
  20 %, and how many of each a flag at 1.96·SE > 20 % would mark (an analysis, not a tuned rule).
* ``iv_flag``: the same windows (synthetic and ANDES records) characterised, off by more than 20 % against
  within, by the IV's indicators, its standard errors and its distance from output error's answer; and the
  flag ``iv_error_may_exceed_20pct`` (largest SE/|D| above a bound) swept over bounds: windows off by more
  than 20 % it leaves unflagged, windows within 20 % it flags.  Development records: synthetic seed 43 and
  ANDES own seed 1 (the bound :data:`aslm_core.identify.IV_SE_MAX` was tuned on them).

    .venv/bin/python -m benchmarks.gate_reach [--n 300] [--no-write] [--records-only]
"""

from __future__ import annotations

import json

import numpy as np

from aslm_core import WindowError, identify_many
from aslm_core.identify import IV_OVERID_MAX, IV_SE_MAX, OWN_UNMODELLED_RATIO
from benchmarks import common
from benchmarks.own_gate import WARNING_FLAGS

OE, IV = "output error", "AR disturbance (IV)"
RECORDS = ("own_fluctuation_gate", "own_fluctuation_gate_seed143")
#: Records of the IV flag's analysis: development first (its bound was tuned on them), then seen confirmation runs.
FLAG_RECORDS = {"own_fluctuation_gate": "dev", "own_fluctuation_andes_gate": "dev",
                "own_fluctuation_gate_seed143": "seen", "own_fluctuation_andes_gate_own11": "seen"}
FLAG_BOUNDS = (0.05, 0.06, 0.07, 0.08, 0.09, 0.10, 0.12)


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


def gated_iv_windows(data: dict) -> list[dict]:
    """The windows of a records file that the gate sends to the IV (output error's ``own_ratio_p`` above the gate,
    the IV's ``iv_overid`` within its bound) and where the IV carries no warning flag: per window its errors,
    standard errors relative to its own estimate, output error's errors, the IV's quality entries, the row."""
    out = []
    for run in data["runs"]:
        for i, ratio in enumerate(run["own_ratio_p"][OE]):
            q = run["quality"][IV][i]
            if ratio is None or not ratio > OWN_UNMODELLED_RATIO or q is None or not q["iv_overid"] <= IV_OVERID_MAX:
                continue
            if run["errors"][IV][i] is None or any(f.startswith(WARNING_FLAGS) for f in run["flags"][IV][i]):
                continue
            err, se = np.array(run["errors"][IV][i]), np.array(run["stderr"][IV][i])
            out.append({"err": err, "se": se, "se_rel": se / np.abs(1.0 + err), "z": err / se, "quality": q,
                        "oe_err": np.array(run["errors"][OE][i]), "ratio": run["ratio"],
                        "noisy": run.get("input_noise", "none") != "none", "off": bool(np.max(np.abs(err)) > 0.2)})
    return out


def part_iv_flag() -> dict:
    """The gated IV windows without a warning flag, off by more than 20 % against within; the SE flag swept."""
    def spread(vals) -> list[float]:
        return [float(v) for v in np.percentile(vals, [10, 50, 90])] if len(vals) else []

    indicators = {
        "iv_strength_p": lambda w: w["quality"]["iv_strength_p"], "iv_overid": lambda w: w["quality"]["iv_overid"],
        "own_ratio_p": lambda w: w["quality"]["own_ratio_p"], "own_ratio_q": lambda w: w["quality"]["own_ratio_q"],
        "excitation_share_p": lambda w: w["quality"]["excitation_share_p"],
        "ar_order_p": lambda w: w["quality"]["ar_order_p"], "max_se_rel": lambda w: float(w["se_rel"].max()),
        "worst_abs_z": lambda w: float(np.abs(w["z"])[np.argmax(np.abs(w["err"]))]),
        "iv_oe_disagreement_se": lambda w: float(np.max(np.abs(w["err"] - w["oe_err"]) / w["se"])),
    }
    out = {}
    for name, role in FLAG_RECORDS.items():
        wins = gated_iv_windows(json.loads((common.RESULTS / f"{name}.json").read_text()))
        off = [w for w in wins if w["off"]]
        within = [w for w in wins if not w["off"]]
        entry = {"role": role, "off": len(off), "within": len(within),
                 "off_noisy_inputs": sum(w["noisy"] for w in off), "off_ratio_0.5": sum(w["ratio"] == 0.5 for w in off),
                 # Calibration of the IV's standard errors on these windows: std of error/SE per parameter (1: right).
                 "z_std_ratio_0.5": np.std([w["z"] for w in wins if w["ratio"] == 0.5], axis=0).tolist(),
                 "indicators": {k: {"off": spread([f(w) for w in off]), "within": spread([f(w) for w in within])}
                                for k, f in indicators.items()},
                 "sweep": [{"bound": b, "off_unflagged": sum(w["se_rel"].max() <= b for w in off),
                            "within_flagged": sum(w["se_rel"].max() > b for w in within)} for b in FLAG_BOUNDS],
                 "at_iv_se_max": {"off_unflagged": sum(w["se_rel"].max() <= IV_SE_MAX for w in off),
                                  "within_flagged": sum(w["se_rel"].max() > IV_SE_MAX for w in within)}}
        out[name] = entry
        print(name, role, {k: entry[k] for k in ("off", "within", "at_iv_se_max")}, flush=True)
    return out


def main() -> None:
    p = common.parser(__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=300, help="windows per level and input class (table1)")
    p.add_argument("--records-only", action="store_true", help="only the parts read from the records")
    args = p.parse_args()
    out = {"machine": common.machine(), "records": part_records(), "iv_flag": part_iv_flag()}
    if args.records_only:
        old = common.read_json("gate_reach")
        out["table1"] = old.get("table1")
    else:
        out["table1"] = part_table1(20 if args.quick else args.n)
    if not args.no_write:
        print(common.write_json("gate_reach", out))


if __name__ == "__main__":
    main()
